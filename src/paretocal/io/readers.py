"""Readers for the files a frame is made of: LiDAR sweeps, images, calibration text and YAML.

Every failure raises :class:`~paretocal.errors.InputError` naming the file and what is wrong.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import os
import re
import sys
import tempfile
import warnings
from pathlib import Path

import cv2
import numpy as np
import yaml

from ..errors import InputError

log = logging.getLogger(__name__)

POINT_SUFFIXES = (".bin", ".npy", ".pcd", ".ply")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
#: Field names read as the intensity column of a .pcd or .ply cloud (case-insensitive, first wins).
INTENSITY_FIELDS = ("intensity", "i", "reflectance")


def read_points(path: Path) -> np.ndarray:
    """Read a LiDAR sweep as an (N, 4) float32 array ``x, y, z, intensity``.

    ``.bin`` holds float32 quadruples (KITTI); ``.npy`` holds an (N, 3) or (N, 4) array (a
    missing intensity column reads as zeros); ``.pcd`` (PCL: ascii, binary or binary_compressed)
    and ``.ply`` (ascii, binary little or big endian) need fields ``x``, ``y``, ``z`` and may have
    an intensity field named ``intensity``, ``i`` or ``reflectance`` (zeros without one); other
    fields are ignored. Points with a NaN or infinite coordinate are dropped with a warning that
    counts them; a NaN or infinite intensity reads as zero.
    """
    path = Path(path)
    _require_file(path, "point cloud file")
    suffix = path.suffix.lower()
    try:
        if suffix == ".bin":
            size = path.stat().st_size
            if size % 16:
                raise InputError(f"{path}: size {size} bytes is not a multiple of 16 "
                                 "(float32 x, y, z, intensity); the file is truncated or not a "
                                 "KITTI .bin sweep")
            pts = np.fromfile(path, dtype=np.float32).reshape(-1, 4)
        elif suffix == ".npy":
            with open(path, "rb") as fh:
                if fh.read(6) != b"\x93NUMPY":
                    raise InputError(f"{path}: not a NumPy .npy file (no .npy header)")
            arr = np.load(path, allow_pickle=False)
            if arr.ndim != 2 or arr.shape[1] not in (3, 4):
                raise InputError(f"{path}: expected an N x 3 or N x 4 array, got shape {arr.shape}")
            if arr.dtype.kind not in "iuf":
                raise InputError(f"{path}: expected real numbers, got dtype {arr.dtype}")
            pts = np.zeros((arr.shape[0], 4), dtype=np.float32)
            with np.errstate(over="ignore", invalid="ignore"):   # out of float32 range -> inf
                pts[:, : arr.shape[1]] = arr
        elif suffix == ".pcd":
            pts = _read_pcd(path, path.read_bytes())
        elif suffix == ".ply":
            pts = _read_ply(path, path.read_bytes())
        else:
            raise InputError(f"{path}: unsupported point cloud format {suffix!r} "
                             f"(supported: {', '.join(POINT_SUFFIXES)})")
    except InputError:
        raise
    except OSError as exc:
        raise InputError(f"{path}: cannot read point cloud ({exc.strerror or exc})") from None
    except ValueError as exc:
        raise InputError(f"{path}: cannot read point cloud ({_first_line(exc)})") from None
    finite = np.isfinite(pts[:, :3]).all(axis=1)
    if len(pts) and not finite.any():
        raise InputError(f"{path}: all {len(pts)} points have NaN or infinite coordinates "
                         "(values beyond the float32 range count as infinite)")
    if not finite.all():
        log.warning("%s: dropped %d points with NaN or infinite coordinates",
                    path, int((~finite).sum()))
        pts = pts[finite]
    pts[:, 3] = np.nan_to_num(pts[:, 3], nan=0.0, posinf=0.0, neginf=0.0)
    if len(pts) == 0:
        raise InputError(f"{path}: the point cloud is empty")
    return np.ascontiguousarray(pts)


def _xyzi(path: Path, fields: dict[str, np.ndarray]) -> np.ndarray:
    """Stack named columns into (N, 4) float32 ``x, y, z, intensity`` (zeros without intensity)."""
    lower: dict[str, np.ndarray] = {}
    for name, col in fields.items():
        lower.setdefault(name.lower(), col)
    missing = [c for c in "xyz" if c not in lower]
    if missing:
        raise InputError(f"{path}: no {', '.join(repr(c) for c in missing)} field "
                         f"(fields: {', '.join(fields) or 'none'}); x, y and z are required")
    n = len(lower["x"])
    pts = np.zeros((n, 4), dtype=np.float32)
    with np.errstate(over="ignore", invalid="ignore"):   # doubles out of float32 range -> inf
        for j, c in enumerate("xyz"):
            pts[:, j] = lower[c]
        for name in INTENSITY_FIELDS:
            if name in lower:
                pts[:, 3] = lower[name]
                break
    return pts


def _loadtxt(body: bytes, **kw) -> np.ndarray:
    """Whitespace-separated numbers as a 2-D float64 table; (0, 0) for no data.

    numpy warns (UserWarning) on empty input: here that is an error the caller reports by
    comparing the table's shape with the header, so the warning is silenced.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return np.loadtxt(io.BytesIO(body), dtype=np.float64, ndmin=2, comments=None, **kw)


