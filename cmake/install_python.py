#!/usr/bin/env python3
"""Fills the package's Python directory, lib/mppid/python (cmake/Install.cmake runs it at
install time; docs/deploy.md says why a directory on Debian's python3 and not a venv):

  - the PyPI wheels Debian 12 lacks (pymavlink, fastcrc, lcm), for the target's architecture
    and Python, downloaded once into a cache and unpacked as they are, less what the board
    never runs (headers, libraries and CMake files, man pages, lcm.jar, pymavlink's tools and
    log indexer, every MAVLink dialect but MAVLink 2's `all`, pymavlink's default; lcm's
    programs but lcm-logger, the flight recorder, and lcm-gen);
  - the project's packages: a folder with a pyproject.toml through
    `pip install --no-deps --no-build-isolation --target`, a folder without one (a PYTHONPATH
    root) by copying its packages and LCM type files;
  - the wheels' programs and extension modules stripped with the target's strip (--strip), and
    every file 0644, those in bin/ 0755, whatever the wheel or the build's umask said;
  - byte-compiled (--compile: an install in place) with the final path in the code objects,
    when this Python is the target's; the Debian package carries no byte code, its postinst
    compiles on the board (cmake/debian/postinst).
"""
from __future__ import annotations

import argparse
import compileall
import fnmatch
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

PLATFORMS = ("manylinux_2_28_{}", "manylinux_2_17_{}", "manylinux2014_{}")
# lib/: liblcm, which lcm's programs and Python module link in statically. The MAVLink
# dialects: the bridge, the mission tool and the stand-in autopilot speak MAVLink 2
# (MAVLINK20) in pymavlink's default dialect, `all` (every dialect's messages: PX4's and
# ArduPilot's).
DROP = ("*.data/*", "include/*", "lib/*", "share/*", "*/__pycache__/*", "pymavlink/tools/*",
        "pymavlink/dfindexer/*", "pymavlink/dialects/v10/*", "pymavlink/dialects/v20/*")
KEEP = ("pymavlink/dialects/v10/__init__.py", "pymavlink/dialects/v20/__init__.py",
        "pymavlink/dialects/v20/all.py")
KEEP_BIN = ("bin/lcm-logger", "bin/lcm-gen")


def log(msg: str):
    print(f"[install_python] {msg}", flush=True)


def wheel_cached(cache: Path, spec: str) -> Path | None:
    """The cached wheel of a pinned `name==version`, or None (unpinned: always fetched)."""
    if "==" not in spec:
        return None
    name, version = spec.split("==", 1)
    prefix = f"{name.replace('-', '_').lower()}-{version}-"
    hits = [w for w in cache.glob("*.whl") if w.name.lower().startswith(prefix)]
    return hits[0] if hits else None


def fetch_wheels(specs: list[str], arch: str, py_version: str, cache: Path) -> list[Path]:
    cache.mkdir(parents=True, exist_ok=True)
    missing = [s for s in specs if wheel_cached(cache, s) is None]
    if missing:
        log(f"pip download for {arch}, Python {py_version}: {' '.join(missing)}")
        cmd = [sys.executable, "-m", "pip", "download", "--disable-pip-version-check", "-q", "--no-deps",
               "--only-binary=:all:", "--implementation", "cp", "--python-version", py_version, "-d", str(cache)]
        for p in PLATFORMS:
            cmd += ["--platform", p.format(arch)]
        subprocess.run(cmd + missing, check=True)
    wheels = []
    for s in specs:
        w = wheel_cached(cache, s)
        if w is None:  # unpinned: the newest downloaded
            name = s.split("=")[0].split("<")[0].split(">")[0].replace("-", "_").lower()
            w = max(cache.glob(f"{name}-*.whl"), key=lambda p: p.stat().st_mtime)
        wheels.append(w)
    return wheels


def wanted(name: str) -> bool:
    if name.startswith("bin/"):
        return name in KEEP_BIN
    if name in KEEP:
        return True
    return not any(fnmatch.fnmatch(name, pat) for pat in DROP)


def unpack_wheel(wheel: Path, dest: Path):
    """A wheel is a zip of its installed tree: unpacked as is (no console scripts: the package
    has its own programs), executable bits kept."""
    kept = 0
    with zipfile.ZipFile(wheel) as z:
        for info in z.infolist():
            if info.is_dir() or not wanted(info.filename):
                continue
            target = dest / info.filename
            target.parent.mkdir(parents=True, exist_ok=True)
            with z.open(info) as src, open(target, "wb") as out:
                shutil.copyfileobj(src, out)
            mode = (info.external_attr >> 16) & 0o777
            os.chmod(target, mode | 0o644 if mode else 0o644)
            kept += 1
    log(f"{wheel.name}: {kept} files")


