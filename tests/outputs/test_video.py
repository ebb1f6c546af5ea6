"""deblurred.mp4 is H.264 / yuv420p (plays in browsers), padded to even size, written atomically."""

from __future__ import annotations

import subprocess

import imageio_ffmpeg
import numpy as np
import pytest

from fusiongs.errors import FusionGSError
from fusiongs.outputs.video import even_frame, write_mp4

COLOURS = [(40, 120, 200), (100, 118, 148), (200, 60, 30), (250, 250, 250)]


def _decode(path):
    """``(meta, frames [N, H, W, 3] uint8)`` decoded by the bundled ffmpeg."""
    gen = imageio_ffmpeg.read_frames(str(path))
    meta = next(gen)
    w, h = meta["size"]
    frames = np.stack([np.frombuffer(b, np.uint8).reshape(h, w, 3) for b in gen])
    return meta, frames


def _odd_frames():
    """Four 17x11 frames of flat colours; the last real column of each is white."""
    out = []
    for c in COLOURS:
        a = np.empty((11, 17, 3), np.uint8)
        a[:] = c
        a[:, -3:] = 255
        out.append(a)
    return out


def test_odd_size_video_is_h264_yuv420p_padded_by_edge_replication(tmp_path):
    path = tmp_path / "deblurred.mp4"
    write_mp4(path, _odd_frames(), fps=12)
    probe = subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-i", str(path)],
                           capture_output=True, text=True).stderr
    assert "Video: h264" in probe and "yuv420p" in probe and "18x12" in probe, probe
    meta, frames = _decode(path)
    assert meta["codec"] == "h264" and meta["pix_fmt"].startswith("yuv420p")
    assert meta["size"] == (18, 12) and meta["fps"] == 12
    assert frames.shape == (4, 12, 18, 3)
    for got, c in zip(frames, COLOURS):
        flat = got[2:9, 2:10].reshape(-1, 3).astype(int)  # away from the white band's edge
        assert np.abs(flat - np.array(c)).max() <= 4
        # the added row and column repeat the last ones (white band, flat colour): nothing cropped
        assert got[:, -1].min() >= 235 and np.abs(got[-1, 2:10].astype(int) - np.array(c)).max() <= 6
    assert [p.name for p in tmp_path.iterdir()] == ["deblurred.mp4"]  # no temporary file left


def test_float_and_grey_frames_are_accepted(tmp_path):
    frames = [np.full((8, 6), 0.5, np.float32), np.full((8, 6, 1), 0.25, np.float64)]
    write_mp4(tmp_path / "v.mp4", frames, fps=24)
    _, got = _decode(tmp_path / "v.mp4")
    assert got.shape == (2, 8, 6, 3)
    assert np.abs(got[0].astype(int) - 128).max() <= 3 and np.abs(got[1].astype(int) - 64).max() <= 3


def test_even_frame_pads_with_the_last_row_and_column_only_when_odd():
    a = np.arange(3 * 5 * 3, dtype=np.uint8).reshape(3, 5, 3)
    e = even_frame(a)
    assert e.shape == (4, 6, 3)
    assert np.array_equal(e[:3, :5], a) and np.array_equal(e[3, :5], a[2])
    assert np.array_equal(e[:3, 5], a[:, 4])
    even = np.zeros((4, 6, 3), np.uint8)
    assert even_frame(even).shape == (4, 6, 3)


def test_bad_input_raises_and_leaves_the_old_file(tmp_path):
    path = tmp_path / "v.mp4"
    path.write_bytes(b"old")
    with pytest.raises(FusionGSError, match="no frames"):
        write_mp4(path, [], fps=12)
    with pytest.raises(FusionGSError, match="frame 1: expected size 6x4, got 5x4"):
        write_mp4(path, [np.zeros((4, 6, 3)), np.zeros((4, 5, 3))], fps=12)
    with pytest.raises(FusionGSError, match="fps"):
        write_mp4(path, [np.zeros((4, 6, 3))], fps=0)
    assert path.read_bytes() == b"old" and [p.name for p in tmp_path.iterdir()] == ["v.mp4"]


def test_ffmpeg_failure_is_a_named_error_and_leaves_no_file(tmp_path, monkeypatch):
    import fusiongs.outputs.video as video

    monkeypatch.setattr(video, "_ffmpeg_exe", lambda: "false")  # exits 1 without reading
    with pytest.raises(FusionGSError, match=r"v\.mp4: ffmpeg could not write the video \(exit 1\)"):
        write_mp4(tmp_path / "v.mp4", [np.zeros((64, 64, 3), np.uint8)] * 50, fps=12)
    assert list(tmp_path.iterdir()) == []
