# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 2. Colour from Bayer events
#
# A colour event camera such as the Color-DAVIS346 puts a 2x2 **Bayer colour filter array** (CFA)
# over its pixels: every pixel sees only red, green or blue light, and its events report changes of
# that one channel. This notebook
#
# 1. explains the four Bayer layouts with pictures,
# 2. mosaics a photo, demosaics it back with OpenCV and kornia (through `fusiongs.events.cfa`), and
#    measures what a **wrong pattern name** costs,
# 3. simulates a colour event camera and draws its events channel by channel.
#
# With `FUSIONGS_NOTEBOOK_FAST=1` (as in CI) sizes are tiny.

# %%
import json
import os
from pathlib import Path

import numpy as np

from fusiongs import viz
from fusiongs.eval.metrics import psnr
from fusiongs.events.cfa import cfa_channel_index, cfa_masks, demosaic, mosaic
from fusiongs.events.stream import CFA_PATTERNS
from fusiongs.frames.response import linear_to_srgb
from fusiongs.sim.simulate import SimConfig, run_simulation
from fusiongs.sim.textures import load_photo

FAST = os.environ.get("FUSIONGS_NOTEBOOK_FAST") == "1"
WORK = Path("nb02_work")
WORK.mkdir(exist_ok=True)
print("fast mode" if FAST else "tutorial mode")

# %% [markdown]
# ## 1. The four Bayer layouts
#
# A layout is named by its top-left 2x2 cell read row by row. `RGGB` (the Color-DAVIS346) has R at
# even rows and even columns, G at (even, odd) and (odd, even), B at (odd, odd). Half the pixels
# are green, a quarter red, a quarter blue.

# %%
fig = viz.strip([viz.cfa_mask_image(p, 6, 6) for p in CFA_PATTERNS], list(CFA_PATTERNS),
                height_in=2.0, suptitle="top-left 6x6 pixels of each layout")
for p in CFA_PATTERNS:
    print(p, "channel index (0 = R, 1 = G, 2 = B) of the top-left cell:",
          cfa_channel_index(p, 2, 2).tolist())

# %% [markdown]
# ## 2. Mosaic and demosaic a photo
#
# A raw sensor image is linear light sampled through the filter: one value per pixel. `mosaic`
# does that to a full-colour photo (scikit-image's *astronaut*, in linear light); `demosaic`
# interpolates the two missing channels of every pixel back. All comparisons are in 8-bit sRGB.

