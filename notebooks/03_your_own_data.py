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
# # 3. Your own data: a real recording, from folder to deblurred video
#
# This notebook takes a real hand-held DAVIS346 recording, `eslnet_cups` (30 blurry grey
# 346x260 frames with their events; **no intrinsics, no trajectory, no sharp truth**), through
# the whole of fusiongs:
#
# 1. load and inspect the scene folder (`fusiongs inspect`), look at a frame and an event slice;
# 2. calibrate the event thresholds (`fusiongs calibrate`);
# 3. EDI-deblur one frame with those thresholds;
# 4. `fusiongs deblur --holdout K`: camera and poses from the frames (pose stage), training, and a
#    score on frames left out of training.
#
# Set `FUSIONGS_REAL_DATA` to a folder holding `eslnet_cups/` (or to a scene folder) to choose the
# data. With `FUSIONGS_NOTEBOOK_FAST=1` (as in CI) the recording is cut to its first 8 frames at
# half resolution and trained for a few iterations only: the pictures then show the workflow, not
# the quality fusiongs reaches.

# %%
import dataclasses
import json
import os
import shutil
from pathlib import Path

import numpy as np

import fusiongs
from fusiongs import viz
from fusiongs.cli import main
from fusiongs.edi import edi_deblur
from fusiongs.events.stream import EventStream
from fusiongs.events.thresholds import read_calibration
from fusiongs.frames.frameset import FrameSet
from fusiongs.frames.image_io import read_image
from fusiongs.io.scene_io import load_scene, save_scene
from fusiongs.pipeline.deblur import run_deblur
from fusiongs.sim.simulate import SimConfig, run_simulation
from fusiongs.sim.write import write_simulated_scene

FAST = os.environ.get("FUSIONGS_NOTEBOOK_FAST") == "1"
K = 3 if FAST else 5  # --holdout K: frames i % K == K - 1 are left out of training
WORK = Path("nb03_work")  # everything this notebook writes goes here
WORK.mkdir(exist_ok=True)
print("fusiongs", fusiongs.__version__, "| fast mode" if FAST else "| tutorial mode")


# %% [markdown]
# ## Find the recording
#
# `eslnet_cups` is looked for in `$FUSIONGS_REAL_DATA` when that is set (point it at your own
# recording folder), else in a `shared/data/real/` folder beside the fusiongs checkout. It is a
# **native scene folder** (`scene.json` + `events.h5` + `frames/`, see `docs/scene-format.md`);
# other layouts are turned into one with `fusiongs convert`.

# %%
def find_recording(name="eslnet_cups"):
    env = os.environ.get("FUSIONGS_REAL_DATA")
    if env:  # an explicit choice: look nowhere else
        p = Path(env)
        return next((d for d in (p, p / name) if (d / "scene.json").is_file()), None)
    repo = Path(fusiongs.__file__).resolve().parents[1]
    candidates = [repo.parent / "shared" / "data" / "real" / name]
    candidates += [d / "shared" / "data" / "real" / name for d in Path.cwd().resolve().parents[:3]]
    return next((p for p in candidates if (p / "scene.json").is_file()), None)


RECORDING = find_recording()
print("recording:", RECORDING.name if RECORDING else "not found")

# %% [markdown]
# **If the recording is not found** (for example in CI without the shared data), the notebook goes
# on with a **simulated** hand-held scene instead, written as a scene folder and then stripped of
# what a real recording lacks: `trajectory.txt`, the intrinsics in `scene.json` and the sharp truth
# `gt/`. Everything below then runs on that substitute.

# %%
if RECORDING is None:
    size = (96, 72) if FAST else (173, 130)
    sim = run_simulation(SimConfig(preset="boxes", width=size[0], height=size[1], duration=0.6,
                                   frames=6 if FAST else 12, exposure=0.06, blur_samples=8 if FAST else 24,
                                   dvs_rate_hz=300.0 if FAST else 1000.0, supersample=1, novel=0,
                                   frame_response="linear", seed=0))
    SOURCE = WORK / "simulated_scene"
    write_simulated_scene(sim.scene, sim.gt, SOURCE, overwrite=True)
    doc = json.loads((SOURCE / "scene.json").read_text())
    for key in ("fx", "fy", "cx", "cy"):
        doc["camera"].pop(key, None)
    doc.pop("trajectory", None)
    (SOURCE / "scene.json").write_text(json.dumps(doc, indent=1))
    (SOURCE / "trajectory.txt").unlink(missing_ok=True)
    shutil.rmtree(SOURCE / "gt", ignore_errors=True)
    print("substitute:", SOURCE, sorted(p.name for p in SOURCE.iterdir()))
