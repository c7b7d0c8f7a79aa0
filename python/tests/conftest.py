"""Shared fixtures of the specmux Python tests: the repository's files and the CLI to compare with."""

import os
import subprocess
from pathlib import Path

import pytest

# The source tree these tests belong to (scenes/, spectra/); the package itself is the installed one.
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def cli():
    """Run the `specmux` CLI ($SPECMUX_BIN, set by .ci/python-check.sh) and return its stdout."""
    binary = os.environ.get("SPECMUX_BIN")
    if not binary:
        pytest.skip("SPECMUX_BIN not set (.ci/python-check.sh sets it to the built CLI)")

    def run(*args, cwd=None):
        return subprocess.run(
            [binary, *map(str, args)], check=True, capture_output=True, text=True, cwd=cwd
        ).stdout

    return run
