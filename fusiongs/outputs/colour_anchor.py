"""Colour that means something: fix each channel's gain and offset of a reconstruction from frames.

Events measure changes of log intensity, so an event-only reconstruction is known up to a scale per
channel (and, through the log's ε and the intensity prior, an offset): its colours are not the
scene's. One captured frame, blurry or not, is enough to fix them. The run's prediction of that
frame (the mean of sharp linear renders over its exposure, docs/method.md §1) is compared with the frame
decoded to linear light through its camera response, and per channel a least-squares

    frame_lin_c ≈ gain_c · render_lin_c + offset_c

is fitted over the pixels the frame did not clip (at white or black). The anchored outputs are
``sRGB(clip(gain · render_lin + offset, 0, 1))``. A monochrome frame sees the grey ``w · L`` of
the render: one gain and offset, applied to all three channels (the weights sum to 1, so an offset
added to every channel adds the same to the grey).

Without a frame nothing fixes the colours: metrics are then also given after a per-channel affine
fit against the truth (:func:`fusiongs.eval.metrics.affine_fit`), and the report says so.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np

from fusiongs.errors import InputError, is_finite_number
from fusiongs.frames.response import linear_to_srgb, srgb_to_linear

#: The anchors a run's report can name.
FRAME_ANCHOR = "frame"
NO_ANCHOR = "none"
ANCHOR_LABELS = {  # one line of the report each
    FRAME_ANCHOR: "frame anchor (gain, offset per channel)",
    NO_ANCHOR: "none: affine fit only",
}
ANCHOR_NOTES = {
    FRAME_ANCHOR: "colours fixed by the captured frame: each channel's gain and offset of the renders "
                  "fitted to it in linear light (through its response) and applied to every output; "
                  "raw metrics need no fit",
    NO_ANCHOR: "no frame: events fix neither absolute brightness nor per-channel gain, so raw colours "
               "are arbitrary; compare after the per-channel affine fit",
}
ANCHOR_FILE = "colour_anchor.json"  # a run's applied anchor, which `fusiongs render` applies too
CLIP_LEVEL = 254.5 / 255.0  # encoded frame values at or above this are clipped (saturated)
BLACK_LEVEL = 0.5 / 255.0   # and at or below this, clipped at black
MIN_PIXELS = 16             # fewer unclipped pixels than this: no fit


@dataclass(frozen=True)
class ColourAnchor:
    """Per-channel ``gain`` and ``offset`` in linear light (``[3]`` each), and what fixed them.

    ``kind`` is :data:`FRAME_ANCHOR` or :data:`NO_ANCHOR` (then gain 1, offset 0); ``frames``
    names the frames fitted; ``pixels`` is how many unclipped pixels per channel took part.
    """

    kind: str = NO_ANCHOR
    gain: tuple[float, float, float] = (1.0, 1.0, 1.0)
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    frames: tuple[str, ...] = ()
    pixels: int = 0

    @property
    def applied(self) -> bool:
        return self.kind != NO_ANCHOR

    @property
    def label(self) -> str:
        return ANCHOR_LABELS[self.kind]

    def as_dict(self) -> dict:
        """The ``colour_anchor`` entry of ``metrics.json``."""
        doc = {"anchor": self.kind, "label": self.label, "note": ANCHOR_NOTES[self.kind]}
        if self.applied:
            doc |= {"gain": list(self.gain), "offset": list(self.offset), "frames": list(self.frames),
                    "pixels": self.pixels, "space": "linear"}
        return doc


def fit_gain_offset(render_lin: np.ndarray, frame_lin: np.ndarray, valid: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Per-channel least squares ``frame ≈ gain · render + offset`` over ``valid`` pixels.

    Args:
        render_lin: ``[..., C]`` the run's prediction of the frames, linear.
        frame_lin: ``[..., C]`` the frames decoded to linear light (same shape).
        valid: ``[...]`` bool, pixels taking part (unclipped in the frame).

    Returns:
        ``(gain [C], offset [C])``; a channel whose render is flat over the valid pixels gets
        gain 0 and the frame's mean as offset.

    Raises:
        InputError: shapes differ, or fewer than :data:`MIN_PIXELS` valid pixels.
    """
    r = np.asarray(render_lin, dtype=np.float64)
    f = np.asarray(frame_lin, dtype=np.float64)
    if r.shape != f.shape or np.shape(valid) != r.shape[:-1]:
        raise InputError("colour anchor", "shapes", f"render and frame of equal shape {f.shape} and "
                         f"a mask {f.shape[:-1]}", f"{r.shape} and {np.shape(valid)}")
    m = np.asarray(valid, dtype=bool)
    n = int(m.sum())
    if n < MIN_PIXELS:
        raise InputError("colour anchor", "unclipped frame pixels", f"at least {MIN_PIXELS}", n)
    rv, fv = r[m], f[m]  # [n, C]
    mr, mf = rv.mean(0), fv.mean(0)
    var = ((rv - mr) ** 2).mean(0)
    cov = ((rv - mr) * (fv - mf)).mean(0)
    gain = np.where(var > 1e-12, cov / np.maximum(var, 1e-12), 0.0)
    return gain, mf - gain * mr


