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
# # 1. Deblurring with events
#
# A conventional frame integrates light over its exposure: when the camera moves, it is blurry. An
# event camera on the same pixel grid reports, with microsecond timing, every pixel whose log
# brightness changed by a contrast threshold `theta`. Together they pin down the sharp images.
#
# This notebook
#
# 1. simulates a small scene (blurry frames, events, trajectory and the sharp truth),
# 2. looks at the events,
# 3. deblurs one frame with the classic **EDI** model (Pan et al., CVPR 2019),
# 4. runs **fusiongs** (a 3D Gaussian scene fitted to the blurry frames and the events, with a
#    learnable threshold) and compares blurry input, EDI, fusiongs and truth.
#
# With `FUSIONGS_NOTEBOOK_FAST=1` (as in CI) sizes and iterations are tiny, so the fusiongs result
# is far from converged; run without it for the tutorial-sized run (a few minutes on a laptop CPU).

# %%
import json
import os
from pathlib import Path

import numpy as np

from fusiongs import viz
from fusiongs.camera.tum import PoseSamples, read_tum, write_tum
from fusiongs.cli import main as fusiongs_cli
from fusiongs.configs import config_file
from fusiongs.edi import edi_deblur
from fusiongs.eval.evaluate import format_table
from fusiongs.eval.metrics import psnr
from fusiongs.frames.image_io import read_image
from fusiongs.frames.response import linear_to_srgb
from fusiongs.io import load_scene
from fusiongs.pipeline.deblur import run_deblur
from fusiongs.sim.simulate import SimConfig, run_simulation
from fusiongs.sim.write import write_simulated_scene
from fusiongs.train.checkpoint import load_checkpoint

FAST = os.environ.get("FUSIONGS_NOTEBOOK_FAST") == "1"
WORK = Path("nb01_work")  # everything this notebook writes goes here
WORK.mkdir(exist_ok=True)
print("fast mode" if FAST else "tutorial mode")

# %% [markdown]
# ## 1. Simulate a scene
#
# `fusiongs.sim` ray-casts a textured world (`boxes`: three boxes and a panel in front of a photo
# wall) along a smooth camera arc with hand shake. Frames average many sharp renders over their
# exposure in linear light and are stored as 8-bit sRGB; events come from a DVS model with
# per-pixel threshold mismatch and background noise. `write_simulated_scene` writes the native
# scene folder plus the sharp truth under `gt/` (the same as `fusiongs simulate`).

# %%
if FAST:
    sim_cfg = SimConfig(preset="boxes", width=48, height=36, duration=0.16, frames=2, exposure=0.07,
                        blur_samples=8, dvs_rate_hz=400.0, supersample=1, novel=1, seed=0)
else:
    sim_cfg = SimConfig(preset="boxes", width=96, height=72, duration=0.5, frames=6, exposure=0.05,
                        blur_samples=24, dvs_rate_hz=600.0, seed=0)
sim = run_simulation(sim_cfg)
SCENE = WORK / "scene"
write_simulated_scene(sim.scene, sim.gt, SCENE, stats=sim.stats, overwrite=True)
st = sim.stats
print(f"{st['events']:,} events ({st['events_per_pixel']:.1f} per pixel), "
      f"ON fraction {st['on_fraction']:.3f}")
print(f"thresholds ON {st['theta_on']:.3f} / OFF {st['theta_off']:.3f} "
      f"(per-pixel sigma {st['theta_sigma']:.3f})")
print(f"mean blur {st['blur_px']:.1f} px per exposure, simulated in {st['seconds_total']:.1f} s")

# %%
scene = load_scene(SCENE)
fs, ev = scene.frames, scene.events
fig = viz.strip([fs.images[0], sim.gt[f"deblur_{fs.names[0]}"]],
                [f"blurry frame {fs.names[0]} ({(fs.t_end[0] - fs.t_start[0]) * 1e3:.0f} ms)",
                 "sharp truth at mid-exposure"])

