"""The two example optimisation loops run as scripts and converge (each
checks its own convergence criterion with --check)."""

import pathlib
import subprocess
import sys

import pytest

EXAMPLES = pathlib.Path(__file__).resolve().parents[1] / "examples"


def run(name, *args):
    r = subprocess.run(
        [sys.executable, str(EXAMPLES / name), "--check", *args],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    return r.stdout


def test_numpy_example_recovers_the_red_wall(tmp_path):
    out = run("optimize_numpy.py", "--out", str(tmp_path))
    assert "max error" in out
    assert (tmp_path / "final.png").exists()


def test_torch_example_recovers_the_texture():
    pytest.importorskip("torch")
    out = run("optimize_torch.py")
    assert "texture RMS error" in out