def fit_frame_anchor(render_lin: np.ndarray, frames: np.ndarray, response: str,
                     grey_weights: tuple[float, float, float], names=()) -> ColourAnchor:
    """The :data:`FRAME_ANCHOR` of a run from its predictions of the captured frames.

    Args:
        render_lin: ``[F, H, W, 3]`` the mean linear render (each clipped to [0, 1], as the
            outputs are) over each frame's exposure.
        frames: ``[F, H, W, C]`` the captured frames as stored (C = 3, or 1 for a monochrome
            camera), values in [0, 1] in their ``response`` encoding.
        response: the frames' response (``"srgb"``, ``"linear"``, ``"gamma:G"``).
        grey_weights: ``w`` of the grey ``w · L`` a monochrome frame sees.
        names: the frames' names (recorded).

    Returns:
        The anchor; pixels where any channel of the frame is clipped (at or above
        :data:`CLIP_LEVEL`, or at or below :data:`BLACK_LEVEL`) are left out of the fit.

    Raises:
        InputError: shapes that do not match, or fewer than :data:`MIN_PIXELS` unclipped pixels.
    """
    from fusiongs.frames.response import response_to_linear

    enc = np.asarray(frames, dtype=np.float64)
    render = np.asarray(render_lin, dtype=np.float64)
    if enc.ndim != 4 or enc.shape[-1] not in (1, 3) or render.shape[:3] != enc.shape[:3]:
        raise InputError("colour anchor", "frames", f"[F, H, W, 1 or 3] frames matching the renders "
                         f"{render.shape[:3]}", enc.shape)
    lin = response_to_linear(enc, response)
    if enc.shape[-1] == 1:
        w = np.asarray(grey_weights, dtype=np.float64)
        render = (render * w).sum(-1, keepdims=True)
    valid = ((enc < CLIP_LEVEL) & (enc > BLACK_LEVEL)).all(-1)
    gain, offset = fit_gain_offset(render, lin, valid)
    if gain.size == 1:
        gain, offset = np.repeat(gain, 3), np.repeat(offset, 3)
    return ColourAnchor(FRAME_ANCHOR, tuple(float(v) for v in gain), tuple(float(v) for v in offset),
                        tuple(str(n) for n in names), int(valid.sum()))


def write_anchor(run, anchor: ColourAnchor) -> None:
    """``run/colour_anchor.json`` (:meth:`ColourAnchor.as_dict`, atomically) when ``anchor`` is
    applied; otherwise an earlier run's file in that folder is removed."""
    import json
    from pathlib import Path

    from fusiongs.atomic import json_ready, write_text

    path = Path(run) / ANCHOR_FILE
    if anchor.applied:  # strict JSON (a non-finite value as null), as every file fusiongs writes
        write_text(path, json.dumps(json_ready(anchor.as_dict()), indent=2, allow_nan=False) + "\n")
    else:
        path.unlink(missing_ok=True)


