"""Thresholds fitted to the renders when the events start (``threshold.render_floor``;
:mod:`fusiongs.train.render_threshold`)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fusiongs.camera.pinhole import PinholeCamera
from fusiongs.errors import InputError
from fusiongs.events.stream import EventStream
from fusiongs.losses.colour import cfa_index
from fusiongs.train.data import TrainData, event_indices
from fusiongs.train.render_threshold import (
    RenderFloor,
    raise_to_render_floor,
    render_floor,
    solve_floor,
    window_sums,
)
from fusiongs.train.schedules import sample_free_windows

CPU = torch.device("cpu")
H, W, EPS = 24, 32, 1e-3
THETA_POS = np.array([0.15, 0.20, 0.26])  # R, G, B
THETA_NEG = np.array([0.30, 0.24, 0.18])


def _ideal_events(rate: np.ndarray, offset: np.ndarray, th_pos: np.ndarray, th_neg: np.ndarray,
                  duration: float) -> tuple[np.ndarray, ...]:
    """Events of ideal DVS pixels whose log intensity changes at a constant ``rate`` [H, W] (1/s):
    a pixel fires each time it has moved a threshold past its reference level, which starts
    ``offset`` (a fraction of a threshold) away."""
    ts, xs, ys, ps = [], [], [], []
    for (y, x), a in np.ndenumerate(rate):
        th = th_pos[y, x] if a > 0 else th_neg[y, x]
        k = np.arange(1, int(abs(a) * duration / th) + 2)
        t = (k - offset[y, x]) * th / abs(a)
        t = t[(t >= 0) & (t < duration)]
        ts.append(t), xs.append(np.full(t.size, x)), ys.append(np.full(t.size, y))
        ps.append(np.full(t.size, 1 if a > 0 else -1))
    t = np.concatenate(ts)
    order = np.argsort(t, kind="stable")
    return (np.round(t[order] * 1e6).astype(np.int64), np.concatenate(xs)[order],
            np.concatenate(ys)[order], np.concatenate(ps)[order])


class _Ramps:
    """A stand-in for the state: linear renders of per-pixel log-intensity ramps ``L0 + a t``."""

    def __init__(self, log0: np.ndarray, rate: np.ndarray, scale: float = 1.0):
        self.log0 = torch.from_numpy(log0)
        self.rate = torch.from_numpy(rate) * scale  # scale < 1: a render with too little contrast

    def render(self, camera, t, backend="auto", check_values=True):
        log = self.log0[None] + self.rate[None] * t[:, None, None]
        lin = (torch.exp(log) - EPS).to(torch.float32)[..., None].expand(-1, -1, -1, 3)
        return lin, None, None


@pytest.fixture(scope="module")
def ramps():
    rng = np.random.default_rng(0)
    rate = rng.uniform(0.5, 3.0, (H, W)) * rng.choice([-1.0, 1.0], (H, W))
    log0 = rng.uniform(-2.0, -0.5, (H, W))
    ch = cfa_index("RGGB", H, W).numpy()
    events = EventStream.create(*_ideal_events(rate, rng.uniform(0, 1, (H, W)), THETA_POS[ch],
                                               THETA_NEG[ch], 1.0), W, H, "RGGB")
    data = TrainData(camera=PinholeCamera(W, H, 30.0, 30.0, W / 2, H / 2),
                     targets=torch.zeros(2, H, W, 3), response="linear",
                     exposures=torch.tensor([[0.1, 0.15], [0.6, 0.65]], dtype=torch.float64),
                     names=("a", "b"), events=events, cfa_index=cfa_index("RGGB", H, W, CPU),
                     t_range=(0.0, 1.0), frame_interval=0.5, event_index=event_indices(events, CPU))
    return log0, rate, data


def _windows(n: int = 16) -> list[tuple[float, float]]:
    return sample_free_windows(n, (0.0, 1.0), 0.5, torch.Generator().manual_seed(1), 0.05, "linear").tolist()


@pytest.mark.parametrize("sigma", [0.0, 2.0])
def test_the_fit_recovers_each_channels_thresholds_from_renders_with_the_true_contrast(ramps, sigma):
    log0, rate, data = ramps
    floor = render_floor(_Ramps(log0, rate), data, _windows(), (0.299, 0.587, 0.114), EPS, min_pixels=20,
                         sigma=sigma)
    # what is left is the DVS pixel's lag (its reference level is up to a threshold behind)
    np.testing.assert_allclose(floor.theta[0].numpy(), THETA_POS, rtol=0.05)
    np.testing.assert_allclose(floor.theta[1].numpy(), THETA_NEG, rtol=0.05)
    assert (floor.pixels > 20).all()


def test_renders_with_too_little_contrast_read_low_and_never_raise_theta_past_them(ramps):
    """The floor's premise: a model smoother than the scene fits a smaller θ."""
    log0, rate, data = ramps
    floor = render_floor(_Ramps(log0, rate, 0.7), data, _windows(), (0.299, 0.587, 0.114), EPS, min_pixels=20)
    np.testing.assert_allclose(floor.theta[0].numpy(), 0.7 * THETA_POS, rtol=0.05)
    true_log = torch.log(torch.tensor(np.stack([THETA_POS, THETA_NEG]), dtype=torch.float32))
    np.testing.assert_array_equal(raise_to_render_floor(true_log, floor).numpy(), true_log.numpy())
    raised = raise_to_render_floor(true_log - 1.0, floor)  # a start far below: raised to the floor
    np.testing.assert_allclose(torch.exp(raised).numpy(), 0.7 * np.stack([THETA_POS, THETA_NEG]), rtol=0.05)


