"""Builds the LCM Python types: build_py first runs lcm-gen (the lcm wheel's) over each
package's .lcm files, into that package's folder beside them (ignored by git), so a wheel and
an editable install (pip install -e) both import the same generated modules.

Everything else is in pyproject.toml."""
import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent
PACKAGES = ("mppi_lcm", "mppi_mavlink_lcm")


def generate(package: Path) -> None:
    """The package's modules from its .lcm files; what an earlier run made goes first (lcm-gen
    only ever adds to __init__.py, so a removed type would linger)."""
    import lcm

    for old in package.glob("*.py"):
        old.unlink()
    sources = sorted(str(p) for p in package.glob("*.lcm"))
    if not sources:
        raise SystemExit(f"lcmtypes: no .lcm files in {package}")
    rc = lcm.run_script("lcm-gen", ["--python", "--ppath", str(package.parent), *sources])
    if rc != 0 or not (package / "__init__.py").is_file():
        raise SystemExit(f"lcmtypes: lcm-gen failed (exit status {rc}) on {package}")


class BuildPyWithLcmGen(build_py):
    def run(self):
        for name in PACKAGES:
            generate(HERE / name)
            shutil.rmtree(Path(self.build_lib) / name, ignore_errors=True)  # an earlier build's copy
        super().run()


setup(cmdclass={"build_py": BuildPyWithLcmGen})
