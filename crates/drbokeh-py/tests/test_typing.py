"""The package's types check: mypy over ``python/drbokeh`` (the pure-Python modules, against
the stubs of ``drbokeh._native``, numpy's and torch's). ``scripts/test`` installs the mypy
it was written against; without mypy the test is skipped."""

import subprocess
import sys
from pathlib import Path

import pytest


def test_the_package_type_checks(tmp_path):
    pytest.importorskip("mypy", reason="mypy is not installed (scripts/test installs it)")
    package = Path(__file__).resolve().parent.parent / "python" / "drbokeh"
    p = subprocess.run(
        [sys.executable, "-m", "mypy", "--cache-dir", str(tmp_path / "cache"), str(package)],
        capture_output=True, text=True, timeout=600,
    )
    assert p.returncode == 0, p.stdout + p.stderr
    assert "Success" in p.stdout
