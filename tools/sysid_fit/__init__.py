"""tools/sysid: system identification of the rate model (docs/sysid.md)."""