def read_anchor(run) -> ColourAnchor:
    """The anchor of ``run/colour_anchor.json``; :class:`ColourAnchor` () (none) without the file.

    Raises:
        InputError: naming the file and key when the file is not JSON, or its ``anchor`` is not
            :data:`FRAME_ANCHOR`, or its ``gain`` / ``offset`` are not 3 finite numbers.
    """
    import json
    from pathlib import Path

    path = Path(run) / ANCHOR_FILE
    if not path.is_file():
        return ColourAnchor()
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise InputError(path, "(file)", "a JSON object written by fusiongs deblur", str(e)) from None
    if not isinstance(doc, dict):
        raise InputError(path, "(top level)", "a JSON object", type(doc).__name__)
    if doc.get("anchor") != FRAME_ANCHOR:
        raise InputError(path, "anchor", f'"{FRAME_ANCHOR}"', doc.get("anchor"))

    values = {}
    for key in ("gain", "offset"):
        v = doc.get(key)
        if not (isinstance(v, list) and len(v) == 3 and all(is_finite_number(x) for x in v)):
            raise InputError(path, key, "3 finite numbers (one per channel, linear light)", v)
        values[key] = tuple(float(x) for x in v)
    frames = doc.get("frames") if isinstance(doc.get("frames"), list) else []
    pixels = doc.get("pixels") if isinstance(doc.get("pixels"), int) else 0
    return ColourAnchor(FRAME_ANCHOR, values["gain"], values["offset"], tuple(str(n) for n in frames), pixels)


def apply_anchor(anchor: ColourAnchor, srgb: np.ndarray) -> np.ndarray:
    """``srgb`` ``[..., 3]`` in [0, 1] with ``anchor`` applied in linear light; float32 sRGB."""
    if not anchor.applied:
        return np.asarray(srgb, dtype=np.float32)
    lin = srgb_to_linear(np.asarray(srgb, dtype=np.float64))
    out = lin * np.asarray(anchor.gain) + np.asarray(anchor.offset)
    return np.asarray(linear_to_srgb(np.clip(out, 0.0, 1.0)), dtype=np.float32)


def anchor_run(state, scene, cfg) -> ColourAnchor:
    """The colour anchor of a finished run: :data:`FRAME_ANCHOR` when the scene has exactly one
    frame (a scene with several frames is anchored by its blur loss over their exposures),
    :data:`NO_ANCHOR` otherwise, and also (said on stderr) when the frame is too clipped to fit.

    Args:
        state: the run's :class:`fusiongs.train.state.FusionState`.
        scene: the scene (its frames, camera).
        cfg: the run's :class:`fusiongs.train.settings.DeblurConfig` (renders per exposure,
            backend, grey weights).
    """
    import torch

    from fusiongs.losses.blur import exposure_instants

    fs = scene.frames
    if len(fs) != 1:
        return ColourAnchor()
    renders = []
    with torch.no_grad():
        for s, e in zip(fs.t_start, fs.t_end):
            t = exposure_instants(float(s), float(e), cfg.blur.n_samples)  # instants stay on the host
            lin, _, _ = state.render(scene.camera, t, cfg.backend)
            renders.append(lin.clamp(0, 1).mean(0).cpu().numpy())  # as the outputs are clipped
    try:
        return fit_frame_anchor(np.stack(renders), fs.images, fs.response, cfg.events.grey_weights,
                                fs.names)
    except InputError as e:  # say so and keep the outputs as rendered
        print(f"fusiongs: no colour anchor ({e}); colours as rendered", file=sys.stderr)
        return ColourAnchor()
