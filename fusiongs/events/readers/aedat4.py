"""iniVation AEDAT4 recordings through the maintained ``aedat`` package (events and APS frames).

Event packets are copied into the output columns as they are decoded
(:func:`~fusiongs.events.readers.chunks.columns_from_chunks`); frames are kept as decoded.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fusiongs.errors import InputError, MissingDependencyError
from fusiongs.events.h5 import stream_from_file
from fusiongs.events.readers.chunks import columns_from_chunks
from fusiongs.events.stream import EventStream


@dataclass(frozen=True, eq=False)
class ApsFrames:
    """Frames of a DAVIS active-pixel sensor, as stored.

    Attributes:
        images: ``[F, H, W]`` (grey) or ``[F, H, W, C]`` uint8/uint16 pixel values.
        t: ``[F]`` int64 frame timestamp in µs (events' clock).
        exposure_start, exposure_end: ``[F]`` int64 exposure window in µs, or ``None`` when the
            recording has none (then only ``t`` is known).
        format: the pixel format as named by the file (``"L"``, ``"RGB"``, ``"RGBA"``).
    """

    images: np.ndarray
    t: np.ndarray
    exposure_start: np.ndarray | None
    exposure_end: np.ndarray | None
    format: str = "L"

    def __len__(self) -> int:
        return int(self.t.shape[0])


def read_aedat4(path: str | Path, width: int | None = None, height: int | None = None,
                cfa: str | None = None, *, sort: bool = False,
                drop_invalid: bool = False) -> tuple[EventStream, ApsFrames]:
    """Read the first event stream and the first frame stream of an AEDAT4 file.

    Args:
        path: the ``.aedat4`` file.
        width, height: sensor size; default from the file's stream description.
        cfa, sort, drop_invalid: see :meth:`EventStream.create`.

    Returns:
        ``(events, frames)``; ``frames`` is empty (``len == 0``) for event-only cameras.

    Raises:
        InputError: unreadable/corrupt file, no event stream, zero events, or any check of
            :meth:`EventStream.create`.
    """
    try:
        import aedat
    except ImportError:
        raise MissingDependencyError("aedat", "reading AEDAT4 files") from None
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file", "an existing AEDAT4 file", "no such file")
    frames: list[dict] = []
    try:
        decoder = aedat.Decoder(str(path))
        streams = decoder.id_to_stream()
        ev_ids = sorted(k for k, v in streams.items() if v.get("type") == "events")
        fr_ids = sorted(k for k, v in streams.items() if v.get("type") == "frame")
        if not ev_ids:
            raise InputError(path, "streams", "an 'events' stream",
                             f"streams {sorted(v.get('type') for v in streams.values())}")
        ev_id, fr_id = ev_ids[0], (fr_ids[0] if fr_ids else None)
        t, x, y, p = columns_from_chunks(_event_packets(decoder, ev_id, fr_id, frames))
    except InputError:
        raise
    except Exception as e:  # the Rust decoder raises plain RuntimeError/OSError on corrupt input
        raise InputError(path, "file", "a readable AEDAT4 file (truncated or corrupt?)", str(e)) from None
    width = width if width is not None else int(streams[ev_id]["width"])
    height = height if height is not None else int(streams[ev_id]["height"])
    stream = stream_from_file(path, t, x, y, p, width, height, cfa, sort, drop_invalid)
    return stream, _frames(frames)


def _event_packets(decoder, ev_id: int, fr_id: int | None, frames: list[dict]):
    """Yield the event packets of stream ``ev_id``; append the frames of ``fr_id`` to ``frames``."""
    for packet in decoder:
        sid = packet.get("stream_id")
        if sid == ev_id and "events" in packet:
            yield packet["events"]
        elif sid == fr_id and "frame" in packet:
            frames.append(packet["frame"])


def _frames(frames: list[dict]) -> ApsFrames:
    if not frames:
        return ApsFrames(np.zeros((0, 0, 0), np.uint8), np.zeros(0, np.int64), None, None)
    images = np.stack([np.asarray(f["pixels"]) for f in frames])
    t = np.asarray([f["t"] for f in frames], np.int64)
    has_exp = all("exposure_begin_t" in f and "exposure_end_t" in f for f in frames)
    s = np.asarray([f["exposure_begin_t"] for f in frames], np.int64) if has_exp else None
    e = np.asarray([f["exposure_end_t"] for f in frames], np.int64) if has_exp else None
    return ApsFrames(images, t, s, e, str(frames[0].get("format", "L")))