def _first_line(exc: Exception) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


# --- PCD (PCL) -----------------------------------------------------------------------------------

_PCD_TYPES = {("F", 4): "f4", ("F", 8): "f8", ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4",
              ("U", 8): "u8", ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4", ("I", 8): "i8"}
_PCD_DATA = ("ascii", "binary", "binary_compressed")


def _pcd_header(path: Path, raw: bytes) -> tuple[dict[str, list[str]], int]:
    """Header entries (upper-case key -> values) and the offset of the data."""
    entries: dict[str, list[str]] = {}
    lines: list[str] = []
    pos = 0
    while "DATA" not in entries:
        nl = raw.find(b"\n", pos)
        if nl < 0 or len(lines) > 64:
            raise InputError(f"{path}: not a PCD file: no 'DATA' line in the header")
        try:
            line = raw[pos:nl].decode("ascii").strip()
        except UnicodeDecodeError:
            if lines:
                raise InputError(f"{path}: PCD header has no 'DATA' line before the data") from None
            raise InputError(f"{path}: not a PCD file: the header is not text") from None
        pos = nl + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        if not lines and key.upper() not in ("VERSION", "FIELDS"):
            raise InputError(f"{path}: not a PCD file: the header starts with {key!r} "
                             "instead of VERSION or FIELDS")
        entries[key.upper()] = values
        lines.append(line)
    return entries, pos


def _pcd_int(path: Path, entries: dict[str, list[str]], key: str) -> int:
    try:
        value = int(entries[key][0])
    except (KeyError, IndexError, ValueError):
        raise InputError(f"{path}: PCD header {key} must be a non-negative integer, got "
                         f"{' '.join(entries.get(key, [])) or 'nothing'}") from None
    if value < 0:
        raise InputError(f"{path}: PCD header {key} must be a non-negative integer, got {value}")
    return value


def _read_pcd(path: Path, raw: bytes) -> np.ndarray:
    """A PCL point cloud file as (N, 4) float32; binary_compressed data is decoded by pypcd4."""
    entries, offset = _pcd_header(path, raw)
    for key in ("FIELDS", "SIZE", "TYPE"):
        if not entries.get(key):
            raise InputError(f"{path}: PCD header has no {key} line")
    fields = entries["FIELDS"]
    counts_text = entries.get("COUNT") or ["1"] * len(fields)
    for key, vals in (("SIZE", entries["SIZE"]), ("TYPE", entries["TYPE"]), ("COUNT", counts_text)):
        if len(vals) != len(fields):
            raise InputError(f"{path}: PCD header {key} has {len(vals)} entries for "
                             f"{len(fields)} FIELDS")
    try:
        sizes = [int(v) for v in entries["SIZE"]]
        counts = [int(v) for v in counts_text]
    except ValueError:
        raise InputError(f"{path}: PCD header SIZE and COUNT must be integers") from None
    types = [t.upper() for t in entries["TYPE"]]
    for name, t, s, c in zip(fields, types, sizes, counts):
        if (t, s) not in _PCD_TYPES:
            raise InputError(f"{path}: PCD field {name!r} has unsupported TYPE {t} SIZE {s}")
        if c < 1:
            raise InputError(f"{path}: PCD field {name!r} has COUNT {c}")
    for name, c in zip(fields, counts):
        if name.lower() in ("x", "y", "z") + INTENSITY_FIELDS and c != 1:
            raise InputError(f"{path}: PCD field {name!r} has COUNT {c}, expected 1")
    width = _pcd_int(path, entries, "WIDTH") if "WIDTH" in entries else None
    height = _pcd_int(path, entries, "HEIGHT") if "HEIGHT" in entries else 1
    if "POINTS" in entries:
        n = _pcd_int(path, entries, "POINTS")
    elif width is not None:
        n = width * height
    else:
        raise InputError(f"{path}: PCD header has neither POINTS nor WIDTH")
    if width is not None and width * height != n:
        raise InputError(f"{path}: PCD header says WIDTH {width} x HEIGHT {height} but POINTS {n}")
    data = (entries["DATA"] or [""])[0].lower()
    if data not in _PCD_DATA:
        raise InputError(f"{path}: PCD header DATA {data!r} is not one of {', '.join(_PCD_DATA)}")
    # One column per field and count; padding fields are named "_" and may repeat.
    names, formats = [], []
    for k, (name, t, s, c) in enumerate(zip(fields, types, sizes, counts)):
        for j in range(c):
            names.append(name if c == 1 and name != "_" else f"_{k}_{j}_{name}")
            formats.append(_PCD_TYPES[(t, s)])
    if len(set(names)) != len(names):
        raise InputError(f"{path}: PCD header FIELDS names a field twice ({' '.join(fields)})")
    dtype = np.dtype({"names": names, "formats": ["<" + f for f in formats]})
    body = raw[offset:]
    if n == 0:
        return _xyzi(path, {name: np.zeros(0) for name in names if not name.startswith("_")})
    if data == "ascii":
        # Whitespace-separated values, one point per line (tolerant of tabs and trailing blanks).
        try:
            table = _loadtxt(body)
        except ValueError as exc:
            raise InputError(f"{path}: PCD ascii data cannot be parsed ({_first_line(exc)})") from None
        if table.shape != (n, len(names)):
            raise InputError(f"{path}: PCD ascii data has {table.shape[0]} rows of "
                             f"{table.shape[1] if table.size else 0} values; the header says "
                             f"POINTS {n} of {len(names)} values (truncated or wrong header)")
        cols = {name: table[:, j] for j, name in enumerate(names)}
    elif data == "binary":
        need = n * dtype.itemsize
        if len(body) < need:
            raise InputError(f"{path}: PCD binary data is truncated: {len(body)} bytes for "
                             f"POINTS {n} of {dtype.itemsize} bytes ({need} bytes)")
        arr = np.frombuffer(body, dtype=dtype, count=n)
        cols = {name: arr[name] for name in names}
    else:
        cols = dict(zip(names, _pcd_compressed(path, body, types, sizes, counts, n)))
    return _xyzi(path, {k: v for k, v in cols.items() if not k.startswith("_")})


def _pcd_compressed(path: Path, body: bytes, types: list[str], sizes: list[int],
                    counts: list[int], n: int) -> list[np.ndarray]:
    """Decode binary_compressed data (LZF, field-major) with pypcd4; one array per value column."""
    from pypcd4 import PointCloud

    if len(body) < 8:
        raise InputError(f"{path}: PCD binary_compressed data is truncated (no size words)")
    # Check the two size words before the decoder allocates what they claim: a corrupt word
    # must not make it reserve gigabytes. LZF expands at most about 100-fold.
    packed, unpacked = (int(v) for v in np.frombuffer(body[:8], "<u4"))
    need = n * sum(s * c for s, c in zip(sizes, counts))
    if unpacked != need or packed > len(body) - 8 or unpacked > 128 * packed + 1024:
        raise InputError(f"{path}: PCD binary_compressed data cannot be decoded (its size "
                         f"words say {packed} bytes compressed, {unpacked} uncompressed; the "
                         f"header needs {need} uncompressed and {len(body) - 8} bytes follow); "
                         "the file is truncated or corrupt")
    # pypcd4 parses a fixed set of header lines: hand it a canonical header of the fields parsed
    # here (plain names, so that padding fields called "_" keep their place).
    k = len(types)
    head = (f"FIELDS {' '.join(f'f{j}' for j in range(k))}\nSIZE {' '.join(map(str, sizes))}\n"
            f"TYPE {' '.join(types)}\nCOUNT {' '.join(map(str, counts))}\nWIDTH {n}\nHEIGHT 1\n"
            f"POINTS {n}\nDATA binary_compressed\n")
    try:
        arr = PointCloud.from_fileobj(io.BytesIO(head.encode() + body)).pc_data
    except Exception as exc:  # any decoder failure means a corrupt file
        raise InputError(f"{path}: PCD binary_compressed data cannot be decoded "
                         f"({_first_line(exc)}); the file is truncated or corrupt") from None
    if arr.ndim != 1 or len(arr) != n or len(arr.dtype.names or ()) != sum(counts):
        raise InputError(f"{path}: PCD binary_compressed data holds {arr.size} points, the header "
                         f"says POINTS {n}")
    return [arr[name] for name in arr.dtype.names]


# --- PLY ------------------------------------------------------------------------------------------

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2",
              "int16": "i2", "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4",
              "uint": "u4", "uint32": "u4", "float": "f4", "float32": "f4", "double": "f8",
              "float64": "f8"}
