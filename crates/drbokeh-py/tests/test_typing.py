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


def test_the_stub_matches_the_compiled_module(tmp_path):
    """``_native.pyi`` against the installed ``drbokeh._native`` (mypy's stubtest): every
    function and class of the module is in the stub with the runtime's parameters (names,
    kinds, defaults), and the stub names nothing the module lacks."""
    pytest.importorskip("mypy", reason="mypy is not installed (scripts/test installs it)")
    p = subprocess.run(
        [sys.executable, "-m", "mypy.stubtest", "drbokeh._native"],
        capture_output=True, text=True, timeout=600, cwd=tmp_path,
    )
    assert p.returncode == 0, p.stdout + p.stderr
