#!/usr/bin/env python3
"""Repository hygiene: the tracked files speak of mppid only and stay small.

    tools/check-hygiene.py [--root DIR]

Fails (exit 1, one `path:line: ...` per finding) on
  - talk about how the project was developed rather than about mppid (the machinery and people
    around its making, private paths of a development machine);
  - recipes for building third-party sources (PX4, ArduPilot): name what was flown and point at
    the autopilot's own build documentation instead;
  - size: a tracked file over 1 MB, or bench/results over 5.5 MB in all.
Binary and compressed files are checked for size only. Runs in well under a second (CI's
first test stage, tools/test.sh).
"""
from __future__ import annotations

import argparse
import re
import subprocess
import sys
from pathlib import Path

MAX_FILE_BYTES = 1_000_000
RESULTS_DIR = "bench/results/"
MAX_RESULTS_BYTES = 5_500_000
BINARY_SUFFIXES = (".png", ".jpg", ".jpeg", ".gif", ".pdf", ".xz", ".gz", ".tgz", ".zst",
                   ".bz2", ".zip", ".ulg", ".lcmlog", ".bin", ".deb")


def _p(*pieces: str) -> str:
    """A pattern joined from pieces, so that this file does not match its own patterns."""
    return "".join(pieces)


# (category, regex); matched case-insensitively, line by line.
PATTERNS: list[tuple[str, str]] = [
    ("development talk", _p(r"\bdevice", r" (tool|time)\b")),
    ("development talk", _p(r"\b(this|next|same|another|the)", r" session('s)?\b(?! *=)")),
    ("development talk", _p(r"\bother", r" sessions\b")),
    ("development talk", _p(r"\bsession", r" of \d{4}")),
    ("development talk", _p(r"\b(cycle|kernel|device|compare|field)", r"[ _]session\b")),
    ("development talk", _p(r"--session", r"-seconds|\bsession", r"\.tgz")),
    ("development talk", _p(r"\bhelper", r"('s)? (own|branch|branches|worktree|checkout)\b")),
    ("development talk", _p(r"\b(other|fellow)", r" (engineers|agents|helpers)\b")),
    ("development talk", _p(r"\bthe", r" lead's")),
    ("development talk", _p(r"\bhelpers? ", r"(building|built|ran)\b")),
    ("development talk", _p(r"\bbranches", r" merged\b")),
    ("development talk", _p(r"\bdevice", r" pool\b")),
    ("development talk", _p(r"\bstored", r" snapshot")),
    ("development talk", _p(r"\bthe", r" workplace\b")),
    ("development talk", _p(r"\bcarry", r": *\[ *\"")),
    ("development talk", _p(r"\.gpu", r"work\b")),
    ("private path", _p(r"(?<![\w.$}-])/wo", r"rk/")),
    ("private path", _p(r"(?<![\w.$}-])/ro", r"ot/(build|out|session|b-)")),
    ("third-party recipe", _p(r"GIT_SUBMODULES", r"_ARE_EVIL")),
    ("third-party recipe", _p(r"\.px4", r"board\b")),
    ("third-party recipe", _p(r"\bwaf", r" configure\b")),
    ("third-party recipe", _p(r"\./wa", r"f ")),
    ("third-party recipe", _p(r"\bwith", r"_can\b")),
    ("third-party recipe", _p(r"\bgit", r" submodule (update|init|add)\b")),
]
COMPILED = [(cat, re.compile(rx, re.IGNORECASE)) for cat, rx in PATTERNS]
SELF = "tools/check-hygiene.py"


def git(root: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["git", "-C", str(root), *args], capture_output=True)


def phrase_findings(root: Path) -> list[str]:
    """git grep over the tracked text files (fast: one pass for all patterns), then each hit's
    category from the first pattern that matches its line."""
    args = ["grep", "-z", "-n", "-I", "-i", "-P"]
    for _, rx in PATTERNS:
        args += ["-e", rx]
    done = git(root, *args, "--", ".", f":!{SELF}", *(f":!*{s}" for s in BINARY_SUFFIXES))
    if done.returncode not in (0, 1):  # 1: no match
        raise RuntimeError(done.stderr.decode().strip())
    found = []
    for record in done.stdout.decode("utf-8", errors="replace").splitlines():
        name, number, line = record.split("\0", 2)
        for category, rx in COMPILED:
            m = rx.search(line)
            if m:
                found.append(f"{name}:{number}: {category}: '{m.group(0)}' in: {line.strip()[:120]}")
                break
    return found


def size_findings(root: Path) -> list[str]:
    listed = git(root, "ls-files", "-z")
    if listed.returncode != 0:
        raise RuntimeError(listed.stderr.decode().strip())
    found, results_total = [], 0
    for name in filter(None, listed.stdout.decode().split("\0")):
        path = root / name
        if not path.is_file():
            continue  # deleted in the work tree, or a submodule
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            found.append(f"{name}:0: size: {size} bytes, over {MAX_FILE_BYTES} (compress or leave it out)")
        if name.startswith(RESULTS_DIR):
            results_total += size
    if results_total > MAX_RESULTS_BYTES:
        found.append(f"{RESULTS_DIR}:0: size: {results_total} bytes in all, over {MAX_RESULTS_BYTES}")
    return found


def check(root: Path) -> list[str]:
    return phrase_findings(root) + size_findings(root)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=Path(__file__).resolve().parent.parent,
                        help="the git checkout to check (default: this one)")
    args = parser.parse_args(argv)
    try:
        findings = check(args.root)
    except RuntimeError as e:
        print(f"check-hygiene: --root {args.root}: git failed: {e}", file=sys.stderr)
        return 2
    for f in findings:
        print(f)
    if findings:
        print(f"check-hygiene: {len(findings)} finding(s)", file=sys.stderr)
        return 1
    print("check-hygiene: clean")
    return 0


if __name__ == "__main__":
    sys.exit(main())