_PLY_FORMATS = {"ascii": "", "binary_little_endian": "<", "binary_big_endian": ">"}


def _read_ply(path: Path, raw: bytes) -> np.ndarray:
    """The ``vertex`` element of a PLY file as (N, 4) float32 ``x, y, z, intensity``."""
    if not re.match(rb"ply\r?\n", raw[:5]):
        raise InputError(f"{path}: not a PLY file (the first line is not 'ply')")
    end = re.search(rb"(^|\n)end_header[ \t]*\r?\n", raw[:1 << 20])
    if end is None:
        raise InputError(f"{path}: PLY header has no 'end_header' line")
    offset = end.end()
    try:
        header = raw[:end.start()].decode("ascii").splitlines()[1:]
    except UnicodeDecodeError:
        raise InputError(f"{path}: PLY header is not text") from None
    fmt = None
    elements: list[list] = []  # [name, count, [(property, type) or (property, None) for lists]]
    for line in header:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        try:
            if words[0] == "format":
                fmt = words[1]
                if fmt not in _PLY_FORMATS:
                    raise InputError(f"{path}: unsupported PLY format {fmt!r} (supported: "
                                     f"{', '.join(_PLY_FORMATS)})")
            elif words[0] == "element":
                elements.append([words[1], int(words[2]), []])
                if elements[-1][1] < 0:
                    raise ValueError
            elif words[0] == "property":
                if not elements:
                    raise ValueError
                if words[1] == "list":
                    elements[-1][2].append((words[4], None))
                else:
                    if words[1] not in _PLY_TYPES:
                        raise InputError(f"{path}: PLY property {words[2]!r} has unknown type "
                                         f"{words[1]!r}")
                    elements[-1][2].append((words[2], _PLY_TYPES[words[1]]))
            else:
                raise ValueError
        except (IndexError, ValueError):
            raise InputError(f"{path}: malformed PLY header line {line!r}") from None
    if fmt is None:
        raise InputError(f"{path}: PLY header has no 'format' line")
    names = [e[0] for e in elements]
    if "vertex" not in names:
        raise InputError(f"{path}: PLY file has no 'vertex' element")
    iv = names.index("vertex")
    _, n, props = elements[iv]
    lists = [p for p, t in props if t is None]
    if lists:
        raise InputError(f"{path}: PLY vertex property {lists[0]!r} is a list; points need "
                         "scalar properties")
    pnames = [p for p, _ in props]
    if len(set(pnames)) != len(pnames):
        raise InputError(f"{path}: PLY vertex element names a property twice")
    body = raw[offset:]
    if fmt == "ascii":
        # One line per element instance: skip the lines of the elements before the vertices.
        skip = sum(e[1] for e in elements[:iv])
        if n == 0:
            return np.zeros((0, 4), np.float32)
        try:
            table = _loadtxt(body, skiprows=skip, max_rows=n)
        except ValueError as exc:
            raise InputError(f"{path}: PLY ascii vertex data cannot be parsed "
                             f"({_first_line(exc)})") from None
        if table.shape != (n, len(pnames)):
            raise InputError(f"{path}: PLY ascii data has {table.shape[0]} vertex lines of "
                             f"{table.shape[1] if table.size else 0} values; the header says "
                             f"{n} of {len(pnames)} (truncated or wrong header)")
        cols = {p: table[:, j] for j, p in enumerate(pnames)}
    else:
        endian = _PLY_FORMATS[fmt]
        start = 0
        for name, count, eprops in elements[:iv]:
            if any(t is None for _, t in eprops):
                raise InputError(f"{path}: PLY element {name!r} before 'vertex' has list "
                                 "properties; binary files with that layout are not supported")
            start += count * sum(np.dtype(t).itemsize for _, t in eprops)
        dtype = np.dtype([(p, endian + t) for p, t in props])
        need = start + n * dtype.itemsize
        if len(body) < need:
            raise InputError(f"{path}: PLY binary data is truncated: {len(body)} bytes after the "
                             f"header, {need} needed for {n} vertices of {dtype.itemsize} bytes")
        arr = np.frombuffer(body, dtype=dtype, count=n, offset=start)
        cols = {p: arr[p] for p in pnames}
    return _xyzi(path, cols)


