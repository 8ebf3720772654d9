"""cmake/install_python.py, the package's Python directory: a package folder with a
pyproject.toml goes through pip (--no-deps --no-build-isolation), one without is copied as a
PYTHONPATH root, console scripts stay out, an install in place (--compile) is byte-compiled for
where it will lie and a staged one (the package) carries no byte code, ELF files are stripped and
modes are Debian's, and the wheels lose what the board never runs. No network: no wheels are
fetched here (the package stage fetches and flies them)."""
from __future__ import annotations

import importlib.util
import shutil
import stat
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "cmake" / "install_python.py"
spec = importlib.util.spec_from_file_location("install_python", SCRIPT)
install_python = importlib.util.module_from_spec(spec)
spec.loader.exec_module(install_python)

PYVER = f"{sys.version_info[0]}.{sys.version_info[1]}"


def make_project(tmp: Path) -> tuple[Path, Path]:
    """A throwaway pyproject package (with a console script) and a PYTHONPATH root."""
    proj = tmp / "proj"
    (proj / "toypkg").mkdir(parents=True)
    (proj / "toypkg" / "__init__.py").write_text("VALUE = 42\n")
    (proj / "toypkg" / "__main__.py").write_text("print('toy')\n")
    (proj / "pyproject.toml").write_text(
        '[build-system]\nrequires = ["setuptools>=61"]\nbuild-backend = "setuptools.build_meta"\n'
        '[project]\nname = "toypkg"\nversion = "0.1"\n[project.scripts]\ntoy = "toypkg.__main__:main"\n'
        '[tool.setuptools]\npackages = ["toypkg"]\n')
    plain = tmp / "plain"
    (plain / "plainpkg").mkdir(parents=True)
    (plain / "plainpkg" / "__init__.py").write_text("")
    (plain / "lcmtypes").mkdir()
    (plain / "lcmtypes" / "x_t.lcm").write_text("struct x_t { int64_t utime; }\n")
    (plain / "notapackage").mkdir()
    return proj, plain


