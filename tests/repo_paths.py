"""Where the tests find the repository's files, whichever test folder they sit in."""

from __future__ import annotations

from pathlib import Path

TESTS = Path(__file__).resolve().parent  #: tests/: the shared helpers (fake_trial.py, bad_inputs.py, ...) and data/
ROOT = TESTS.parent  #: the repository's root
DATA = TESTS / "data"  #: small input files of the tests