def install_project(folders: list[Path], dest: Path):
    with_pyproject = [f for f in folders if (f / "pyproject.toml").is_file()]
    if with_pyproject:
        log(f"pip install --no-deps --no-build-isolation: {' '.join(map(str, with_pyproject))}")
        with tempfile.TemporaryDirectory() as tmp:
            subprocess.run([sys.executable, "-m", "pip", "install", "--disable-pip-version-check", "-q", "--no-deps",
                            "--no-build-isolation", "--no-compile", "--target", tmp] + [str(f) for f in with_pyproject],
                           check=True)
            for item in Path(tmp).iterdir():
                if item.name != "bin":  # console scripts name the build's Python: cmake/python-program.sh.in instead
                    copy_item(item, dest / item.name)
    for f in folders:
        if f in with_pyproject:
            continue
        if not f.is_dir():
            raise SystemExit(f"install_python.py: {f}: no such folder (built? MPPID_PYTHON_PACKAGES)")
        found = [d for d in sorted(f.iterdir()) if d.is_dir() and ((d / "__init__.py").is_file() or any(d.glob("*.lcm")))]
        if not found:
            raise SystemExit(f"install_python.py: {f}: neither a pyproject.toml nor a package in it")
        log(f"{f} (no pyproject.toml: copied): {' '.join(d.name for d in found)}")
        for d in found:
            copy_item(d, dest / d.name)


def copy_item(src: Path, dst: Path):
    if dst.exists():
        shutil.rmtree(dst) if dst.is_dir() else dst.unlink()
    if src.is_dir():
        shutil.copytree(src, dst, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    else:
        shutil.copy2(src, dst)


def is_elf(path: Path) -> bool:
    with open(path, "rb") as f:
        return f.read(4) == b"\x7fELF"


def strip_and_set_modes(dest: Path, strip: str):
    """As dh_strip and dh_fixperms would leave them: ELF files without symbols or .comment and
    .note (extension modules --strip-unneeded, programs fully), directories 0755, files 0644 but
    the programs in bin/ 0755."""
    stripped = 0
    for path in sorted(dest.rglob("*")):
        if path.is_symlink():
            continue
        if path.is_dir():
            os.chmod(path, 0o755)
            continue
        program = path.parent.name == "bin"
        os.chmod(path, 0o755 if program else 0o644)
        if strip and is_elf(path):
            how = [] if program else ["--strip-unneeded"]
            subprocess.run([strip, "--remove-section=.comment", "--remove-section=.note", *how, str(path)], check=True)
            stripped += 1
    if strip:
        log(f"{strip}: {stripped} ELF files")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dest", required=True, type=Path, help="the Python directory (with DESTDIR)")
    ap.add_argument("--final-dir", help="where it lies on the board (the compiled files' paths)")
    ap.add_argument("--arch", required=True, help="x86_64 | aarch64")
    ap.add_argument("--python-version", required=True, help="the target's python3, e.g. 3.11")
    ap.add_argument("--wheel-cache", required=True, type=Path)
    ap.add_argument("--wheels", default="", help="';'-separated requirement specs")
    ap.add_argument("--packages", default="", help="';'-separated folders")
    ap.add_argument("--strip", default="", help="the target's strip (empty: nothing stripped)")
    ap.add_argument("--compile", action="store_true", help="byte-compile (an install in place)")
    a = ap.parse_args()
    if a.dest.exists():
        shutil.rmtree(a.dest)
    a.dest.mkdir(parents=True)
    specs = [s for s in a.wheels.split(";") if s]
    for w in fetch_wheels(specs, a.arch, a.python_version, a.wheel_cache / f"{a.arch}-cp{a.python_version}"):
        unpack_wheel(w, a.dest)
    install_project([Path(p) for p in a.packages.split(";") if p], a.dest)
    strip_and_set_modes(a.dest, a.strip)
    if not a.compile:
        log("not byte-compiled: a staged install (the package's postinst compiles)")
    elif a.python_version == f"{sys.version_info[0]}.{sys.version_info[1]}":
        ok = compileall.compile_dir(str(a.dest), quiet=1, ddir=a.final_dir or str(a.dest))
        if not ok:
            raise SystemExit("install_python.py: byte-compiling failed")
    else:
        log(f"not byte-compiled: this Python is not the target's {a.python_version}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
