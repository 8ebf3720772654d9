"""pytest picks the MAVLink tests' fixtures up from here; they live in mavtest.py."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from mavtest import *  # noqa: E402,F401,F403  (fixtures: netns, procs, tap, ...)