def _require_file(path: Path, what: str) -> None:
    """Fail naming ``path`` when it is missing or not a regular file."""
    if path.is_file():
        return
    if path.is_dir():
        raise InputError(f"{path}: {what} expected, but this is a folder")
    if path.exists():
        raise InputError(f"{path}: {what} expected, but this is not a regular file")
    raise InputError(f"{path}: {what} not found")


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


def decode_image(path: Path) -> np.ndarray:
    """The image at ``path`` as OpenCV decodes it (any depth and channel count).

    Raises :class:`InputError` naming the file when it is missing, unreadable, empty (0 bytes)
    or cannot be decoded; what the decoder printed is put in the message, not on stderr.
    """
    path = Path(path)
    _require_file(path, "image file")
    try:
        raw = np.fromfile(path, dtype=np.uint8)
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


def read_image(path: Path) -> np.ndarray:
    """Read an image as (H, W, 3) uint8 BGR; grey images are expanded to three channels."""
    img = decode_image(Path(path))
    if img.dtype != np.uint8:
        # 16-bit and float images: keep the relative contrast for edge detection.
        img = cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    elif img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    elif img.shape[2] != 3:
        raise InputError(f"{path}: image has {img.shape[2]} channels; expected 1, 3 or 4")
    return img


def read_kitti_calib(path: Path) -> dict[str, np.ndarray]:
    """Parse a KITTI calibration text file (``key: numbers`` per line) into float64 arrays.

    Lines whose values are not numbers (such as ``calib_time``) are skipped.
    """
    path = Path(path)
    _require_file(path, "calibration file")
    out: dict[str, np.ndarray] = {}
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text file (not UTF-8); expected a KITTI calibration "
                         "file") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read calibration file ({exc.strerror or exc})") from None
    for line in text.splitlines():
        if ":" not in line:
            continue
        key, _, rest = line.partition(":")
        try:
            out[key.strip()] = np.array([float(v) for v in rest.split()], dtype=np.float64)
        except ValueError:
            continue
    return out


