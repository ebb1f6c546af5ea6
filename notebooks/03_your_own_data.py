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
# # 3. Your own data: from a recording to a scene folder
#
# fusiongs reads one native layout, the **scene folder** (`scene.json` + `events.h5` + frames, see
# `FORMAT.md`). `fusiongs convert` turns the common event layouts (HDF5 variants, rpg text, npz,
# AEDAT4, Prophesee raw) into it. This notebook
#
# 1. converts a real DAVIS346 recording (AEDAT4: events **and** APS frames) with the same code
#    path as `fusiongs convert`,
# 2. inspects it (`fusiongs inspect`, text and JSON),
# 3. looks at the events (event frames, rate), the APS frames and their exposures, and a
#    high-pass-filter trace of a few pixels,
# 4. discusses what to do when the recording has **no trajectory**: the pose-estimation route, with
#    the EDI step run on the converted frames and a tiny pycolmap reconstruction on simulated images.
#
# Set `FUSIONGS_REAL_DATA` to a folder holding `davis346_mono.aedat4` (or to any `.aedat4` file)
# to use your own recording. With `FUSIONGS_NOTEBOOK_FAST=1` (as in CI) everything is tiny.

# %%
import json
import os
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import fusiongs
from fusiongs import viz
from fusiongs.cli import build_parser, main
from fusiongs.commands.inspect import build_report
from fusiongs.eval.edi import edi_deblur
from fusiongs.events.readers.text import write_events_txt
from fusiongs.io import load_scene
from fusiongs.sim.simulate import SimConfig, run_simulation
from fusiongs.sim.write import write_simulated_scene

FAST = os.environ.get("FUSIONGS_NOTEBOOK_FAST") == "1"
WORK = Path("nb03_work")  # everything this notebook writes goes here
WORK.mkdir(exist_ok=True)
print("fusiongs", fusiongs.__version__, "| fast mode" if FAST else "| tutorial mode")


# %% [markdown]
# ## Find a recording
#
# The recording used here is `davis346_mono.aedat4` (the `aedat` package's test file: an iniVation
# DAVIS346 looking at a street, 2.4 s). It is looked for in `$FUSIONGS_REAL_DATA` when that is
# set (a folder or an `.aedat4` file), else in `../shared/data/real/` beside the fusiongs checkout.

# %%
def find_recording(name="davis346_mono.aedat4"):
    env = os.environ.get("FUSIONGS_REAL_DATA")
    if env:  # an explicit choice: look nowhere else
        p = Path(env) if env.endswith(".aedat4") else Path(env) / name
        return p if p.is_file() else None
    candidates = []
    repo = Path(fusiongs.__file__).resolve().parents[1]
    candidates.append(repo.parent / "shared" / "data" / "real" / name)
    candidates += [d / "shared" / "data" / "real" / name for d in Path.cwd().resolve().parents[:3]]
    return next((p for p in candidates if p.is_file()), None)


RECORDING = find_recording()
print("recording:", RECORDING or "not found")

# %% [markdown]
# **If no recording is found** (for example in CI), the notebook does not stop: it simulates a
# small scene, writes its events as an **rpg text file** (`t x y p` per line, `t` in seconds,
# first line `width height`) and converts that instead. That substitute has events but no frames,
# so the frame sections below then use the simulated scene's blurry frames.

# %%
SIM_EVENTS_DIR = WORK / "simulated_events"
if RECORDING is None:
    sim = run_simulation(SimConfig(preset="boxes", width=64, height=48, duration=0.3, frames=3,
                                   exposure=0.04, blur_samples=8, dvs_rate_hz=200.0, supersample=1,
                                   novel=0, seed=1))
    write_simulated_scene(sim.scene, sim.gt, SIM_EVENTS_DIR, overwrite=True)
    SOURCE = WORK / "events.txt"
    write_events_txt(sim.scene.events, SOURCE)
    print("substitute:", SOURCE, f"({len(sim.scene.events):,} simulated events)")
    print(SOURCE.read_text().splitlines()[:4])
