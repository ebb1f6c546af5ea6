"""benchmarks/bench_calibrate_resim.py: the recording's own sensor parameters and the re-simulated
events, on streams whose rates and crossings are known."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from benchmarks.bench_calibrate_resim import (
    estimated_sensor,
    events_with,
    fast_steps,
    isolated_rates,
    main,
    own_log,
    sim_video,
)
from fusiongs.events.stream import EventStream
from fusiongs.frames.frameset import FrameSet
from fusiongs.sim.dvs import DVSParams, sensor_log
from fusiongs.sim.simulate import SimConfig, scene_renderer

W, H, T = 60, 40, 4.0  # sensor and span (s)


def _poisson(rate: float, polarity: int | None, rng: np.random.Generator):
    n = rng.poisson(rate * W * H * T)
    t = rng.integers(0, int(T * 1e6), n)
    p = rng.choice([-1, 1], n) if polarity is None else np.full(n, polarity)
    return t, rng.integers(0, W, n), rng.integers(0, H, n), p


def _stream(parts) -> EventStream:
    t, x, y, p = (np.concatenate(v) for v in zip(*parts))
    return EventStream.create(t, x, y, p, W, H, sort=True)


def test_isolated_rates_recover_background_and_leak_beside_an_edge():
    rng = np.random.default_rng(3)
    ba, leak = 2.0, 0.5
    # a bar sweeping across the sensor eight times: each column fires ON on all rows, 2 ms apart
    sweep_t = (np.arange(8)[:, None] * 0.5 + np.arange(W)[None] * 2e-3).ravel()
    xs = np.tile(np.arange(W), 8)
    edge = (np.repeat((sweep_t * 1e6).astype(np.int64), H), np.repeat(xs, H),
            np.tile(np.arange(H), xs.size), np.ones(xs.size * H, np.int64))
    ev = _stream([_poisson(ba, None, rng), _poisson(leak, 1, rng), edge])
    assert len(ev) > 3 * (ba + leak) * W * H  # the edge's events outnumber the noise
    on, off = isolated_rates(ev, np.zeros(W * H, bool), T)
    assert 2 * off == pytest.approx(ba, rel=0.15)
    assert on - off == pytest.approx(leak, abs=0.15)


def test_isolated_rates_leave_out_hot_pixels():
    rng = np.random.default_rng(4)
    hot_pix = rng.choice(W * H, 48, replace=False)  # 2 % of the pixels fire ON at 30 Hz
    n = rng.poisson(30 * T, hot_pix.size)
    idx = np.repeat(hot_pix, n)
    hot_t = rng.integers(0, int(T * 1e6), idx.size)
    hot = (hot_t, idx % W, idx // W, np.ones(idx.size, np.int64))
    ev = _stream([_poisson(1.0, None, rng), hot])
    mask = np.zeros(W * H, bool)
    mask[hot_pix] = True
    on, off = isolated_rates(ev, mask, T)
    assert on - off == pytest.approx(0.0, abs=0.1)
    assert 2 * off == pytest.approx(1.0, rel=0.15)
    on_all, off_all = isolated_rates(ev, np.zeros(W * H, bool), T)
    assert on_all - off_all > on - off + 0.1  # kept in, the hot pixels read as leak


def test_events_with_uses_the_given_thresholds_and_dead_time():
    cfg = SimConfig(width=2, height=1, duration=0.01, dvs_rate_hz=1000.0, seed=1)
    quiet = dataclasses.replace(DVSParams(), theta_sigma=0.0, refractory_s=0.0, ba_rate_hz=0.0,
                                hot_pixel_fraction=0.0, leak_rate_hz=0.0)
    k = np.arange(11)[:, None]
    logs = np.concatenate([0.1 * k, -0.105 * k], 1).astype(np.float32)  # +1.0, -1.05 in 10 ms
    ev = events_with(cfg, quiet, logs, (0.25, 0.2), 0.0, seed=0)
    on = ev.p > 0
    assert (ev.x[on] == 0).all() and (ev.x[~on] == 1).all()
    assert int(on.sum()) == 4 and int((~on).sum()) == 5  # floor(1.0 / θ) crossings each
    slow = events_with(cfg, dataclasses.replace(quiet, refractory_s=4e-3), logs, (0.25, 0.2), 0.0, seed=0)
    assert len(slow) < len(ev)  # the dead time drops crossings


def test_the_twin_takes_the_located_refractory_period():
    """The twin's dead time is the period the recording's intervals step at, not the histogram
    bin's left edge the gates count in (866 µs for a 972 µs sensor); a calibration written before
    the period was reported gives the edge."""
    ev = _stream([_poisson(2.0, None, np.random.default_rng(0))])
    est = SimpleNamespace(details={"dead_time_us": 866.0, "refractory_period_us": 972.0})
    params, _ = estimated_sensor(DVSParams(), est, ev, T)
    assert params.refractory_s == pytest.approx(972e-6)
    est.details.pop("refractory_period_us")
    assert estimated_sensor(DVSParams(), est, ev, T)[0].refractory_s == pytest.approx(866e-6)


def test_own_log_takes_each_pixels_channel():
    img = np.zeros((2, 2, 3), np.float32)
    img[..., 0], img[..., 1], img[..., 2] = 0.5, 0.25, 0.125
    cfa = np.array([[0, 1], [1, 2]])  # RGGB
    out = own_log(img, cfa, 0.0)
    assert np.allclose(np.exp(out), [0.5, 0.25, 0.25, 0.125])
    grey = own_log(img, None, 0.0)
    assert np.allclose(np.exp(grey), 0.299 * 0.5 + 0.587 * 0.25 + 0.114 * 0.125)


def test_fast_steps_count_large_changes_between_render_steps():
    logs = np.zeros((4, 3), np.float32)
    logs[1, 0], logs[2, 0] = 0.5, 0.1  # up 0.5, down 0.4: two fast steps
    logs[1:, 1] = 0.2  # one step of 0.2: not fast
    logs[3, 2] = -0.31  # one fast step down
    assert fast_steps(logs) == 3
    assert fast_steps(logs, step=0.45) == 1


def test_sim_video_matches_the_simulator_and_blur_takes_fast_steps_away():
    cfg = SimConfig(preset="wall", width=40, height=30, duration=0.02, dvs_rate_hz=1000.0, seed=5,
                    cfa="RGGB")
    frames = FrameSet(np.zeros((1, 30, 40, 3), np.float32), np.array([0.0]), np.array([0.01]),
                      ["f0"], "linear")
    logs, made = sim_video(SimpleNamespace(frames=frames), cfg)
    render = scene_renderer(cfg).render
    for k in (0, 20):
        assert np.allclose(logs[k], sensor_log(render(k * 1e-3), "RGGB", cfg.dvs.eps), atol=1e-5)
    assert made.images.shape == (1, 30, 40, 3) and float(made.images.max()) > 0  # frames made again
    blurred, _ = sim_video(SimpleNamespace(frames=frames), cfg, blur=1.5)
    assert fast_steps(blurred, 0.05) < fast_steps(logs, 0.05)


@pytest.mark.parametrize("args", [["--video", "flow", "--blur", "0.5"], ["--trajectory", "run"],
                                  ["--blur", "-1"]])
def test_main_refuses_inconsistent_variants(args, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["no_such_scene", *args])
    assert exc.value.code == 2
    assert len(capsys.readouterr().err.strip().splitlines()[-1]) > 0
