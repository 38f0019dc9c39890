"""Reading camera images (PNG, JPEG; 8- and 16-bit): sizes checked from the header before
decoding, a 16-bit frame stretched to 8 bits by its own range, decoder complaints kept out of
the process's stderr and put into the one-line error instead.

Every failure raises :class:`~paretocal.errors.InputError` naming the file and what is wrong.
"""

from __future__ import annotations

import contextlib
import functools
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
#: Steps (segments and fill bytes) of a JPEG's header walked in Python before the compiled walk
#: takes over: real files have a few dozen segments before the frame header; a file padded with
#: millions of them (legal, and no more than a way to hide its size) is walked at C speed.
_PYTHON_STEPS = 4096


def image_header_size(data) -> tuple[int, int] | None:
    """``(width, height)`` in pixels from the header of PNG or JPEG ``data`` (bytes, or a
    binary file object read from its current position), without decoding; None for other
    formats or a header this cannot read (the decoder then judges the data).

    A PNG's size is its first chunk's (IHDR). A JPEG's segments are walked from its start to
    the frame header (SOFn), skipping fill bytes and any number of segments: the walk is
    bounded by the data, not by a count of segments (a compiled walk past the first
    :data:`_PYTHON_STEPS`: 64 MB of empty comment segments in about 0.1 s). From a file
    object a PNG's first 24 bytes are read, a JPEG's whole data."""
    if hasattr(data, "read"):
        first = data.read(24)
        data = first + data.read() if first[:3] == b"\xff\xd8\xff" else first
    buf = np.frombuffer(data, dtype=np.uint8)
    head = buf[:24].tobytes()
    if head[:8] == _PNG and head[12:16] == b"IHDR" and len(head) == 24:
        return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
    if head[:3] != b"\xff\xd8\xff":
        return None
    state, a, b = _jpeg_walk(buf, 2, _PYTHON_STEPS)
    if state == _WALKING:
        state, a, b = _compiled_jpeg_walk()(buf, a, len(buf) + 1)
    return (a, b) if state == _FOUND else None


_FOUND, _NO_FRAME, _WALKING = 0, 1, 2


def _jpeg_walk(buf: np.ndarray, pos: int, steps: int) -> tuple[int, int, int]:
    """Walk the JPEG segments of ``buf`` (uint8) from ``pos`` to the frame header, at most
    ``steps`` segments and fill bytes: ``(_FOUND, width, height)``, ``(_NO_FRAME, 0, 0)``
    (no frame header before the scan data, the end, or something that is no segment), or
    ``(_WALKING, pos, 0)`` to go on from ``pos``. Plain Python over an array, so that numba
    compiles it unchanged (:func:`_compiled_jpeg_walk`)."""
    end = len(buf)
    while steps > 0:
        steps -= 1
        if pos >= end or buf[pos] != 0xFF:
            return _NO_FRAME, 0, 0
        pos += 1
        if pos < end and buf[pos] == 0xFF:
            continue                               # a fill byte: any marker may follow them
        if pos >= end:
            return _NO_FRAME, 0, 0
        marker = int(buf[pos])
        pos += 1
        if marker == 0x01 or 0xD0 <= marker <= 0xD7:
            continue                               # TEM, RSTn: no length
        if marker == 0x00 or 0xD8 <= marker <= 0xDA:
            return _NO_FRAME, 0, 0                 # a stuffed byte, SOI, EOI, SOS: no frame
        if 0xC0 <= marker <= 0xCF and marker != 0xC4 and marker != 0xC8 and marker != 0xCC:
            if pos + 7 > end:                      # SOFn: length, precision, height, width
                return _NO_FRAME, 0, 0
            h = int(buf[pos + 3]) * 256 + int(buf[pos + 4])
            w = int(buf[pos + 5]) * 256 + int(buf[pos + 6])
            return (_FOUND, w, h) if w > 0 and h > 0 else (_NO_FRAME, 0, 0)
        if pos + 2 > end:
            return _NO_FRAME, 0, 0
        length = int(buf[pos]) * 256 + int(buf[pos + 1])
        if length < 2:
            return _NO_FRAME, 0, 0
        pos += length
    return _WALKING, pos, 0