def calib_matrix(calib: dict[str, np.ndarray], key: str, shape: tuple[int, int],
                 path: Path) -> np.ndarray:
    """Fetch ``key`` from a parsed KITTI calibration and reshape it, or fail naming the file."""
    if key not in calib:
        raise InputError(f"{path}: missing key {key!r}")
    v = calib[key]
    if v.size != shape[0] * shape[1]:
        raise InputError(f"{path}: {key!r} has {v.size} values, expected "
                         f"{shape[0] * shape[1]} ({shape[0]}x{shape[1]})")
    m = v.reshape(shape)
    if not np.all(np.isfinite(m)):
        raise InputError(f"{path}: {key!r} contains NaN or infinite values")
    return m


def read_mapping(path: Path) -> dict:
    """Read a YAML or JSON file whose top level is a mapping."""
    path = Path(path)
    _require_file(path, "file")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text file (not UTF-8); expected YAML or JSON") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    kind = "JSON" if path.suffix.lower() == ".json" else "YAML"
    try:
        data = json.loads(text) if kind == "JSON" else yaml.safe_load(text)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
        what = exc.problem or exc.context or "syntax error"
        raise InputError(f"{path}: not valid YAML ({where}{what})") from None
    except (ValueError, yaml.YAMLError, RecursionError) as exc:
        raise InputError(f"{path}: not valid {kind} ({_first_line(exc)})") from None
    if not isinstance(data, dict):
        got = "an empty file" if data is None else f"a {type(data).__name__}"
        raise InputError(f"{path}: expected a mapping (key: value) at the top level, got {got}")
    return data
