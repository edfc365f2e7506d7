"""Shared helpers of the rovib Python tests: the repository root and the `rovib` command."""

import os
import subprocess

import pytest

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


def cli(*args):
    """Runs the `rovib` command of this checkout (``$ROVIB_CLI`` if set, else ``cargo run
    --release``) and returns the completed process (stdout and stderr as text)."""
    exe = os.environ.get("ROVIB_CLI")
    cmd = [exe] if exe else ["cargo", "run", "--release", "--quiet", "--manifest-path", os.path.join(ROOT, "Cargo.toml"), "--"]
    return subprocess.run(cmd + list(args), capture_output=True, text=True, cwd=ROOT)


@pytest.fixture
def root():
    return ROOT
