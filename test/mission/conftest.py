"""The mission tool's tests: its package on the path (drivers/mission, and drivers/mavlink
for the LCM types and the bridge's control client)."""
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "drivers" / "mission"), str(ROOT / "drivers" / "mavlink")]
