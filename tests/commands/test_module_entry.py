"""``python -m fusiongs`` is the ``fusiongs`` command (machines where the console script is not on
PATH, e.g. a package unpacked with ``pip --target``, as benchmarks/bench_gpu.sh does)."""

from __future__ import annotations

import subprocess
import sys

import fusiongs


def test_python_m_fusiongs_runs_the_cli():
    out = subprocess.run([sys.executable, "-m", "fusiongs", "--version"], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert fusiongs.__version__ in out.stdout


def test_python_m_fusiongs_passes_the_exit_status_on():
    out = subprocess.run([sys.executable, "-m", "fusiongs", "inspect", "/nonexistent/scene"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    assert "/nonexistent/scene" in out.stderr
