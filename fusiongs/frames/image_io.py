"""Frame files: 8/16-bit PNG and JPEG through OpenCV, camera raw files through rawpy."""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fusiongs.atomic import write_bytes
from fusiongs.errors import InputError, MissingDependencyError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_IEND = b"\x00\x00\x00\x00IEND\xaeB`\x82"  # the 12-byte chunk every complete PNG ends with
_PNG_CHANNELS = {0: 1, 2: 3, 3: 3, 4: 2, 6: 4}  # IHDR colour type -> samples per pixel (palette: RGB)


@dataclass(frozen=True)
class ImageInfo:
    """Size of an image file without its pixels: ``width`` x ``height``, ``channels`` samples per
    pixel (1 grey, 3 RGB; 2 or 4 with alpha, which :func:`read_image` refuses)."""

    width: int
    height: int
    channels: int


def is_raw_path(path: str | Path) -> bool:
    """True when ``path`` is not an ordinary image file name (then it is opened with rawpy)."""
    return Path(path).suffix.lower() not in IMAGE_SUFFIXES


def read_image(path: str | Path) -> np.ndarray:
    """Read an 8- or 16-bit PNG/JPEG (or TIFF/BMP) image.

    Args:
        path: image file.

    Returns:
        ``[H, W, C]`` float32 in [0, 1], stored values divided by 255 or 65535; C = 3 (RGB order)
        or 1 (grey).

    Raises:
        InputError: unreadable file, a truncated or damaged PNG (see :func:`png_info`), an alpha
            channel, or a bit depth other than 8/16.
    """
    import cv2

    path = Path(path)
    if not path.is_file():
        raise InputError(path, "image", "an existing image file", "no such file")
    data = path.read_bytes()
    if not data:
        raise InputError(path, "image", "a PNG or JPEG file", "an empty file (0 bytes)")
    if _looks_like_png(path, data):
        png_info(path, data)  # truncated or damaged: named here, before libpng prints its own error
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(path, "image", "a PNG or JPEG file OpenCV can decode", "undecodable")
    if img.dtype == np.uint8:
        scale = 255.0
    elif img.dtype == np.uint16:
        scale = 65535.0
    else:
        raise InputError(path, "image", "8- or 16-bit samples", str(img.dtype))
    if img.ndim == 2:
        img = img[:, :, None]
    elif img.shape[2] == 3:
        img = img[:, :, ::-1]
    elif img.shape[2] != 1:
        raise InputError(path, "image", "1 (grey) or 3 (RGB) channels", f"{img.shape[2]} channels")
    return (img.astype(np.float32) / np.float32(scale)).copy()


def _looks_like_png(path: Path, data: bytes) -> bool:
    head = data[:8]
    return head == PNG_SIGNATURE or (path.suffix.lower() == ".png" and PNG_SIGNATURE.startswith(head))


def _png_header(path: Path, head: bytes) -> ImageInfo:
    """:class:`ImageInfo` from the first 33 bytes of a PNG (signature and IHDR chunk)."""
    if head[:8] != PNG_SIGNATURE and not (len(head) < 8 and PNG_SIGNATURE.startswith(head)):
        raise InputError(path, "image", "a PNG file", f"first bytes {head[:8]!r}")
    if len(head) < 33:
        raise InputError(path, "image", "a complete PNG file (truncated?)", f"{len(head)} bytes in all")
    n, ctype, w, h, depth, colour = struct.unpack(">I4sIIBB", head[8:26])
    if ctype != b"IHDR" or n != 13 or w == 0 or h == 0 or colour not in _PNG_CHANNELS:
        raise InputError(path, "image", "a PNG file starting with a valid IHDR chunk (corrupt?)",
                         f"chunk {ctype!r} of {n} bytes, {w}x{h}, colour type {colour}")
    return ImageInfo(int(w), int(h), _PNG_CHANNELS[colour])


