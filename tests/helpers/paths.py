"""The repository's folders, for a test at any depth of tests/."""
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]     # the repository
TESTS = ROOT / "tests"
DATA = TESTS / "data"
