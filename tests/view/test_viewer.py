"""``fusiongs view`` on finished runs: the page's slider and clicks (in process), an event-only run
of a recording without truth, and the page itself in a headless Chromium, whose screenshot must
show the run's scene from its first frame's fitted pose."""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.cli import main
from fusiongs.frames.image_io import read_image, write_png
from fusiongs.view.geometry import fov_y
from fusiongs.view.run import blurry_image, load_run, side_by_side, to_uint8
from fusiongs.view.server import enlarged, start_viewer
from tests.conftest import REPO_ROOT, simulated_scene, small_run
from tests.view.browser import find_browser, screenshot, url_in

WINDOW = (1000, 700)  # px; the panel floats over the right, a notice over the top left


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return small_run(tmp_path_factory)


@pytest.fixture(scope="module")
def viewer(run):
    v = start_viewer(load_run(run), "127.0.0.1", 0)
    yield v
    v.stop()


def _rendered(run: Path, t: float, out: Path) -> np.ndarray:
    """What ``fusiongs render RUN --t t`` writes, as uint8."""
    assert main(["render", str(run), "--t", repr(t), "-o", str(out)]) == 0
    return to_uint8(read_image(out / f"t_{t:.6f}.png"))


@pytest.mark.slow
def test_the_slider_shows_what_fusiongs_render_writes_at_that_instant(viewer, run, tmp_path):
    t = 0.5 * sum(viewer.run.t_range) + 0.0123
    viewer.slider.value = t
    expected = _rendered(run, t, tmp_path)
    assert np.abs(viewer.sharp.image.astype(int) - enlarged(expected).astype(int)).max() <= 1
    assert f"{t:.4f}" in viewer.sharp_label.content


@pytest.mark.slow
def test_a_clicked_frame_shows_blurry_beside_deblurred_and_moves_the_slider(viewer, run):
    frames = viewer.run.frames
    assert len(frames.frames) == 2 and frames.scene is not None and not frames.notes
    assert len(viewer.frustums) == 3  # the two frames and the render instant between them
    second = frames.frames[1]
    viewer.show_frame(second)
    scene = json.loads((frames.scene / "scene.json").read_text())
    blurry = to_uint8(read_image(frames.scene / scene["frames"][1]["path"]))
    deblurred = to_uint8(read_image(run / "deblurred" / f"{second.name}.png"))
    assert np.array_equal(blurry_image(frames.scene, second), blurry)  # sRGB frames: as stored
    assert np.array_equal(viewer.frame_image.image, enlarged(side_by_side(blurry, deblurred)))
    assert viewer.slider.value == pytest.approx(second.t_mid, abs=1e-3)
    assert second.name in viewer.frame_label.content and "blurry | deblurred" in viewer.frame_label.content


@pytest.fixture(scope="module")
def event_only_run(tmp_path_factory):
    """An event-only run (no frames) of a recording without truth images (gt/ removed)."""
    scene = simulated_scene(tmp_path_factory.mktemp("eo_scene"), preset="wall", frames=0, novel=2,
                            duration=0.15, dvs_rate_hz=600.0)
    shutil.rmtree(scene / "gt")
    out = tmp_path_factory.mktemp("eo_run")
    args = ["deblur", str(scene), "-o", str(out), "--config", "event_only", "init.n_points=300",
            "events.pixels=256", "optim.iterations=8", "densify.enabled=false", "event_only.alpha_warmup=3",
            "event_only.alpha_ramp=2", "event_only.hpf_readouts=20", "output.progress=false",
            "output.checkpoint_every=0"]
    assert main(args) == 0
    return out


def test_an_event_only_run_opens_at_the_path_start_with_its_render_instants(event_only_run, tmp_path):
    loaded = load_run(event_only_run)
    assert loaded.frames.frames == () and len(loaded.frames.renders) == 2 and not loaded.frames.notes
    assert loaded.t_open == loaded.t_range[0] and loaded.gain != 1.0  # exposure.json applied
    v = start_viewer(loaded, "127.0.0.1", 0)
    try:
        name, t = loaded.frames.renders[1]
        v.show_render(name, t)
        assert np.array_equal(v.frame_image.image,
                              enlarged(to_uint8(read_image(event_only_run / "renders" / f"{name}.png"))))
        expected = _rendered(event_only_run, t, tmp_path)
        assert np.abs(v.sharp.image.astype(int) - enlarged(expected).astype(int)).max() <= 1
        assert expected.mean() > 20  # not black: the exposure gain brought the renders up
    finally:
        v.stop()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _window_render(run: Path, fov_scale: float = 1.0) -> np.ndarray:
    """fusiongs' render at the first frame's fitted pose through a pinhole of the browser window
    (viser: the camera's vertical field of view, principal point centred), ``fov_scale`` times it."""
    from fusiongs.train.render_io import render_srgb

    loaded = load_run(run)
    w, h = WINDOW
    f = 0.5 * h / math.tan(0.5 * fov_y(loaded.camera) * fov_scale)
    cam = PinholeCamera(width=w, height=h, fx=f, fy=f, cx=0.5 * w, cy=0.5 * h)
    return render_srgb(loaded.state, cam, [loaded.t_open], loaded.backend, gain=loaded.gain)[0]


def _scene_area() -> np.ndarray:
    """``[H, W]`` the window's pixels that no panel covers: left of the floating panel (340 px
    wide), below the software-WebGL notice (top left), clear of the axes gizmo (bottom left)."""
    w, h = WINDOW
    mask = np.zeros((h, w), bool)
    mask[:, : w - 360] = True
    mask[:180, :340] = False
    mask[h - 90:, :90] = False
    return mask


def _correlation(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    return float(np.corrcoef(a.mean(-1)[mask], b.mean(-1)[mask])[0, 1])


@pytest.mark.slow
def test_the_page_in_a_browser_shows_the_scene_from_the_first_frame(run, tmp_path):
    exe = find_browser()
    if exe is None:
        pytest.skip("no chromium on PATH (the CI installs it: apt-get install -y chromium)")
    port = _free_port()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-m", "fusiongs", "view", str(run), "--port", str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    try:
        url, lines, deadline = None, [], time.monotonic() + 180
        while url is None and time.monotonic() < deadline and proc.poll() is None:
            line = proc.stdout.readline()
            lines.append(line)
            url = url_in(line) if "fusiongs view:" in line else None
        assert url == f"http://127.0.0.1:{port}", "".join(lines)
        shot = screenshot(url, *WINDOW, exe=exe)
        expected, wider = _window_render(run), _window_render(run, 1.25)
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            rc = proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            rc = proc.wait()
    assert shot.shape[:2] == WINDOW[::-1]
    write_png(tmp_path / "viewer.png", shot)  # kept with pytest's temporary folders, to look at
    mask = _scene_area()
    match, off = _correlation(shot, expected, mask), _correlation(shot, wider, mask)
    print(f"screenshot against fusiongs' render at the opening pose: r = {match:.3f} (field of view 25 % "
          f"wider: r = {off:.3f})")
    assert match > 0.9 and match > off + 0.05
    assert rc == 0  # Ctrl-C ends the viewer normally
