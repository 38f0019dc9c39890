"""Reading camera images (PNG, JPEG; 8- and 16-bit): sizes checked from the header before
decoding, a 16-bit frame stretched to 8 bits by its own range, decoder complaints kept out of
the process's stderr and put into the one-line error instead.

Every failure raises :class:`~paretocal.errors.InputError` naming the file and what is wrong.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError
from .paths import require_file, require_size

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")

# What a file may hold, or its header claim, is checked before anything is allocated for it (a
# stat and a header read: the normal path costs nothing measurable). Each limit is far beyond any
# real sensor or file, so that only a corrupt or hostile file meets it; docs/bad_input.md lists
# them with their messages.

#: Pixels of an image (width x height), read from the PNG or JPEG header before decoding. The
#: largest camera sensors have about 150 million pixels, automotive ones 2 to 8 million; a
#: larger header (a decompression bomb: a 20000 x 20000 PNG of 1 MB decodes to 1.2 GB) is
#: refused. 2**28 = 268 million, e.g. 16384 x 16384.
MAX_IMAGE_PIXELS = 1 << 28
#: Bytes of an image file: an uncompressed image of MAX_IMAGE_PIXELS 16-bit RGBA pixels
#: (8 bytes each) is the largest a camera image can be. 2 GiB.
MAX_IMAGE_BYTES = MAX_IMAGE_PIXELS * 8


@contextlib.contextmanager
def _native_stderr(sink: list[str]):
    """Collect what native code (libpng, libjpeg, OpenCV's log) writes to file descriptor 2.

    Decoders print their complaints straight to the process's stderr, which would add stray
    lines to the CLI's one-line error; the text is appended to ``sink`` instead, for the
    error message. Not thread-safe (fd 2 is process-wide): used around short decoder calls.
    """
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):
        yield                                   # no usable fd 2: let the library print
        return
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            sink.append(tmp.read(4096).decode("utf-8", "replace"))


def _decoder_note(texts: list[str]) -> str:
    """The last line a decoder printed, shortened, for an error message ('' if none)."""
    lines = [ln.strip() for t in texts for ln in t.splitlines() if ln.strip()]
    if not lines:
        return ""
    # OpenCV's log lines: "[ WARN:0@0.01] global grfmt_png.cpp:793 readFromStreamOrBuffer ..."
    last = re.sub(r"^\[\s*(WARN|ERROR|INFO)[^\]]*\]\s*(global\s+\S+\s+)?(\w+\s+)?", "",
                  lines[-1])
    last = re.sub(r"\w+\('[^']*'\):\s*", "", last).split(" OpenCV(")[0].rstrip(" :")
    return f": {last[:160]}" if last else ""


_PNG = b"\x89PNG\r\n\x1a\n"
#: JPEG start-of-frame markers (baseline, progressive, lossless, arithmetic): they hold the size.
_JPEG_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


def image_header_size(fh) -> tuple[int, int] | None:
    """``(width, height)`` in pixels from the header of the PNG or JPEG data in the binary
    file object ``fh`` (read from its current position), without decoding; None for other
    formats or a header this cannot read (the decoder then judges the data)."""
    start = fh.tell()
    head = fh.read(24)
    if head[:8] == _PNG and head[12:16] == b"IHDR":
        return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
    if head[:3] != b"\xff\xd8\xff":
        return None
    pos = start + 2
    for _ in range(1024):               # the segments before the frame header (APPn, DQT, ...)
        fh.seek(pos)
        seg = fh.read(9)
        if len(seg) < 4 or seg[0] != 0xFF:
            return None
        marker = seg[1]
        if marker == 0xFF or 0xD0 <= marker <= 0xD7 or marker == 0x01:
            pos += 1 if marker == 0xFF else 2        # a fill byte, or a marker without length
            continue
        if marker in _JPEG_SOF:
            h, w = int.from_bytes(seg[5:7], "big"), int.from_bytes(seg[7:9], "big")
            return (w, h) if len(seg) == 9 and w and h else None
        if marker in (0xD9, 0xDA):                  # end of image, or scan data: no frame size
            return None
        pos += 2 + int.from_bytes(seg[2:4], "big")
    return None


def check_image_size(where, size: tuple[int, int] | None) -> None:
    """Refuse an image whose header (``size``: width, height from :func:`image_header_size`)
    says more than :data:`MAX_IMAGE_PIXELS`, before it is decoded; ``where`` names it."""
    if size is not None and size[0] * size[1] > MAX_IMAGE_PIXELS:
        raise InputError(f"{where}: the image header says {size[0]}x{size[1]} pixels, more than "
                         f"the {MAX_IMAGE_PIXELS:,} an image may have")


def decode_image(path: Path) -> np.ndarray:
    """The image at ``path`` as OpenCV decodes it (any depth and channel count).

    Raises :class:`InputError` naming the file when it is missing, unreadable, empty (0 bytes)
    or cannot be decoded; what the decoder printed is put in the message, not on stderr.
    """
    path = Path(path)
    require_file(path, "image file")
    try:
        require_size(path, MAX_IMAGE_BYTES, "image file")
        with open(path, "rb") as fh:
            check_image_size(path, image_header_size(fh))
            fh.seek(0)
            raw = np.fromfile(fh, dtype=np.uint8)
    except OSError as exc:
        raise InputError(f"{path}: cannot read the image ({exc.strerror or exc})") from None
    if raw.size == 0:
        raise InputError(f"{path}: the image file is empty (0 bytes)")
    notes: list[str] = []
    with _native_stderr(notes):
        try:
            img = cv2.imdecode(raw, cv2.IMREAD_UNCHANGED)
        except cv2.error:
            img = None
    if img is None or img.size == 0:
        raise InputError(f"{path}: cannot decode the image (corrupt, truncated or not an "
                         f"image{_decoder_note(notes)})")
    if _decoder_note(notes):
        log.warning("%s: the image decoder reported a problem%s", path, _decoder_note(notes))
    return img


#: Share of the pixels (per tail) that 16-bit and float images may hold beyond their black and
#: white points: a hot or dead pixel, or a cluster of up to 0.1 % of the frame (466 pixels of a
#: 1242x375 image), does not set the scale; clipping so few to black or white loses no edge that
#: matters.
STRETCH_CLIP = 0.001


def _to_8bit(img: np.ndarray) -> np.ndarray:
    """A 16-bit or float image as uint8 for edge detection, its 0.1th to 99.9th percentile
    (:data:`STRETCH_CLIP`, over the finite values of every channel) stretched to 0..255.

    The extremes would let one hot pixel decide: a 12-bit frame stored in 16 bits with one
    pixel at 65535 turns black (every other value below 16 of 255) and shows no edges.
    """
    values = img[np.isfinite(img)] if img.dtype.kind == "f" else img.ravel()
    if values.size == 0:
        return np.zeros(img.shape, np.uint8)
    lo, hi = np.percentile(values, [100 * STRETCH_CLIP, 100 * (1 - STRETCH_CLIP)])
    if not hi > lo:
        lo, hi = float(values.min()), float(values.max())
    if not hi > lo:
        return np.zeros(img.shape, np.uint8)
    scaled = (np.nan_to_num(img.astype(np.float32), nan=lo) - lo) * (255.0 / (hi - lo))
    return np.clip(np.rint(scaled), 0, 255).astype(np.uint8)


def read_image(path: Path) -> np.ndarray:
    """Read an image as (H, W, 3) uint8 BGR; grey images are expanded to three channels."""
    img = decode_image(Path(path))
    if img.dtype != np.uint8:
        img = _to_8bit(img)
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    elif img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    elif img.shape[2] != 3:
        raise InputError(f"{path}: image has {img.shape[2]} channels; expected 1, 3 or 4")
    return img