@functools.cache
def _compiled_jpeg_walk():
    """:func:`_jpeg_walk` compiled (numba, cached on disk), for the rare file that needs it."""
    from numba import njit

    return njit(cache=True)(_jpeg_walk)


def check_image_size(where, size: tuple[int, int] | None,
                     expected: tuple[int, int] | None = None, what: str = "image",
                     against: str = "the calibration says") -> None:
    """Refuse an image whose header (``size``: width, height from :func:`image_header_size`,
    None when it gives none) says more than :data:`MAX_IMAGE_PIXELS`, or another size than
    ``expected`` (width, height: the camera's), before it is decoded; or check a decoded
    image's size the same way. ``where`` names it, ``what`` it is (``"image"``, ``"mask"``),
    ``against`` where ``expected`` comes from."""
    if size is None:
        return
    w, h = size
    if w * h > MAX_IMAGE_PIXELS:
        raise InputError(f"{where}: the image header says {w}x{h} pixels, more than "
                         f"the {MAX_IMAGE_PIXELS:,} an image may have")
    if expected is not None and (w, h) != tuple(expected):
        raise InputError(f"{where}: {what} is {w}x{h} but {against} "
                         f"{expected[0]}x{expected[1]}")


def image_size(path: Path) -> tuple[int, int]:
    """``(width, height)`` of the image at ``path``: from its header (PNG: its first 24 bytes;
    JPEG), else as decoded. Raises :class:`InputError` as :func:`decode_image` does."""
    path = Path(path)
    with _image_file(path) as fh:
        size = image_header_size(fh)
    if size is None:
        img = decode_image(path)
        return img.shape[1], img.shape[0]
    check_image_size(path, size)
    return size


@contextlib.contextmanager
def _image_file(path: Path):
    """The image file ``path`` open for reading, once it is known to be a regular file of at
    most :data:`MAX_IMAGE_BYTES` that is not empty; a failure to read it (inside the block
    too) is an :class:`InputError` naming it."""
    require_file(path, "image file")
    try:
        if require_size(path, MAX_IMAGE_BYTES, "image file") == 0:
            raise InputError(f"{path}: the image file is empty (0 bytes)")
        with open(path, "rb") as fh:
            yield fh
    except OSError as exc:
        raise InputError(f"{path}: cannot read the image ({exc.strerror or exc})") from None


def decode_image(path: Path, expected: tuple[int, int] | None = None,
                 what: str = "image") -> np.ndarray:
    """The image at ``path`` as OpenCV decodes it (any depth and channel count).

    ``expected`` (width, height), the camera's size: an image of another size is refused
    (naming ``what`` it is) before it is decoded when its header says so, else once decoded.

    Raises :class:`InputError` naming the file when it is missing, unreadable, empty (0 bytes),
    of another size or cannot be decoded; what the decoder printed is put in the message, not
    on stderr.
    """
    path = Path(path)
    with _image_file(path) as fh:
        # A PNG is judged from its first 24 bytes, before the file is read; a JPEG's segments
        # are walked in the bytes the decoder reads.
        check_image_size(path, image_header_size(fh.read(24)), expected, what)
        fh.seek(0)
        raw = np.fromfile(fh, dtype=np.uint8)
    check_image_size(path, image_header_size(raw.data), expected, what)
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
    check_image_size(path, (img.shape[1], img.shape[0]), expected, what)
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


def read_image(path: Path, expected: tuple[int, int] | None = None) -> np.ndarray:
    """Read an image as (H, W, 3) uint8 BGR; grey images are expanded to three channels.
    ``expected`` (width, height): the camera's size, checked as :func:`decode_image` does."""
    img = decode_image(Path(path), expected)
    if img.dtype != np.uint8:
        img = _to_8bit(img)
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    elif img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    elif img.shape[2] != 3:
        raise InputError(f"{path}: image has {img.shape[2]} channels; expected 1, 3 or 4")
    return img