def png_info(path: str | Path, data: bytes | None = None) -> ImageInfo:
    """Size and channels of a PNG file from its IHDR chunk, checking that the file is complete.

    Args:
        path: the PNG file (named in errors).
        data: the whole file when already in memory: then every chunk is walked and its CRC
            verified (catches damage anywhere). Without it only the 33-byte header and the 12-byte
            trailer are read (two small reads, no decoding): a file that does not end with the IEND
            chunk (truncated, or with bytes after IEND) is then read whole and walked.

    Raises:
        InputError: naming the file: not a PNG, truncated (where the file ends), a damaged chunk
            (CRC mismatch, naming the chunk and its byte offset), or no IEND chunk.
    """
    path = Path(path)
    if data is None:
        try:
            with open(path, "rb") as f:
                head = f.read(33)
                size = f.seek(0, 2)
                f.seek(max(size - 12, 0))
                tail = f.read(12)
        except OSError as e:
            raise InputError(path, "image", "a readable PNG file", e.strerror) from None
        info = _png_header(path, head)
        if tail == _PNG_IEND and size >= 45:
            return info
        data = path.read_bytes()
    info = _png_header(path, data[:33])
    buf, pos, size = memoryview(data), 8, len(data)
    while True:
        if pos + 12 > size:
            raise InputError(path, "image", "a complete PNG file (truncated?)",
                             f"{size} bytes, ending inside the chunk header at byte {pos}")
        n, ctype = struct.unpack(">I4s", buf[pos:pos + 8])
        end = pos + 12 + n
        name = ctype.decode("latin-1")
        if end > size:
            raise InputError(path, "image", "a complete PNG file (truncated?)",
                             f"{size} bytes, ending inside chunk {name} at byte {pos} (needs {end})")
        if zlib.crc32(buf[pos + 4:end - 4]) != struct.unpack(">I", buf[end - 4:end])[0]:
            raise InputError(path, "image", "an undamaged PNG file (corrupt?)",
                             f"chunk {name} at byte {pos} fails its CRC check")
        if ctype == b"IEND":
            return info
        pos = end