else:
    SOURCE = RECORDING

# %% [markdown]
# ## Convert
#
# `fusiongs convert IN -o SCENE` detects the layout from the file (override with `--format`).
# Calling `fusiongs.cli.main` with the same arguments runs exactly the command-line code. The
# AEDAT4 file stores no lens calibration, so convert warns and uses `fx = fy = width` with the
# principal point at the centre: **pass your calibration** (`--fx --fy --cx --cy`) for real work.
# Time 0 of the scene is the first event or exposure (`--keep-clock` keeps the camera's clock).

# %%
SCENE = WORK / "scene"
args = ["convert", str(SOURCE), "-o", str(SCENE), "--overwrite"]
if SOURCE.suffix == ".txt":
    args += ["--time-unit", "s", "--keep-clock"]  # keep the simulated frames' clock
print("fusiongs", " ".join(args))
assert main(args) == 0
print(sorted(p.name for p in SCENE.iterdir()))

# %% [markdown]
# ## Inspect
#
# `fusiongs inspect SCENE` summarises the folder and lists what looks wrong (time gaps, hot
# pixels, frames outside the event range, a trajectory that does not cover the events).
# `--json` prints the same report as JSON; in Python, `build_report` returns it as a dictionary.

# %%
assert main(["inspect", str(SCENE)]) == 0

# %%
report = build_report(build_parser().parse_args(["inspect", str(SCENE), "--json"]))
print(json.dumps(report, indent=2))

# %%
scene = load_scene(SCENE)
ev = scene.events
print(f"{len(ev):,} events, {ev.width}x{ev.height}, CFA {ev.cfa}, "
      f"{ev.rate / 1e3:.1f} kev/s, ON fraction {ev.polarity_balance:.3f}, {len(scene.frames)} frames")

# %% [markdown]
# ## Events
#
# An **event frame** accumulates the events of a time window per pixel: red where the signed count
# is positive (brightness went up), blue where it is negative, white where nothing happened.
# Moving edges show up as red/blue pairs; the order tells the direction of motion.

# %%
t_first, t_last = int(ev.t[0]), int(ev.t[-1])
window = 50_000 if RECORDING is not None else 20_000  # µs
starts = np.linspace(t_first, t_last - window, 4).astype(np.int64)
fig = viz.strip([viz.event_frame(ev, s, s + window) for s in starts],
                [f"[{s * 1e-6:.2f}, {(s + window) * 1e-6:.2f}) s" for s in starts],
                suptitle=f"event frames ({window / 1e3:.0f} ms windows)")

# %%
fs = scene.frames
fig = viz.event_rate(ev, bin_s=0.02 if RECORDING is not None else 0.005,
                     exposures=(fs.t_start, fs.t_end) if len(fs) else None)

# %% [markdown]
# ## Frames and their exposures
#
# A DAVIS reads its active-pixel sensor (APS) on the same pixel grid as the events. Convert keeps
# each frame's exposure window `[t_start, t_end]` (seconds, on the events' clock) and marks the
# frames `linear` (the APS read-out is linear in irradiance). The exposure window is what the blur
# model and EDI need: a frame is the mean of the sharp images over its exposure.

# %%
if len(fs):
    idx = np.linspace(0, len(fs) - 1, 4).round().astype(int)
    fig = viz.strip([fs.images[i] for i in idx],
                    [f"{fs.names[i]}: {fs.t_start[i]:.3f}-{fs.t_end[i]:.4f} s\n"
                     f"exposure {(fs.t_end[i] - fs.t_start[i]) * 1e3:.2f} ms" for i in idx])
    exp_ms = (fs.t_end - fs.t_start) * 1e3
    print(f"{len(fs)} frames, exposure min/median/max {exp_ms.min():.3g}/{np.median(exp_ms):.3g}/"
          f"{exp_ms.max():.3g} ms, interval {np.median(np.diff(fs.t_start)) * 1e3:.1f} ms")
