"""Scene presets: every preset simulates, and the new ones have the property they are named for."""

from __future__ import annotations

import numpy as np
import pytest

from fusiongs.sim.dvs import DVSParams
from fusiongs.sim.presets import PRESETS
from fusiongs.sim.simulate import run_simulation, scene_renderer

from .conftest import tiny_config


def _mid_render(preset: str, width: int = 64, height: int = 48):
    r = scene_renderer(tiny_config(preset=preset, width=width, height=height, duration=1.0, frames=12,
                                   exposure=0.06))
    c2w = r.trajectory.c2w(np.array([0.5]))[0]
    return r, c2w, r.render(0.5).numpy()


@pytest.mark.parametrize("name", ["gallery", "dark", "depth", "hallway"])
def test_new_presets_simulate_a_tiny_scene_with_events_frames_and_truth(name):
    res = run_simulation(tiny_config(preset=name, duration=0.06, frames=1, exposure=0.02, novel=1,
                                     dvs=DVSParams(ba_rate_hz=0.0)))
    assert len(res.scene.events) > 100 and 0.2 < res.scene.events.polarity_balance < 0.8
    img = res.scene.frames.images[0]
    assert np.isfinite(img).all() and img.std() > 0.02
    assert set(res.gt) == {"deblur_000000", "novel_000"} and res.stats["preset"] == name


def test_all_presets_are_registered():
    assert {"boxes", "wall", "corridor", "gallery", "dark", "depth", "hallway", "walkway"} <= set(PRESETS)


def test_dark_preset_is_mostly_dark_with_a_few_bright_objects():
    _, _, img = _mid_render("dark")
    lum = img @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
    assert np.mean(lum < 0.03) > 0.8 and np.mean(lum > 0.2) > 0.02


def test_depth_preset_spans_near_objects_to_a_far_background():
    r, c2w, _ = _mid_render("depth")
    pts = r.caster.surface_points(c2w).numpy()
    z = (pts - c2w[:3, 3]) @ c2w[:3, :3][:, 2]
    assert np.percentile(z, 2) < 2.0 and np.percentile(z, 95) > 30.0


def test_gallery_has_fine_texture_at_the_default_resolution():
    # Mean absolute log-Laplacian at 173x130 (boxes / wall / corridor: 0.12 / 0.12 / 0.09).
    _, _, img = _mid_render("gallery", 173, 130)
    g = np.log(img @ np.array([0.299, 0.587, 0.114], dtype=np.float32) + 1e-3)
    lap = g[1:-1, 1:-1] - 0.25 * (g[:-2, 1:-1] + g[2:, 1:-1] + g[1:-1, :-2] + g[1:-1, 2:])
    assert np.abs(lap).mean() > 0.13


@pytest.mark.parametrize("name", ["hallway", "walkway"])
def test_a_walk_covers_10_m_in_20_s_and_its_view_is_new_at_the_end(name):
    r = scene_renderer(tiny_config(preset=name, width=48, height=36, duration=20.0, frames=240,
                                   exposure=0.06))
    c2w = r.trajectory.c2w(np.array([0.0, 10.0, 20.0]))
    walked = np.linalg.norm(c2w[1:, :3, 3] - c2w[:-1, :3, 3], axis=1)
    assert np.all(np.abs(walked - 5.0) < 0.2)
    first, last = r.render(0.0).numpy(), r.render(20.0).numpy()
    assert np.corrcoef(first.ravel(), last.ravel())[0, 1] < 0.5