def test_counts_marked_as_lower_bounds_are_left_out(ramps):
    """Where a pixel lost events (dead time) and they are marked fast, the fit does not see them;
    unmarked, the same losses pull θ up."""
    log0, rate, data = ramps
    ev = data.events
    lossy = (ev.x < 3 * W // 4) & (np.arange(len(ev)) % 2 == 0)  # half the events of 3/4 of the pixels lost
    kept = EventStream.create(ev.t[~lossy], ev.x[~lossy], ev.y[~lossy], ev.p[~lossy], W, H, "RGGB")
    thin = TrainData(**{**data.__dict__, "events": kept, "event_index": event_indices(kept, CPU),
                        "_coarse": {}})
    args = (_Ramps(log0, rate), thin, _windows(), (0.299, 0.587, 0.114), EPS)
    unmarked = render_floor(*args, min_pixels=20)
    assert (unmarked.theta[:, 1] > 1.2 * torch.tensor([THETA_POS[1], THETA_NEG[1]])).all()
    thin.fast = torch.from_numpy(kept.x < 3 * W // 4)
    marked = render_floor(*args, min_pixels=20)
    np.testing.assert_allclose(marked.theta.numpy(), np.stack([THETA_POS, THETA_NEG]), rtol=0.05)


def _noisy_maps(seed: int, shape: tuple[int, int]):
    """Random counts, CFA channels and kept pixels, and log changes ``0.2 n₊ − 0.3 n₋`` plus noise."""
    rng = np.random.default_rng(seed)
    n_pos, n_neg = rng.poisson(2.0, (2, *shape)).astype(np.float64)
    d = 0.2 * n_pos - 0.3 * n_neg + rng.normal(0, 0.05, shape)
    return d, n_pos, n_neg, rng.integers(0, 3, shape), rng.random(shape) > 0.1


def _sums(d, n_pos, n_neg, ch, keep, sigma=0.0):
    t = [torch.from_numpy(v) for v in (d, n_pos, n_neg, ch, keep)]
    return window_sums(*t, 3, sigma)


def test_closed_form_matches_least_squares_per_channel():
    d, n_pos, n_neg, ch, keep = _noisy_maps(2, (20, 25))
    sums = _sums(d, n_pos, n_neg, ch, keep)
    floor = solve_floor(sums, min_pixels=10)
    for c in range(3):
        m = keep & (ch == c)
        ref = np.linalg.lstsq(np.stack([n_pos[m], -n_neg[m]], 1), d[m], rcond=None)[0]
        np.testing.assert_allclose(floor.theta[:, c].numpy(), ref, rtol=1e-9)
        assert floor.pixels[0, c] == (n_pos[m] > 0).sum() and floor.pixels[1, c] == (n_neg[m] > 0).sum()


def test_low_passed_sums_match_a_per_channel_opencv_blur():
    """The fast path blurs every channel's masked maps at once (kornia); the reference blurs each
    one separately with OpenCV (zero outside the image) and fits by least squares."""
    import cv2

    d, n_pos, n_neg, ch, keep = _noisy_maps(3, (18, 22))
    floor = solve_floor(_sums(d, n_pos, n_neg, ch, keep, sigma=1.5), 10)
    k = 2 * int(np.ceil(4.5)) + 1
    for c in range(3):
        m = (keep & (ch == c)).astype(np.float64)
        b = [cv2.GaussianBlur(v * m, (k, k), 1.5, borderType=cv2.BORDER_CONSTANT).ravel()
             for v in (d, n_pos, n_neg)]
        ref = np.linalg.lstsq(np.stack([b[1], -b[2]], 1), b[0], rcond=None)[0]
        np.testing.assert_allclose(floor.theta[:, c].numpy(), ref, rtol=1e-6)


def test_too_few_pixels_or_a_negative_fit_leave_theta_unchanged():
    sums = torch.zeros(7, 2, dtype=torch.float64)
    sums[:, 0] = torch.tensor([10.0, 0.0, 10.0, 2.0, -3.0, 5.0, 5.0])  # θ 0.2 / 0.3 from 5 pixels each
    sums[:, 1] = torch.tensor([10.0, 0.0, 10.0, -2.0, -3.0, 500.0, 500.0])  # θ₊ < 0
    assert torch.isnan(solve_floor(sums, min_pixels=6).theta).all()
    floor = solve_floor(sums, min_pixels=5)
    np.testing.assert_allclose(floor.theta[:, 0].numpy(), [0.2, 0.3])
    assert torch.isnan(floor.theta[:, 1]).all()
    log_theta = torch.log(torch.tensor([[0.1, 0.1], [0.1, 0.1]]))
    out = raise_to_render_floor(log_theta, floor)
    np.testing.assert_allclose(torch.exp(out).numpy(), [[0.2, 0.1], [0.3, 0.1]], rtol=1e-6)
    one = RenderFloor(torch.tensor([[0.2], [0.05]]), torch.tensor([[9.0], [9.0]]))
    np.testing.assert_allclose(torch.exp(raise_to_render_floor(log_theta, one)).numpy(),
                               [[0.2, 0.2], [0.1, 0.1]], rtol=1e-6)


def test_windows_lie_inside_the_range_with_lengths_in_bounds():
    """The fit's windows: the training's sampler with durations uniform, not log-uniform."""
    w = sample_free_windows(200, (2.0, 3.0), 0.4, torch.Generator().manual_seed(0), 0.1, "linear").numpy()
    length = w[:, 1] - w[:, 0]
    assert (w[:, 0] >= 2.0).all() and (w[:, 1] <= 3.0 + 1e-12).all()
    assert length.min() >= 0.1 - 1e-12 and length.max() <= 0.4 + 1e-12 and length.std() > 0.05
    assert abs(length.mean() - 0.25) < 0.02  # log-uniform would give 0.3 / ln 4 = 0.216
    with pytest.raises(InputError, match="spacing"):
        sample_free_windows(2, (2.0, 3.0), 0.4, None, 0.1, "cubic")


@pytest.mark.parametrize("floor", [True, False])
def test_deblur_lifts_theta_to_the_floor_once_when_the_events_start(tiny_scene, tmp_path, capsys, monkeypatch,
                                                                    floor):
    """The trainer's wiring: the fit (tested above on ramps; replaced here by a fixed floor, since
    the tiny run's renders after 4 iterations fit nothing) is made once, at ``events.warmup``
    (4), from the state then; θ rises to it where it is larger and the run says so. θ is not
    learned here, so the history shows the lift alone."""
    import json

    import fusiongs.train.render_threshold as rt
    from fusiongs.cli import main
    from tests.conftest import TINY

    calls = []

    def fixed(state, data, windows, *args, **kwargs):
        calls.append(len(windows))
        return RenderFloor(torch.tensor([[0.05], [0.002]]), torch.tensor([[500.0], [500.0]]))

    monkeypatch.setattr(rt, "render_floor", fixed)
    args = ["deblur", str(tiny_scene), "-o", str(tmp_path), *TINY, "threshold.estimate=false",
            "threshold.init=0.005", "threshold.learn=false", "threshold.render_floor_windows=7",
            f"threshold.render_floor={str(floor).lower()}"]
    assert main(args) == 0
    rows = [json.loads(line) for line in (tmp_path / "history.jsonl").read_text().splitlines()]
    theta = {r["iteration"]: r["theta_pos"] + r["theta_neg"] for r in rows}
    assert all(v == pytest.approx([0.005, 0.005]) for it, v in theta.items() if it < 4)
    said = capsys.readouterr().err.count("θ raised to the renders' floor")
    assert calls == ([7] if floor else []) and said == (1 if floor else 0)
    after = [0.05, 0.005] if floor else [0.005, 0.005]  # OFF's floor is below its start: kept
    assert all(v == pytest.approx(after) for it, v in theta.items() if it >= 4)


def test_no_windows_is_refused_naming_the_key():
    from fusiongs.errors import ConfigError
    from fusiongs.pipeline.deblur import resolve_config

    with pytest.raises(ConfigError, match="threshold.render_floor_windows"):
        resolve_config(None, ["threshold.render_floor_windows=0"])