# %% [markdown]
# ## 2. The events
#
# Each event is `(t [µs], x, y, p = ±1)`. Accumulated over a window they draw the moving edges:
# red where the brightness rose (ON), blue where it fell (OFF). Below, the exposure of the first
# frame cut into four windows: the edges move between them, which is exactly the motion that
# blurred the frame.

# %%
s_us, e_us = int(fs.t_start[0] * 1e6), int(fs.t_end[0] * 1e6)
cuts = np.linspace(s_us, e_us, 5).astype(np.int64)
fig = viz.strip([viz.event_frame(ev, a, b) for a, b in zip(cuts[:-1], cuts[1:])],
                [f"{(a - s_us) / 1e3:.0f}-{(b - s_us) / 1e3:.0f} ms" for a, b in zip(cuts[:-1], cuts[1:])],
                suptitle=f"events during the exposure of frame {fs.names[0]}")

# %%
counts = ev.count_maps()
print(f"rate {ev.rate / 1e6:.2f} Mev/s over {ev.duration_us / 1e6:.2f} s; "
      f"ON {counts[0].sum():,} / OFF {counts[1].sum():,} (ON fraction {ev.polarity_balance:.3f}); "
      f"{(counts.sum(0) > 0).mean():.0%} of the pixels fired")
fig = viz.event_rate(ev, bin_s=0.005 if FAST else 0.01, exposures=(fs.t_start, fs.t_end))

# %% [markdown]
# ## 3. EDI: one frame, one formula
#
# In linear light, `L(t) = L(t_mid) exp(theta E(t))` with `E(t)` the signed event count from
# mid-exposure to `t`, and the blurry frame is the mean of `L(t)` over the exposure, so
#
# `L(t_mid) = B / mean_t exp(theta E(t))`  (Pan et al., CVPR 2019, Eq. 6).
#
# EDI is cheap and strong when `theta` is right. Here we use the simulator's mean threshold and
# show how the result depends on it: a sensor's threshold is never known exactly (and varies from
# pixel to pixel), one reason fusiongs learns it.

# %%
i = 0
name = f"deblur_{fs.names[i]}"
truth = sim.gt[name]
lin = fs.to_linear()[i]
theta_true = 0.5 * (st["theta_on"] + st["theta_off"])


def edi_srgb(theta):
    out = edi_deblur(lin, ev, float(fs.t_start[i]), float(fs.t_end[i]), theta=theta)
    return linear_to_srgb(np.clip(out, 0.0, 1.0)).astype(np.float32)


edi = edi_srgb(theta_true)
p_blur, p_edi = psnr(fs.images[i], truth), psnr(edi, truth)
fig = viz.strip([fs.images[i], edi, truth],
                [f"blurry, {p_blur:.2f} dB", f"EDI (theta {theta_true:.3f}), {p_edi:.2f} dB", "truth"])

# %%
thetas = np.geomspace(0.05, 0.6, 8 if FAST else 16)
curve = [psnr(edi_srgb(th), truth) for th in thetas]
fig = viz.line_plot({"EDI": (thetas, curve), "blurry frame": ([thetas[0], thetas[-1]], [p_blur, p_blur])},
                    title=f"EDI vs threshold (true mean {theta_true:.3f})", xlabel="theta",
                    ylabel="PSNR (dB)")
_ = fig.axes[0].axvline(theta_true, color="0.5", ls=":")

# %% [markdown]
# ## 4. fusiongs
#
# `run_deblur` is `fusiongs deblur SCENE -o OUT` as a function: it fits a 3D Gaussian scene whose
# exposure-averaged renders match the blurry frames and whose log-brightness changes match the
# events, learns the contrast thresholds (and refines the poses), writes the deblurred frames,
# novel views, `model.ply`, `checkpoint.pt`, and, because the scene has truth, `metrics.json` and
# `report.png`. The config is the shipped `deblur_fast.yaml` plus `key=value` overrides, exactly
# as on the command line.

# %%
OUT = WORK / "run"
overrides = ["output.progress=false"]
if FAST:
    overrides += ["optim.iterations=30", "init.n_points=500", "blur.n_samples=3", "events.warmup=10",
                  "events.pixels=512", "optim.pose_start=20", "densify.start=10", "densify.every=10",
                  "densify.stop=25"]