else:
    SOURCE = RECORDING

# %% [markdown]
# ## A small cut (fast mode only)
#
# In fast mode a shorter scene is written with the scene API: `load_scene`, keep the first frames
# and the events of their time range, average 2x2 pixel blocks of the frames and merge the events
# of each block into one pixel, then `save_scene`. (Merged events no longer come from one pixel's
# threshold, so the thresholds calibrated on the cut are not those of the sensor.)

# %%
def cut_scene(src, dst, n_frames=6, factor=2):
    s = load_scene(src)
    fs, ev = s.frames, s.events
    n = min(n_frames, len(fs))
    t0, t1 = int(np.floor(fs.t_start[0] * 1e6)), int(np.ceil(fs.t_end[n - 1] * 1e6)) + 1
    e = ev.slice_time(t0, t1)
    w, h = ev.width // factor, ev.height // factor
    imgs = fs.images[:n, :h * factor, :w * factor]
    imgs = imgs.reshape(n, h, factor, w, factor, -1).mean(axis=(2, 4)).astype(np.float32)
    events = EventStream.create(e.t, e.x // factor, e.y // factor, e.p, w, h, ev.cfa, drop_invalid=True)
    frames = FrameSet(imgs, fs.t_start[:n].copy(), fs.t_end[:n].copy(), fs.names[:n], fs.response)
    camera = dataclasses.replace(s.camera, width=w, height=h)
    cut = dataclasses.replace(s, camera=camera, events=events, frames=frames, renders=(), root=None)
    save_scene(cut, dst)
    return Path(dst)


if FAST and RECORDING is not None:
    SCENE = cut_scene(SOURCE, WORK / "cut", n_frames=8, factor=2)  # 6 kept, 2 held out
else:
    SCENE = SOURCE
print("scene used below:", SCENE)

# %% [markdown]
# ## 1. Inspect
#
# `fusiongs inspect SCENE` summarises the folder and lists what looks wrong. Calling
# `fusiongs.cli.main` with the command-line arguments runs exactly the command-line code. Note
# the lines on the camera and the trajectory: both are to be estimated.

# %%
assert main(["inspect", str(SCENE)]) == 0

# %%
scene = load_scene(SCENE)
ev, fs = scene.events, scene.frames
exp_ms = (fs.t_end - fs.t_start) * 1e3
print(f"{len(ev):,} events, {ev.width}x{ev.height}, ON fraction {ev.polarity_balance:.3f}; "
      f"{len(fs)} frames ({fs.response}), exposure {np.median(exp_ms):.1f} ms every "
      f"{np.median(np.diff(fs.t_start)) * 1e3:.1f} ms")
print("intrinsics known:", scene.camera.intrinsics_known, "| trajectory:", scene.poses is not None)

# %% [markdown]
# Frame `K - 1` (the first one step 4 leaves out of training) and the events inside its exposure:
# red where brightness went up (ON), blue where it went down (OFF). The events show the edges the
# blur has smeared.

# %%
i = min(K - 1, len(fs) - 1)
t0_us, t1_us = int(fs.t_start[i] * 1e6), int(fs.t_end[i] * 1e6)
mid = (t0_us + t1_us) // 2
win = (t1_us - t0_us) // 8
panels = [fs.images[i], viz.event_frame(ev, t0_us, t1_us),
          viz.event_frame(ev, mid - win // 2, mid + win // 2)]
fig = viz.strip(panels,
                [f"frame {fs.names[i]} ({exp_ms[i]:.0f} ms exposure)", "events of the whole exposure",
                 f"events of {win / 1e3:.0f} ms at mid-exposure"])

# %% [markdown]
# ## 2. Calibrate the thresholds
#
# `fusiongs calibrate SCENE -o calibration.json` estimates the ON and OFF contrast thresholds from
# the frames and events alone: the thresholds that make the EDI images of consecutive frames
# agree. There is **no truth** to compare with on a real recording; the `±` is a bootstrap over
# spatial tiles of the image (one standard deviation of the estimate when tiles are resampled),
# which measures how much the answer depends on which part of the image is used, not how far it is
# from the sensor's true threshold.

# %%
CALIB = WORK / "calibration.json"
assert main(["calibrate", str(SCENE), "-o", str(CALIB)]) == 0
th = read_calibration(CALIB)[0]
print(f"theta_on {th.theta_pos[0]:.4f} ± {th.std_pos[0]:.4f}, theta_off {th.theta_neg[0]:.4f} ± "
      f"{th.std_neg[0]:.4f} ({th.method})")

# %% [markdown]
# ## 3. EDI with the calibrated thresholds
#
# EDI (Pan et al., CVPR 2019) divides the blurry frame (in linear light) by the mean of
# `exp(theta * event count)` over the exposure, giving the sharp image at mid-exposure.

# %%
lin = fs.to_linear()[i]
edi = edi_deblur(lin, ev, float(fs.t_start[i]), float(fs.t_end[i]), theta=th)
fig = viz.strip([np.clip(lin, 0, 1), np.clip(edi, 0, 1)],
                [f"blurry frame {fs.names[i]}", "EDI (calibrated thresholds)"])

# %% [markdown]
# ## 4. Deblur, with held-out frames
#
# `fusiongs deblur SCENE -o OUT --holdout K` (here `run_deblur`, the same code):
#
# - **pose stage**: the scene has neither intrinsics nor trajectory, so its frames are EDI-deblurred
#   and registered with pycolmap; the camera and the initial trajectory go to `OUT/camera.json` and
#   `OUT/trajectory_initial.txt`;
# - **training** without every K-th frame (never the first or last);
# - **held-out score**: each left-out blurry frame is predicted by fusiongs, by the nearest kept
#   frame, and by EDI of its kept neighbours carried to it with the events; PSNR against the real
#   blurry frame goes to `OUT/heldout.json`.
#
# Fast mode uses very few iterations and `--holdout 3`; the tutorial mode uses the default
# configuration and `--holdout 5`.

# %%
OUT = WORK / "run"
overrides = ["output.progress=false"]
if FAST:
    overrides += ["optim.iterations=30", "init.n_points=500", "blur.n_samples=3", "events.warmup=10",
                  "events.pixels=512", "optim.pose_start=20", "densify.start=10", "densify.every=10",
                  "densify.stop=25"]
result = run_deblur(SCENE, OUT, overrides=overrides, holdout=K, calibration=CALIB)
print(sorted(p.name for p in OUT.iterdir()))

# %% [markdown]
# ### Registration
#
# `camera.json` holds the estimated camera and the registration report. When the focal length is
# marked as not observable, the images did not constrain it and the starting guess was kept.

# %%
cam = json.loads((OUT / "camera.json").read_text())
rep = cam["report"]
print(f"intrinsics {cam['intrinsics']}, trajectory {cam['trajectory']}, from {cam['source']}")
print(f"registered {rep['registered']}/{rep['n_images']} (failed: {rep['failed'] or 'none'}), "
      f"focal {rep['focal'][0]:.1f} px ({'observable' if rep['focal_observable'] else 'not observable'}), "
      f"reprojection error {rep['reprojection_error_px']:.2f} px")
print("camera:", cam["camera"])

# %% [markdown]
# ### Held-out frames
#
# PSNR (dB) of each method's prediction of the held-out blurry frames, and the means. In fast mode
# fusiongs has trained for 30 iterations only, far from converged, so its column says nothing about
# the method; run the tutorial mode for a meaningful score.

# %%
held = json.loads((OUT / "heldout.json").read_text())
methods = held["methods"]
print(f"K = {held['holdout']}: " + held["rule"])
print(f"{'frame':<10}" + "".join(f"{m:>14}" for m in methods))
for name, row in held["frames"].items():
    print(f"{name:<10}" + "".join(f"{row[m]:>14.2f}" for m in methods))
print(f"{'mean':<10}" + "".join(f"{held['mean'][m]['psnr']:>14.2f}" for m in methods))

# %% [markdown]
# ### Blurry | EDI | fusiongs
#
# The frame from steps 1 and 3 (held out of training) and fusiongs' render at its mid-exposure
# (`OUT/deblurred/`). The EDI image here is made from this frame itself, unlike the table's
# `edi_carried`, which only uses the kept neighbours. The deblurred frames are also a video:
# `OUT/deblurred.mp4`.

# %%
ours = read_image(OUT / "deblurred" / f"{fs.names[i]}.png")
fig = viz.strip([fs.images[i], np.clip(edi, 0, 1), ours], [f"blurry {fs.names[i]}", "EDI", "fusiongs"],
                suptitle="held-out frame" if fs.names[i] in held["frames"] else "training frame")
video = OUT / "deblurred.mp4"
print("video:", video, f"({video.stat().st_size / 1e3:.0f} kB)" if video.is_file() else "(not written)")
