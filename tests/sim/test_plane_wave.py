"""The closed-form plane-wave scene: events that EDI's model explains exactly, and its bad input."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from fusiongs.errors import InputError
from fusiongs.io.scene_io import load_scene
from fusiongs.sim.plane_wave import PlaneWave, log_intensity, write_plane_wave_scene


def test_signed_counts_follow_the_log_intensity(tmp_path):
    """Between any two instants, ON minus OFF counts times theta equal the change of the log
    intensity to within one level (the scene's events are the level crossings)."""
    pw = PlaneWave(events=200_000, width=32, height=24, duration=2.0, frames=3)
    info = write_plane_wave_scene(pw, tmp_path / "pw")
    scene = load_scene(tmp_path / "pw")
    assert len(scene.events) == info["events"] and abs(info["events"] / pw.events - 1) < 0.05
    a, b = 0.3, 1.7
    n = scene.events.signed_count_map(int(a * 1e6), int(b * 1e6))
    change = log_intensity(pw, b) - log_intensity(pw, a)
    assert np.abs(n * pw.theta - change).max() <= pw.theta + 1e-6


@pytest.mark.parametrize("args, words", [
    (["--size", "12by9"], "--size"),
    (["--events", "0"], "events"),
    (["--duration", "-1"], "duration"),
])
def test_bad_arguments_are_one_line_exit_2(tmp_path, args, words):
    res = subprocess.run([sys.executable, "-m", "fusiongs.sim.plane_wave", str(tmp_path / "s"), *args],
                         capture_output=True, text=True)
    assert res.returncode == 2
    last = res.stderr.strip().splitlines()[-1]
    assert words in last and "Traceback" not in res.stderr


def test_an_existing_scene_is_not_overwritten(tmp_path):
    (tmp_path / "scene.json").write_text("{}")
    res = subprocess.run([sys.executable, "-m", "fusiongs.sim.plane_wave", str(tmp_path), "--events", "1000",
                          "--size", "8x6"], capture_output=True, text=True)
    assert res.returncode == 2 and "already" in res.stderr
    assert (tmp_path / "scene.json").read_text() == "{}"
    with pytest.raises(InputError, match="amplitude_spread"):
        PlaneWave(amplitude_spread=1.0)
