"""tools/check-hygiene.py on small git repositories: clean ones pass, a planted phrase, recipe
marker or oversized file fails with its file and line, and the script never flags itself."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "tools" / "check-hygiene.py"


def run(repo: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), "--root", str(repo)], capture_output=True,
                          text=True, timeout=60)


@pytest.fixture
def repo(tmp_path: Path) -> Path:
    subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    write(tmp_path, "README.md", "# demo\n\nA controller daemon. Its sessions of pytest are fine.\n")
    write(tmp_path, "tools/run.sh", "#!/bin/sh\nsetsid sh -c 'echo in its own session'\n")
    return tmp_path


def write(repo: Path, name: str, text: str | bytes, track: bool = True) -> None:
    path = repo / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    if track:
        subprocess.run(["git", "-C", str(repo), "add", name], check=True)


def test_a_clean_repository_passes(repo: Path) -> None:
    done = run(repo)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "clean" in done.stdout


# Each phrase is built from two pieces so that this file itself stays clean.
@pytest.mark.parametrize("phrase, category", [
    ("measured while other " + "engineers built", "development talk"),
    ("the device " + "tool's H100 machine", "development talk"),
    ("all of this " + "session's work", "development talk"),
    ("from the stored " + "snapshot", "development talk"),
    ("see /wo" + "rk/main/build", "private path"),
    ("GIT_SUBMODULES_ARE" + "_EVIL=1 make", "third-party recipe"),
    ("./wa" + "f configure --board sitl", "third-party recipe"),
])
def test_a_planted_phrase_fails_naming_file_and_line(repo: Path, phrase: str, category: str) -> None:
    write(repo, "docs/page.md", f"# page\n\nfine text\n{phrase}\n")
    done = run(repo)
    assert done.returncode == 1
    assert f"docs/page.md:4: {category}" in done.stdout
    assert "1 finding" in done.stderr


def test_untracked_files_are_not_checked(repo: Path) -> None:
    write(repo, "notes.md", "other " + "engineers\n", track=False)
    assert run(repo).returncode == 0


def test_a_file_over_one_megabyte_fails(repo: Path) -> None:
    write(repo, "data/big.bin", b"\0" * 1_000_001)
    done = run(repo)
    assert done.returncode == 1
    assert "data/big.bin:0: size: 1000001 bytes" in done.stdout


def test_bench_results_over_their_total_fail(repo: Path) -> None:
    for i in range(6):  # each under 1 MB, 5.7 MB in all
        write(repo, f"bench/results/r{i}.bin", b"\0" * 950_000)
    done = run(repo)
    assert done.returncode == 1
    assert "bench/results/:0: size: 5700000 bytes in all, over 5500000" in done.stdout
    assert "r0.bin" not in done.stdout


def test_the_script_does_not_flag_itself(repo: Path) -> None:
    # At its own path it is skipped; at any other path its patterns, built from pieces, still
    # do not match its own text.
    write(repo, "tools/check-hygiene.py", SCRIPT.read_text())
    write(repo, "tools/copy_of_check.py", SCRIPT.read_text())
    done = run(repo)
    assert done.returncode == 0, done.stdout


def test_not_a_git_checkout_is_a_clear_error(tmp_path: Path) -> None:
    done = run(tmp_path)
    assert done.returncode == 2
    assert "--root" in done.stderr and "git" in done.stderr