else:
    print("this scene has no frames (event-only source)")

# %% [markdown]
# ## High-pass filtered events at a few pixels
#
# Event-3DGS's photovoltage contrast comes from a per-pixel high-pass filter (Scheerlinck et al.,
# ACCV 2018): every event adds `±C` to the pixel's state, which decays with time constant `tau`.
# It tracks log-brightness changes while forgetting slow drift and stray noise events. Here are the
# traces of three of the busiest pixels (markers: the pixel's ON and OFF events).

# %%
counts = ev.pixel_counts()
busiest = np.argsort(counts.ravel())[::-1][:3]
pixels = [(int(i % ev.width), int(i // ev.width)) for i in busiest]
print("pixels (x, y):", pixels, "events:", [int(counts[y, x]) for x, y in pixels])
mine = ev.slice_time(t_first, t_last + 1)
sel = np.isin(mine.y.astype(np.int64) * ev.width + mine.x, busiest)
t0, t1 = int(mine.t[sel].min()), int(mine.t[sel].max())
pad = (t1 - t0) // 4 + 1
fig = viz.hpf_traces(ev, pixels, max(t0 - pad, 0), t1 + 2 * pad, tau=0.05, contrast=0.2,
                     n_samples=300 if FAST else 1000)

# %% [markdown]
# ## No trajectory yet
#
# `inspect` says *trajectory: none (poses to be estimated)*. fusiongs needs camera poses over time.
# When the recording has none, the route (METHOD.md §6, after E2NeRF) is:
#
# 1. **EDI-deblur every frame** with its events (Pan et al., CVPR 2019): sharp frames give far
#    more reliable feature matches than blurry ones (E2NeRF registered 30/30 views this way
#    against 14-27 with the blurry frames);
# 2. **structure from motion** with pycolmap: SIFT features, *sequential* matching (the frames are
#    a video), and the known intrinsics as a fixed `PINHOLE` camera;
# 3. **interpolate** the per-frame poses over time (translation linearly, rotation by slerp, or a
#    spline) and write them as `trajectory.txt` (TUM format, camera-to-world, OpenCV axes);
# 4. let training **refine** the trajectory (control knots, camera learning rate 1e-3 to 1e-5).
#
# Note that this particular recording comes from a **static** camera watching traffic: every pose
# is the same, structure from motion has no baseline to work with, and a constant trajectory is
# the right answer. The steps are shown anyway, because they are the same for a moving camera.
#
# ### Step 1: EDI on the converted frames
#
# EDI needs linear frames, the events and a contrast threshold. Here the threshold is a known
# value: a typical DAVIS346 threshold (0.25) for the recording, the simulator's own mean threshold
# for the substitute. (`fusiongs.eval.edi.estimate_theta` estimates one from the events around
# mid-exposure; it needs many events inside the exposure to be trusted.)
# The gain is as large as the blur: with this recording's 0.5 ms exposures there is little to
# remove, and the difference image shows where events inside the exposure changed the result.

# %%
edi_scene_src = scene if len(scene.frames) else load_scene(SIM_EVENTS_DIR)
fs2, ev2 = edi_scene_src.frames, edi_scene_src.events
inside = [int(np.diff(ev2.index_range(int(s * 1e6), int(e * 1e6)))[0])
          for s, e in zip(fs2.t_start, fs2.t_end)]
i = int(np.argmax(inside))  # the frame with the most events inside its exposure
lin = fs2.to_linear()[i]
theta = 0.25 if RECORDING is not None else 0.5 * (sim.stats["theta_on"] + sim.stats["theta_off"])
sharp = edi_deblur(lin, ev2, float(fs2.t_start[i]), float(fs2.t_end[i]), theta=theta)
diff = np.abs(sharp - lin).mean(-1)
print(f"frame {fs2.names[i]}: {inside[i]} events inside the exposure, theta = {theta:.3f}, "
      f"mean |EDI - frame| = {diff.mean():.2e}, max {diff.max():.3f}")
fig = viz.strip([np.clip(lin, 0, 1), np.clip(sharp, 0, 1), diff / max(float(diff.max()), 1e-6)],
                ["frame (linear)", f"EDI, theta = {theta:.3f}", "|EDI - frame| (normalised)"])

# %% [markdown]
# ### Step 2: structure from motion with pycolmap (a tiny demonstration)
#
# A static camera gives nothing to reconstruct, so this step runs on a **simulated** moving camera:
# six sharp truth images of the `boxes` scene (in a real run these would be the EDI results of
# step 1). `fusiongs.camera.sfm.estimate_poses` wraps these pycolmap 4.2 calls:
#
# ```python
# reader = pycolmap.ImageReaderOptions()
# reader.camera_model = "PINHOLE"
# reader.camera_params = f"{fx},{fy},{cx},{cy}"          # known intrinsics
# pycolmap.extract_features(db, image_dir, camera_mode=pycolmap.CameraMode.SINGLE,
#                           reader_options=reader)         # SIFT
# pycolmap.match_sequential(db)                            # video order
# opts = pycolmap.IncrementalPipelineOptions()
# opts.ba_refine_focal_length = False                      # keep the known intrinsics fixed
# opts.ba_refine_principal_point = False
# recs = pycolmap.incremental_mapping(db, image_dir, out_dir, options=opts)
# image.cam_from_world()                                   # a pycolmap.Rigid3d per registered image
# ```
#
# COLMAP's poses are world-to-camera in an arbitrary frame and scale; comparing them with the true
# camera centres needs a similarity alignment (`fusiongs.camera.sfm.umeyama`).

# %%
from fusiongs.camera.sfm import estimate_poses, umeyama

size = (160, 120) if FAST else (320, 240)
sfm = run_simulation(SimConfig(preset="boxes", width=size[0], height=size[1], duration=1.0, frames=6,
                               exposure=0.02, blur_samples=1, dvs_rate_hz=4.0, supersample=1, novel=0,
                               seed=0))
SFM = WORK / "sfm"
write_simulated_scene(sfm.scene, sfm.gt, SFM / "scene", overwrite=True)
images = SFM / "scene" / "gt"  # deblur_000000.png ... deblur_000005.png: sharp mid-exposure views
poses = estimate_poses(images, sfm.scene.camera, SFM / "colmap")  # {stem: c2w}, COLMAP's frame
print(f"{len(poses)}/6 images registered")

# %%
if len(poses) >= 3:
    names = sorted(poses)
    est = np.array([poses[n][:3, 3] for n in names])  # camera centres, COLMAP frame
    mids = {r.name: r.t for r in sfm.scene.renders}
    p = sfm.scene.poses  # true trajectory samples (camera-to-world)
    true = np.stack([p.c2w[np.argmin(np.abs(p.t - mids[n])), :3, 3] for n in names])
    s, R, t = umeyama(est, true)  # similarity est -> true
    aligned = s * est @ R.T + t
    err = np.linalg.norm(aligned - true, axis=1)
    path_len = np.linalg.norm(np.diff(true, axis=0), axis=1).sum()
    print(f"camera centre error after alignment: mean {err.mean():.3f} m over a {path_len:.2f} m path")
    fig, ax = plt.subplots(figsize=(5, 3))
    ax.plot(true[:, 0], true[:, 2], "o-", label="true camera centres")
    ax.plot(aligned[:, 0], aligned[:, 2], "x--", label="pycolmap (aligned)")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.set_title("top view", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
else:
    print("too few images registered to compare")

# %% [markdown]
# ### Steps 3-4
#
# With one pose per frame, a trajectory file is the poses at the frames' mid-exposure times,
# written with `fusiongs.camera.tum.write_tum` (after converting COLMAP's world-to-camera poses
# to camera-to-world) and named in `scene.json` as `"trajectory"`; fusiongs interpolates between
# them and refines them during training. The EDI + pycolmap route is the plan of METHOD.md §6; in
# this version of fusiongs it is run by hand as above.