def test_pyproject_through_pip_plain_roots_copied_and_compiled_for_the_board(tmp_path):
    # --no-build-isolation builds with the venv's own setuptools: bdist_wheel is in it from
    # 70.1 on (requirements.txt), or comes with the `wheel` package.
    import setuptools
    has_bdist_wheel = importlib.util.find_spec("wheel") is not None or \
        tuple(int(x) for x in setuptools.__version__.split(".")[:2]) >= (70, 1)
    assert has_bdist_wheel, f"setuptools {setuptools.__version__} without `wheel`: requirements.txt needs setuptools>=70.1"
    proj, plain = make_project(tmp_path)
    dest = tmp_path / "stage" / "usr" / "lib" / "mppid" / "python"
    r = subprocess.run([sys.executable, str(SCRIPT), "--dest", str(dest), "--final-dir", "/usr/lib/mppid/python",
                        "--arch", "x86_64", "--python-version", PYVER, "--wheel-cache", str(tmp_path / "cache"),
                        "--wheels", "", "--packages", f"{proj};{plain}", "--compile"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    assert (dest / "toypkg" / "__init__.py").is_file()
    assert any(dest.glob("toypkg-0.1.dist-info"))
    assert not (dest / "bin").exists(), "console scripts name the build's Python: never installed"
    assert (dest / "plainpkg" / "__init__.py").is_file() and (dest / "lcmtypes" / "x_t.lcm").is_file()
    assert not (dest / "notapackage").exists()
    pyc = next((dest / "toypkg" / "__pycache__").glob("__init__.cpython-*.pyc"))
    assert b"/usr/lib/mppid/python/toypkg/__init__.py" in pyc.read_bytes()
    out = subprocess.run([sys.executable, "-c", "import toypkg; print(toypkg.VALUE)"], capture_output=True,
                         text=True, env={"PYTHONPATH": str(dest)})
    assert out.stdout.strip() == "42"


def test_a_folder_with_neither_is_refused(tmp_path):
    (tmp_path / "empty").mkdir()
    r = subprocess.run([sys.executable, str(SCRIPT), "--dest", str(tmp_path / "d"), "--arch", "x86_64",
                        "--python-version", PYVER, "--wheel-cache", str(tmp_path / "c"),
                        "--packages", str(tmp_path / "empty")], capture_output=True, text=True, timeout=60)
    assert r.returncode != 0 and "neither a pyproject.toml nor a package" in r.stderr


def test_wheels_lose_what_the_board_never_runs(tmp_path):
    kept = ["pymavlink/mavutil.py", "pymavlink/dialects/v20/all.py", "pymavlink/dialects/v20/__init__.py",
            "pymavlink/generator/mavcrc.py", "lcm/__init__.py", "lcm/_lcm.so", "bin/lcm-logger", "bin/lcm-gen",
            "fastcrc/__init__.py", "lcm-1.5.3.dist-info/METADATA"]
    dropped = ["pymavlink/dialects/v20/ardupilotmega.py", "pymavlink/dialects/v10/all.py", "pymavlink/tools/mavlogdump.py",
               "pymavlink/dfindexer/dfindexer_cy.so", "lib/liblcm.a", "lib/liblcm.so.1", "include/lcm/lcm.h",
               "share/java/lcm.jar", "bin/lcm-spy", "pymavlink-2.4.50.data/scripts/mavproxy.py",
               "pymavlink/__pycache__/mavutil.cpython-311.pyc"]
    wheel = tmp_path / "toy-1.0-py3-none-any.whl"
    with zipfile.ZipFile(wheel, "w") as z:
        for name in kept + dropped:
            info = zipfile.ZipInfo(name)
            info.external_attr = (0o755 if name.startswith("bin/") else 0o644) << 16
            z.writestr(info, "x")
    dest = tmp_path / "d"
    install_python.unpack_wheel(wheel, dest)
    have = sorted(str(p.relative_to(dest)) for p in dest.rglob("*") if p.is_file())
    assert have == sorted(kept)
    assert (dest / "bin" / "lcm-logger").stat().st_mode & 0o111, "programs stay executable"


def test_a_staged_install_carries_no_byte_code(tmp_path):
    _, plain = make_project(tmp_path)
    (plain / "plainpkg" / "__pycache__").mkdir()
    (plain / "plainpkg" / "__pycache__" / "__init__.cpython-311.pyc").write_bytes(b"stale")
    dest = tmp_path / "stage"
    r = subprocess.run([sys.executable, str(SCRIPT), "--dest", str(dest), "--arch", "x86_64",
                        "--python-version", PYVER, "--wheel-cache", str(tmp_path / "c"), "--packages", str(plain)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr
    assert (dest / "plainpkg" / "__init__.py").is_file()
    assert not list(dest.rglob("__pycache__")) and not list(dest.rglob("*.pyc")), "the postinst compiles, not the build"


def elf_sections(path: Path) -> str:
    return subprocess.run(["readelf", "-S", "-W", str(path)], capture_output=True, text=True, check=True).stdout


def test_elf_files_stripped_and_modes_debians(tmp_path):
    cc = shutil.which("cc") or shutil.which("gcc")
    assert cc and shutil.which("strip") and shutil.which("readelf"), "build-essential (tools/setup.sh)"
    src = tmp_path / "x.c"
    src.write_text("int f(int x) { return x + 1; }\nint main(void) { return f(-1); }\n")
    dest = tmp_path / "d"
    (dest / "bin").mkdir(parents=True)
    (dest / "pkg").mkdir()
    subprocess.run([cc, "-g", "-o", str(dest / "bin" / "prog"), str(src)], check=True)
    subprocess.run([cc, "-g", "-shared", "-fPIC", "-o", str(dest / "pkg" / "_ext.so"), str(src)], check=True)
    (dest / "pkg" / "mod.py").write_text("")
    (dest / "pkg" / "mod.py").chmod(0o664)
    (dest / "pkg" / "run.py").write_text("#!/usr/bin/python3\n")
    (dest / "pkg" / "run.py").chmod(0o775)
    (dest / "pkg").chmod(0o775)
    (dest / "bin" / "prog").chmod(0o775)
    for f in ("bin/prog", "pkg/_ext.so"):
        assert ".debug_info" in elf_sections(dest / f) and ".symtab" in elf_sections(dest / f)
    install_python.strip_and_set_modes(dest, "strip")
    for f in ("bin/prog", "pkg/_ext.so"):
        sections = elf_sections(dest / f)
        assert ".debug_info" not in sections and ".symtab" not in sections and ".comment" not in sections, f
    mode = {str(p.relative_to(dest)): stat.S_IMODE(p.stat().st_mode) for p in [dest / "bin", dest / "pkg", *dest.rglob("*")]}
    assert mode == {"bin": 0o755, "pkg": 0o755, "bin/prog": 0o755, "pkg/_ext.so": 0o644,
                    "pkg/mod.py": 0o644, "pkg/run.py": 0o644}
    assert subprocess.run([str(dest / "bin" / "prog")]).returncode == 0, "a stripped program still runs"