result = run_deblur(SCENE, OUT, config=config_file("deblur_fast.yaml"), overrides=overrides)
print(sorted(p.name for p in OUT.iterdir()))

# %% [markdown]
# ## 5. Compare
#
# `metrics.json` holds PSNR and SSIM (8-bit sRGB, docs/method.md §8) per view and method, and their
# means: `deblur` views are the frames' mid-exposure instants (blurry input, EDI with a threshold
# estimated from the consistency of consecutive frames, and fusiongs), `novel` views are held-out
# instants between exposures, which
# only a 3D model can render.

# %%
metrics = json.loads((OUT / "metrics.json").read_text())
print(format_table(metrics))
print(f"\n{metrics['iterations']} iterations in {metrics['seconds']:.1f} s; PSNR per view (dB):")
for view, by_method in metrics["views"].items():
    print(f"  {view:<16}" + "  ".join(f"{m} {v['psnr']:.2f}" for m, v in by_method.items()))

# %%
ours = read_image(OUT / "deblurred" / f"{fs.names[i]}.png")
fig = viz.strip([fs.images[i], edi, ours, truth],
                [f"blurry, {p_blur:.2f} dB", f"EDI, {p_edi:.2f} dB", f"fusiongs, {psnr(ours, truth):.2f} dB",
                 "truth"], suptitle=f"frame {fs.names[i]} at mid-exposure")

# %% [markdown]
# ### The learned threshold
#
# fusiongs keeps `theta = exp(s)` per polarity, frozen during the warm-up and then learned with
# the event loss. The checkpoint's history holds its value at every iteration; the dotted lines are
# the simulator's mean thresholds.

# %%
hist = load_checkpoint(OUT / "checkpoint.pt")["history"]
it = np.asarray(hist["iteration"])
tp = np.asarray(hist["theta_pos"], dtype=np.float64).reshape(len(it), -1).mean(1)
tn = np.asarray(hist["theta_neg"], dtype=np.float64).reshape(len(it), -1).mean(1)
fig = viz.line_plot({"theta ON (learned)": (it, tp), "theta OFF (learned)": (it, tn)},
                    title="contrast threshold during training", xlabel="iteration", ylabel="theta")
ax = fig.axes[0]
ax.axhline(st["theta_on"], color="C0", ls=":")
ax.axhline(st["theta_off"], color="C1", ls=":")
print(f"final theta ON {tp[-1]:.3f} (simulator {st['theta_on']:.3f}), "
      f"OFF {tn[-1]:.3f} (simulator {st['theta_off']:.3f})")

# %% [markdown]
# `report.png`, written by `run_deblur`, collects the same comparison in one picture:

# %%
fig = viz.strip([read_image(OUT / "report.png")], ["report.png"], height_in=6.0)

# %% [markdown]
# ### Views the camera never had
#
# The fitted scene is 3D, so it renders from any camera. `OUT/trajectory.txt` is the refined camera
# path (TUM: `t tx ty tz qx qy qz qw`, camera-to-world, OpenCV axes). Below, the camera from the
# middle of that path is moved along its own x axis (to the right) and rendered with
# `fusiongs render OUT --poses FILE`. Near surfaces move farther across the image than far ones:
# that is parallax.

# %%
path = read_tum(OUT / "trajectory.txt")
mid = path.c2w[len(path) // 2]
slide = np.array([-0.3, 0.0, 0.3])  # scene units along the camera's own x axis
c2w = np.repeat(mid[None], slide.size, 0)
c2w[:, :3, 3] += slide[:, None] * mid[:3, 0]
write_tum(WORK / "slide.txt", PoseSamples(np.arange(slide.size, dtype=np.float64), c2w))
assert fusiongs_cli(["render", str(OUT), "--poses", str(WORK / "slide.txt"), "-o", str(WORK / "slide")]) == 0
views = [read_image(p) for p in sorted((WORK / "slide").glob("pose_*.png"))]
fig = viz.strip(views, [f"camera moved {s:+.1f} along x" for s in slide], suptitle="novel views")