def image_info(path: str | Path, *, verify: bool = True) -> ImageInfo:
    """Size and channels of a frame file as :func:`fusiongs.io.load_scene` reads it, without
    decoding a PNG's pixels; other formats are decoded (a raw file counts as RGB: it is demosaiced
    on loading).

    Args:
        path: the image file.
        verify: read a PNG whole and check every chunk's CRC (damage anywhere); ``False`` reads
            only its header and trailer (truncation). See :func:`png_info`.

    Raises:
        InputError: naming the file when it is missing, truncated or unreadable.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "image", "an existing image file", "no such file")
    if is_raw_path(path):
        mos, _ = read_raw_mosaic(path)
        return ImageInfo(int(mos.shape[1]), int(mos.shape[0]), 3)
    with open(path, "rb") as f:
        head = f.read(8)
    if head and _looks_like_png(path, head):
        return png_info(path, path.read_bytes() if verify else None)
    img = read_image(path)
    return ImageInfo(int(img.shape[1]), int(img.shape[0]), int(img.shape[2]))


def write_png(path: str | Path, img: np.ndarray, bits: int = 8) -> None:
    """Write ``[H, W, C]`` (C = 1 or 3, RGB) or ``[H, W]`` values in [0, 1] as a PNG, atomically.

    Values are clipped to [0, 1] and rounded to ``bits`` (8 or 16); a uint8 array is written as it
    is (8 bits). The file is written next to its destination under a temporary name and then
    renamed, so readers never see half a file.
    """
    import cv2

    path = Path(path)
    if bits not in (8, 16):
        raise InputError(path, "bits", "8 or 16", bits)
    raw = isinstance(img, np.ndarray) and img.dtype == np.uint8 and bits == 8
    a = img if raw else np.asarray(img, dtype=np.float64)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] == 3)):
        raise InputError(path, "image", "an array [H, W], [H, W, 1] or [H, W, 3]", a.shape)
    top = 255 if bits == 8 else 65535
    q = a if raw else np.rint(np.clip(np.nan_to_num(a), 0.0, 1.0) * top).astype(
        np.uint8 if bits == 8 else np.uint16)
    if q.ndim == 3:
        q = np.ascontiguousarray(q[:, :, ::-1])
    ok, buf = cv2.imencode(".png", q)
    if not ok:
        raise InputError(path, "image", "an image OpenCV can encode as PNG", q.shape)
    write_bytes(path, buf.tobytes())


def _open_raw(path: Path):
    try:
        import rawpy
    except ImportError:  # pragma: no cover - rawpy is a dependency
        raise MissingDependencyError("rawpy", "reading raw frames") from None
    if not path.is_file():
        raise InputError(path, "raw", "an existing raw file", "no such file")
    try:
        return rawpy.imread(str(path))
    except Exception as e:  # rawpy raises LibRawError subclasses and others
        raise InputError(path, "raw", "a raw file rawpy can open", type(e).__name__) from None


def read_raw_mosaic(path: str | Path) -> tuple[np.ndarray, str]:
    """Read a Bayer raw file's visible mosaic, normalised to [0, 1].

    ``(raw - black[channel]) / (white - black[channel])`` per pixel with the per-channel black
    levels and the white level from the file, clipped to [0, 1] (sensor saturation).

    Returns:
        ``([H, W] float32 linear mosaic, pattern)`` with ``pattern`` one of ``"RGGB"``, ``"BGGR"``,
        ``"GRBG"``, ``"GBRG"``, derived from rawpy's per-pixel colours and ``color_desc``.

    Raises:
        InputError: unreadable file or a non-Bayer sensor (X-Trans, four-colour, Foveon, linear).
    """
    path = Path(path)
    with _open_raw(path) as r:
        if r.raw_pattern is None or r.num_colors != 3:
            raise InputError(path, "raw", "a 2x2 Bayer sensor with three colours",
                             f"num_colors={r.num_colors}")
        # copies: rawpy's arrays are views of LibRaw memory freed when the file is closed
        raw = np.array(r.raw_image_visible, copy=True)
        colors = np.array(r.raw_colors_visible, copy=True)
        desc = r.color_desc.decode("ascii", "replace")
        black = np.asarray(r.black_level_per_channel, dtype=np.float64)
        white = float(r.white_level)
    if raw.ndim != 2 or raw.shape[0] < 2 or raw.shape[1] < 2:
        raise InputError(path, "raw", "a 2-D mosaic of at least 2x2", raw.shape)
    cell = colors[:2, :2]
    h, w = colors.shape
    tiled = np.tile(cell, ((h + 1) // 2, (w + 1) // 2))[:h, :w]
    try:
        pattern = "".join(desc[c] for c in cell.ravel())
    except IndexError:
        pattern = "?"
    if not np.array_equal(tiled, colors) or pattern not in ("RGGB", "BGGR", "GRBG", "GBRG"):
        raise InputError(path, "raw", "a 2x2 Bayer pattern of R, G, B", f"{pattern!r} ({desc})")
    blk = black[colors]
    out = (raw.astype(np.float64) - blk) / np.maximum(white - blk, 1.0)
    return np.clip(out, 0.0, 1.0).astype(np.float32), pattern


def read_raw(path: str | Path, *, demosaic: str | None = "opencv-ea", white_balance: bool = False,
             color_matrix: bool = False) -> np.ndarray | tuple[np.ndarray, str]:
    """Read a camera raw file as linear data.

    Args:
        path: raw file (anything LibRaw opens with a 2x2 Bayer sensor).
        demosaic: a :func:`fusiongs.events.cfa.demosaic` method (``"opencv-ea"``,
            ``"opencv-bilinear"``, ``"kornia"``, ...), or ``None`` for the mosaic itself.
        white_balance: multiply by the camera's as-shot white balance (normalised to green).
        color_matrix: apply the file's camera-RGB -> sRGB-primaries matrix (``rawpy.color_matrix``);
            an InputError when the file has none. Without it colours stay in camera RGB.

    Returns:
        ``[H, W, 3]`` float32 linear RGB (not clipped after the colour steps) when ``demosaic`` is
        given; else ``(mosaic [H, W] float32 in [0, 1], pattern)`` as :func:`read_raw_mosaic`.
    """
    from fusiongs.events.cfa import demosaic as _demosaic

    path = Path(path)
    mos, pattern = read_raw_mosaic(path)
    if demosaic is None:
        return mos, pattern
    rgb = np.asarray(_demosaic(mos, pattern, demosaic), dtype=np.float32)
    if white_balance or color_matrix:
        with _open_raw(path) as r:
            wb = np.asarray(r.camera_whitebalance[:3], dtype=np.float64)
            cm = np.asarray(r.color_matrix, dtype=np.float64)[:3, :3]
        if white_balance:
            if not (np.all(np.isfinite(wb)) and np.all(wb > 0)):
                raise InputError(path, "camera_whitebalance", "positive multipliers", wb.tolist())
            rgb = rgb * (wb / wb[1]).astype(np.float32)
        if color_matrix:
            if not np.any(cm):
                raise InputError(path, "color_matrix", "a camera-to-sRGB matrix in the file", "zeros")
            rgb = (rgb @ cm.T.astype(np.float32)).astype(np.float32)
    return rgb