# %%
side = 128 if FAST else 384
photo = load_photo("astronaut", max_side=side)  # [H, W, 3] linear
photo = photo[: photo.shape[0] // 2 * 2, : photo.shape[1] // 2 * 2]
truth = linear_to_srgb(photo)
raw = mosaic(photo, "RGGB")  # [H, W] linear
as_colour = photo * cfa_masks("RGGB", *raw.shape).transpose(1, 2, 0)  # each pixel in its filter colour
crop = (slice(side // 8, 3 * side // 8), slice(3 * side // 8, 5 * side // 8))  # the face
fig = viz.strip([truth, linear_to_srgb(raw), linear_to_srgb(as_colour), linear_to_srgb(as_colour)[crop]],
                ["photo", "RGGB mosaic (one value per pixel)", "the same, in filter colours",
                 "zoom: the 2x2 pattern"])

# %% [markdown]
# fusiongs offers several demosaicing methods: `bilinear` (its own, for any float data including
# signed event maps; differentiable in torch), OpenCV's bilinear, edge-aware (`opencv-ea`) and VNG
# (`opencv-vng`), and `kornia` (bilinear, differentiable).

# %%
methods = ("bilinear", "opencv-bilinear", "opencv-ea", "opencv-vng", "kornia")
recon = {m: linear_to_srgb(np.clip(demosaic(raw, "RGGB", m), 0.0, 1.0)) for m in methods}
for m in methods:
    print(f"{m:<16} {psnr(recon[m], truth):6.2f} dB")
fig = viz.strip([truth[crop]] + [recon[m][crop] for m in methods], ["truth"] + list(methods),
                height_in=2.2, suptitle="zoom, demosaiced from the RGGB mosaic")

# %% [markdown]
# ### The wrong pattern name
#
# The name is easy to get wrong: OpenCV's Bayer conversion codes name the pattern by the colours
# of the **second** row and column (pixel (1, 1) onwards), so an RGGB sensor is
# `COLOR_BayerBG2RGB` (OpenCV 5 adds the alias `COLOR_BayerRGGB2RGB`), and kornia calls it
# `CFA.BG`. fusiongs always uses the top-left reading and translates. Below, the RGGB mosaic is
# demosaiced under each of the four names: the correct one, and three mistakes (`BGGR` is exactly
# what `COLOR_BayerRG2RGB` does, the natural-looking but wrong OpenCV code for an RGGB sensor).

# %%
wrong = {p: linear_to_srgb(np.clip(demosaic(raw, p, "opencv-ea"), 0.0, 1.0)) for p in CFA_PATTERNS}
scores = {p: psnr(img, truth) for p, img in wrong.items()}
for p, v in scores.items():
    print(f"demosaiced as {p}: {v:6.2f} dB" + ("   <- the sensor's pattern" if p == "RGGB" else ""))
fig = viz.strip([wrong[p] for p in CFA_PATTERNS], [f"as {p}: {scores[p]:.1f} dB" for p in CFA_PATTERNS],
                height_in=2.4, suptitle="the RGGB mosaic demosaiced (opencv-ea) under each pattern name")

# %% [markdown]
# Swapping R and B (`BGGR`) keeps the image sharp but turns the orange suit blue; the G-first
# names interpolate green from red and blue samples and draw a maze of false colour. Either way it
# costs far more than the choice of demosaicing method, and a swapped R/B still looks like a
# plausible image, which is why that mistake survives.

# %% [markdown]
# ## 3. Colour events from the simulator
#
# `SimConfig(cfa="RGGB")` simulates a colour event sensor: each pixel's log intensity is taken in
# its own filter channel, so its events report changes of red, green or blue light only. The
# event stream carries the pattern (`events.cfa`), and so does the scene folder (`scene.json`:
# `"events": {"cfa": "RGGB"}`).

# %%
size = (48, 36) if FAST else (173, 130)
sim = run_simulation(SimConfig(preset="boxes", width=size[0], height=size[1], duration=0.1 if FAST else 0.5,
                               frames=1, exposure=0.05, cfa="RGGB", blur_samples=4 if FAST else 24,
                               dvs_rate_hz=400.0 if FAST else 1000.0, supersample=1 if FAST else 2,
                               novel=0, seed=0))
ev = sim.scene.events
masks = cfa_masks(ev.cfa, ev.height, ev.width)
print(f"{len(ev):,} events, CFA {ev.cfa}, {ev.width}x{ev.height}")
for c, name in enumerate("RGB"):
    n = ev.count_maps()[:, masks[c]].sum(axis=1)
    print(f"  {name} pixels ({masks[c].mean():.0%} of the sensor): {n.sum():,} events, ON fraction "
          f"{n[0] / max(n.sum(), 1):.3f}, {n.sum() / masks[c].sum():.1f} per pixel")

# %% [markdown]
# Below: the events of a short window drawn for all pixels, then for each channel's pixels alone
# (other pixels grey). An edge between two surfaces of different colour fires differently in the
# three channels: that difference is the colour information the events carry.

# %%
t_mid = int(ev.t[len(ev) // 2])
win = 10_000 if FAST else 5_000
a, b = t_mid - win // 2, t_mid + win // 2
frames = [viz.event_frame(ev, a, b)] + [viz.event_frame(ev, a, b, mask=masks[c]) for c in range(3)]
fig = viz.strip(frames, ["all pixels", "R pixels", "G pixels", "B pixels"],
                suptitle=f"events in [{a * 1e-3:.1f}, {b * 1e-3:.1f}) ms")

# %% [markdown]
# The per-channel maps live on the raw grid. Demosaicing the signed event counts (the `bilinear`
# method accepts signed data) turns them into a three-channel "colour change" picture: where it is
# not grey, the brightness changed differently in the three channels.

# %%
signed = ev.signed_count_map(a, b).astype(np.float32)
rgb_change = demosaic(signed, ev.cfa, "bilinear")  # [H, W, 3] signed counts per channel
scale = max(float(np.percentile(np.abs(rgb_change), 99.5)), 1e-6)
fig = viz.strip([sim.scene.frames.images[0], np.clip(0.5 + 0.5 * rgb_change / scale, 0.0, 1.0)],
                ["the simulated (blurry) frame", "demosaiced signed event counts (0.5 = no change)"])

# %% [markdown]
# ## 4. Colour reconstruction from events alone
#
# A scene without frames is reconstructed by the same `fusiongs deblur` command with
# `configs/event_only.yaml`: the loss is `α·L_event + (1−α)·L_intensity`, where the intensity
# anchor is the high-pass-filter image (Event-3DGS) and α grows from 0 to 0.95; θ is learned per
# polarity and channel but pulled toward its start. Colour events are used in `mask` mode (each
# pixel compared in its own channel on the raw grid) or `demosaic` mode (the window's event maps
# demosaiced into three-channel targets).
#
# Events only record log-intensity *changes*: absolute brightness and colour balance are not
# observable, so the result is also scored after a per-channel affine fit (EventNeRF's protocol).
#
# The scene is **test seed 1004** of the benchmark sweep (`fusiongs simulate --sweep-seed 1004
# --split test`: a corridor, RGGB events, a sensor drawn from the calibration range), one that no
# default was chosen on, written without frames. Beside fusiongs we score the *floor peer*: the
# leaky-integrator (high-pass) image of the same events, which is what event-only training starts
# from. At 96x72 the sweep measured 19.9 dB for fusiongs on this scene with 2500 iterations
# (19.5 with 1500, 19.2 with earlier defaults; benchmarks/RESULTS.md, "Event-only colour"): honest
# figures, below the 23 dB target.

# %%
from fusiongs.cli import main as fusiongs_main
from fusiongs.configs import config_file
from fusiongs.eval.event_floor import leaky_integrator_floor
from fusiongs.eval.metrics import affine_fit
from fusiongs.frames.image_io import read_image

eo_scene = WORK / "event_only_test_1004"
if not (eo_scene / "scene.json").is_file():
    fusiongs_main(["simulate", "--sweep-seed", "1004", "--split", "test", "--frames", "0", "--novel", "6",
                   "--size", "32x24" if FAST else "96x72", *(["--duration", "0.15"] if FAST else []),
                   "-o", str(eo_scene)])
facts = json.loads((eo_scene / "gt" / "sim.json").read_text())
print(f"{facts['preset']} scene, {facts['cfa']} events, true thresholds ON {facts['theta_on']:.3f} / "
      f"OFF {facts['theta_off']:.3f}, spread {facts['theta_sigma']:.3f}")
floor = leaky_integrator_floor(eo_scene)
print(f"floor peer (leaky integrator): affine-fit PSNR {floor['psnr']:.2f} dB")
tiny = ["optim.iterations=10", "init.n_points=300", "event_only.alpha_warmup=3",
        "event_only.alpha_ramp=3", "event_only.hpf_readouts=20", "densify.enabled=false"] if FAST else []
results = {}
for mode in ("mask", "demosaic"):
    out = WORK / f"event_only_{mode}"
    fusiongs_main(["deblur", str(eo_scene), "-o", str(out), "--config", str(config_file("event_only.yaml")),
                   f"events.colour_mode={mode}", "output.progress=false", *tiny])
    results[mode] = json.loads((out / "metrics.json").read_text())
for mode, m in results.items():
    raw = m["mean"]["novel"]["fusiongs"]
    fit = m["affine_fit"]["mean"]["novel"]["fusiongs"]
    print(f"{mode:9s} raw PSNR {raw['psnr']:.2f} dB   after affine fit {fit['psnr']:.2f} dB "
          f"(SSIM {fit['ssim']:.3f}; floor peer {floor['psnr']:.2f} dB)")

# %%
name = sorted(p.stem for p in (eo_scene / "gt").glob("*.png"))[0]
truth = read_image(eo_scene / "gt" / f"{name}.png")
render = read_image(WORK / "event_only_mask" / "renders" / f"{name}.png")
fig = viz.strip([render, affine_fit(render, truth), truth],
                ["render (mask mode)", "after per-channel affine fit", "truth"])
