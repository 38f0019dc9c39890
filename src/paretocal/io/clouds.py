"""Reading LiDAR sweeps: ``.pcd``, ``.ply``, ``.npy`` and headerless ``.bin`` files.

Every failure raises :class:`~paretocal.errors.InputError` naming the file and what is wrong.

Point clouds
------------
:func:`read_cloud` reads ``.pcd`` (PCL: ascii, binary, binary_compressed; every PCD integer and
float type), ``.ply`` (ascii, binary little or big endian), ``.npy`` (a plain N x 3 / N x 4
array, or a record array with named fields) and headerless ``.bin`` files (see
:data:`BIN_LAYOUTS`). Besides ``x, y, z`` it keeps three optional fields, matched by name
without regard to case; within each list the first name the file has wins:

=========  ===================================================================
intensity  ``intensity``, ``reflectivity``, ``signal``, ``i``, ``reflectance``
ring       ``ring``, ``laser_id``, ``channel``, ``line``
time       ``time``, ``t``, ``timestamp``, ``offset_time``
=========  ===================================================================

(Ouster clouds hold both ``reflectivity`` and ``signal``: the calibrated ``reflectivity`` is
preferred.) Other fields are ignored.

Ring numbers must be whole numbers 0..255; gaps (only 0, 2, 4, ...) are kept as they are.

Time is converted to seconds by a rule that looks at the data, because files do not state the
unit: a LiDAR sweep lasts between a few and a few hundred milliseconds, so the unit is the one of
s, ms, us, ns that puts the span of the times across the cloud (max - min) within
:data:`PLAUSIBLE_SWEEP_S` (1 ms .. 1 s). The units are tried starting from the field type's
usual one: ns, us, ms, s for integer fields (Livox ``offset_time``, Ouster ``t``: integer
nanoseconds) and s, ms, us, ns for float fields (Velodyne ``time``, Hesai ``timestamp``:
seconds). Neighbouring units are 1000 apart, so at most one unit fits except at the bounds,
where the usual one wins. When none fits (every point has the same time, or a span longer than
a second) the usual unit is kept (ns for integers, s for floats) and ``fields["warnings"]`` says
so with the span; float times read in another unit than seconds are also noted there. Times stay
on the file's own clock (not shifted to start at 0); a nanosecond epoch in float64 seconds keeps
about 0.2 us.
"""

from __future__ import annotations

import io
import logging
import math
import os
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, excerpt, first_line, is_name, key_list, quote
from .arrays import npy_data, npy_header
from .paths import mib, require_file, require_size

log = logging.getLogger(__name__)

POINT_SUFFIXES = (".bin", ".npy", ".pcd", ".ply")
#: Field names read as the intensity of a cloud (case-insensitive, first wins).
INTENSITY_FIELDS = ("intensity", "reflectivity", "signal", "i", "reflectance")
#: Field names read as the laser (ring) index (case-insensitive, first wins).
RING_FIELDS = ("ring", "laser_id", "channel", "line")
#: Field names read as the per-point time (case-insensitive, first wins).
TIME_FIELDS = ("time", "t", "timestamp", "offset_time")
#: Span of a sweep's per-point times, in seconds, that the time-unit rule accepts as plausible.
PLAUSIBLE_SWEEP_S = (1e-3, 1.0)
#: How a user declares the layout of .bin files (the text put into error messages).
DECLARE_LAYOUT = "points: {{layout: {}}} in calib.yaml"

# What a file may hold, or its header claim, is checked before anything is allocated for it (a
# stat and a header read: the normal path costs nothing measurable). Each limit is far beyond any
# real sensor or file, so that only a corrupt or hostile file meets it; docs/bad_input.md lists
# them with their messages.

#: Points in one cloud file, by its header (a .npy's shape, a PCD's POINTS, a PLY's vertex
#: count) or size. The densest LiDARs give a few hundred thousand points a sweep (128 beams at
#: 2048 columns: 262,144); 2**25 (33.5 million) leaves room for sweeps accumulated into one file.
MAX_CLOUD_POINTS = 1 << 25
#: Bytes of one cloud file, and of the data its header says it holds (points x record size):
#: MAX_CLOUD_POINTS records of 64 bytes, above the widest records drivers write (32 to 48
#: bytes: x, y, z, intensity, ring, time and padding). 2 GiB.
MAX_CLOUD_BYTES = MAX_CLOUD_POINTS * 64
#: Values per point in a PCD header (the sum of its COUNTs), checked before a column is made
#: for each: a LiDAR point has under a dozen; PCL's widest point type (ShapeContext1980) 1989.
MAX_POINT_VALUES = 4096

_TIME_UNITS = {"s": 1.0, "ms": 1e3, "us": 1e6, "ns": 1e9}
_UNIT_WORDS = {"s": "seconds", "ms": "milliseconds", "us": "microseconds", "ns": "nanoseconds"}
#: A .bin file is only judged to be in another layout with at least this many records: fewer
#: whole-numbered ring values can be chance (tiny synthetic or hand-made files).
_MIN_LAYOUT_EVIDENCE = 64


@dataclass(frozen=True)
class BinLayout:
    """The record of a headerless ``.bin`` cloud: one record per point, fields back to back.

    Attributes
    ----------
    columns : tuple of (str, str)
        Field name and NumPy type (little endian) of each value in a record, in file order.
        ``x, y, z`` are metres; ``ring`` and ``time`` follow the rules of :func:`read_cloud`.
    note : str
        Where the layout is found and what its values mean.
    """

    columns: tuple[tuple[str, str], ...]
    note: str

    @property
    def dtype(self) -> np.dtype:
        """The record as a structured NumPy dtype."""
        return np.dtype(list(self.columns))

    @property
    def record_bytes(self) -> int:
        """Bytes per point."""
        return self.dtype.itemsize

    def describe(self) -> str:
        """The record in words, e.g. ``float32 x, y, z, intensity; 16 bytes per point``."""
        kinds = {np.dtype(t).name for _, t in self.columns}
        names = ", ".join(n for n, _ in self.columns)
        return f"{'/'.join(sorted(kinds))} {names}; {self.record_bytes} bytes per point"


def _float32_layout(names: str, note: str) -> BinLayout:
    return BinLayout(tuple((n, "<f4") for n in names.split()), note)


#: The declared layouts of ``.bin`` clouds, by the name users give (``bin_layout``). Without a
#: declaration a ``.bin`` file is read as ``kitti``, but refused when its size does not fit, or
#: when it holds at least 64 records of a layout with a ring column whose every ring is a whole
#: number 0..255 (see ``_fits_ring_layout``). Layouts without a ring (``xyzit``) cannot be told
#: from KITTI by their data: such a file whose size divides by 16 reads as ``kitti`` unless
#: declared.
BIN_LAYOUTS: dict[str, BinLayout] = {
    "kitti": _float32_layout(
        "x y z intensity",
        "KITTI, SemanticKITTI and most .bin exports; intensity as stored (KITTI: 0..1); the "
        "default"),
    "nuscenes": _float32_layout(
        "x y z intensity ring",
        "nuScenes LIDAR_TOP .pcd.bin: intensity 0..255, the ring index stored as a float"),
    "xyzit": _float32_layout(
        "x y z intensity time",
        "a per-point time after the intensity, converted to seconds by the time-unit rule; "
        "float32 keeps about 7 digits, so the time should be relative (from the sweep start), "
        "not an epoch stamp"),
    "xyzirt": _float32_layout(
        "x y z intensity ring time",
        "ROS velodyne PointXYZIRT written out flat with every field as float32"),
    "xyz": _float32_layout("x y z", "coordinates only; intensity reads as 0"),
}


@dataclass(eq=False)
class Cloud:
    """A LiDAR sweep with the per-point fields its file offers.

    Attributes
    ----------
    points : ndarray, shape (N, 4), float32
        ``x, y, z`` in metres and intensity (as stored; 0 when the file has none). Points with a
        NaN or infinite coordinate are left out; a NaN or infinite intensity reads as 0.
    ring : ndarray, shape (N,), int16, or None
        Laser (ring) index per point, 0..255 as the file numbers them; None without a ring field.
    time : ndarray, shape (N,), float64, or None
        Per-point time in seconds on the file's own clock; None without a time field.
    fields : dict
        ``intensity``, ``ring``, ``time``: the file field read for each (its own spelling) or
        None; ``time_unit``: the unit the time field was read in (``s``, ``ms``, ``us``,
        ``ns``) or None; ``format``: ``pcd``, ``ply``, ``npy`` or ``bin``; ``layout``: the
        :data:`BIN_LAYOUTS` name used (``.bin`` and plain ``.npy`` with a declared layout) or
        None; ``warnings``: list of str, things the caller should tell the user once per source
        (a missing intensity field, a time unit that had to be guessed).
    """

    points: np.ndarray
    ring: np.ndarray | None
    time: np.ndarray | None
    fields: dict


def read_points(path: Path, bin_layout: str | None = None) -> np.ndarray:
    """Read a LiDAR sweep as an (N, 4) float32 array ``x, y, z, intensity``.

    The ``points`` of :func:`read_cloud` (see there for formats, field names and errors).
    """
    return read_cloud(path, bin_layout).points


def read_cloud(path: Path, bin_layout: str | None = None) -> Cloud:
    """Read a LiDAR sweep with its intensity, ring and time fields when the file has them.

    Parameters
    ----------
    path : path
        A ``.pcd``, ``.ply``, ``.npy`` or ``.bin`` file (chosen by suffix, case-insensitive).
        ``.pcd``/``.ply`` need fields ``x``, ``y``, ``z``; other fields are matched by the names
        in the module docstring. ``.npy`` holds a record array with named fields (any shape; an
        organised H x W cloud is flattened row by row) or a plain N x 3 / N x 4 array ``x, y,
        z[, intensity]`` (wider plain arrays need ``bin_layout``).
    bin_layout : str, optional
        A :data:`BIN_LAYOUTS` name: the record of ``.bin`` files, and the columns of a plain
        ``.npy`` array with as many columns. Without it a ``.bin`` file is read as ``kitti``
        when its size and data fit that layout. Ignored (with a note in ``fields["warnings"]``)
        for files that name their fields.

    Returns
    -------
    Cloud
        The points, ring (int16) and time (float64 seconds) of the points with finite
        coordinates, and which file fields gave them.

    Raises
    ------
    InputError
        Naming the file and what is wrong: missing, unreadable, malformed or truncated data, no
        ``x``/``y``/``z``, empty, every point NaN, ring values that are not whole numbers
        0..255, NaN or infinite times, a ``.bin`` size that fits no layout or data that fits a
        layout other than the one assumed, an unknown ``bin_layout``.

    Notes
    -----
    Points with a NaN or infinite coordinate are dropped (with their ring and time) and the
    count is logged as a warning; the other notes are returned in ``fields["warnings"]``
    rather than logged, so that the caller can say them once per source.
    """
    path = Path(path)
    layout = _layout_name(path, bin_layout)
    require_file(path, "point cloud file")
    suffix = path.suffix.lower()
    notes: list[str] = []
    used: str | None
    try:
        require_size(path, MAX_CLOUD_BYTES, "point cloud file")
        if suffix == ".bin":
            cols, used = _read_bin(path, path.read_bytes(), layout)
        elif suffix == ".npy":
            cols, used = _read_npy(path, layout)
        elif suffix == ".pcd":
            cols, used = _read_pcd(path, path.read_bytes()), None
        elif suffix == ".ply":
            cols, used = _read_ply(path, path.read_bytes()), None
        else:
            raise InputError(f"{path}: unsupported point cloud format {suffix!r} "
                             f"(supported: {', '.join(POINT_SUFFIXES)})")
    except InputError:
        raise
    except OSError as exc:
        raise InputError(f"{path}: cannot read point cloud ({exc.strerror or exc})") from None
    except ValueError as exc:
        raise InputError(f"{path}: cannot read point cloud ({first_line(exc)})") from None
    if layout is not None and used is None:
        notes.append(f"layout {layout!r} ignored: it applies to .bin files and plain .npy "
                     f"arrays, and this {suffix} file names its fields")
    return _assemble(path, cols, suffix[1:], used, notes)


def _layout_name(path: Path, name) -> str | None:
    """``name`` checked against :data:`BIN_LAYOUTS` (case-insensitive), or None."""
    if name is None:
        return None
    key = name.strip().lower() if isinstance(name, str) else None
    if key not in BIN_LAYOUTS:
        raise InputError(f"{path}: unknown point layout {quote(name)} (known: "
                         f"{', '.join(BIN_LAYOUTS)})")
    return key


def _assemble(path: Path, cols: dict[str, np.ndarray], fmt: str, layout: str | None,
              notes: list[str]) -> Cloud:
    """The cloud of named columns: pick the fields, drop non-finite points, check ring and time.

    ``cols`` maps the file's field names to equally long 1-D arrays in the file's types.
    """
    by_name: dict[str, tuple[str, np.ndarray]] = {}
    for name, col in cols.items():
        by_name.setdefault(name.lower(), (name, col))
    missing = [c for c in "xyz" if c not in by_name]
    if missing:
        raise InputError(f"{path}: no {', '.join(repr(c) for c in missing)} field "
                         f"(fields: {key_list(cols)}); x, y and z are required")

    def pick(aliases: tuple[str, ...]) -> tuple[str | None, np.ndarray | None]:
        return next((by_name[a] for a in aliases if a in by_name), (None, None))

    i_name, inten = pick(INTENSITY_FIELDS)
    r_name, ring = pick(RING_FIELDS)
    t_name, time = pick(TIME_FIELDS)
    n = len(by_name["x"][1])
    pts = np.zeros((n, 4), dtype=np.float32)
    with np.errstate(over="ignore", invalid="ignore"):   # doubles out of float32 range -> inf
        for j, c in enumerate("xyz"):
            pts[:, j] = by_name[c][1]
        if inten is not None:
            pts[:, 3] = inten
    if inten is None:
        notes.insert(0, f"no intensity field (looked for {', '.join(INTENSITY_FIELDS)}): "
                        "intensity reads as 0, so intensity edges are off")
    finite = np.isfinite(pts[:, :3]).all(axis=1)
    if len(pts) and not finite.any():
        raise InputError(f"{path}: all {len(pts)} points have NaN or infinite coordinates "
                         "(values beyond the float32 range count as infinite)")
    if not finite.all():
        log.warning("%s: dropped %d points with NaN or infinite coordinates",
                    path, int((~finite).sum()))
        pts = pts[finite]
        ring = None if ring is None else ring[finite]
        time = None if time is None else time[finite]
    pts[:, 3] = np.nan_to_num(pts[:, 3], nan=0.0, posinf=0.0, neginf=0.0)
    if len(pts) == 0:
        raise InputError(f"{path}: the point cloud is empty")
    unit = None
    if r_name is not None and ring is not None:         # a field is picked with its name
        ring = _ring_numbers(path, r_name, ring)
    if t_name is not None and time is not None:
        time, unit = _seconds(path, t_name, time, notes)
    fields = {"intensity": i_name, "ring": r_name, "time": t_name, "time_unit": unit,
              "format": fmt, "layout": layout, "warnings": notes}
    return Cloud(np.ascontiguousarray(pts), ring, time, fields)


def _num(v) -> str:
    """A number for a message: whole numbers without a decimal point."""
    v = v.item() if hasattr(v, "item") else v
    if isinstance(v, float) and v.is_integer() and abs(v) < 1e15:
        return str(int(v))
    return f"{v:.6g}" if isinstance(v, float) else str(v)


def _ring_numbers(path: Path, name: str, col: np.ndarray) -> np.ndarray:
    """The ring field as int16 after checking that it holds whole numbers 0..255."""
    if col.dtype.kind not in "iuf":
        raise InputError(f"{path}: field {quote(name)} has type {col.dtype}; ring numbers must be "
                         "whole numbers 0..255")
    if col.dtype.kind == "f":
        bad = ~np.isfinite(col)
        if bad.any():
            raise InputError(f"{path}: field {quote(name)} holds NaN or infinite values at "
                             f"{int(bad.sum())} of {len(col)} points; ring numbers must be whole "
                             "numbers 0..255")
    lo, hi = col.min(), col.max()
    if lo < 0 or hi > 255:
        raise InputError(f"{path}: field {quote(name)} holds values outside 0..255 "
                         f"(min {_num(lo)}, max {_num(hi)})")
    if col.dtype.kind == "f":
        frac = col != np.round(col)
        if frac.any():
            raise InputError(f"{path}: field {quote(name)} holds values that are not whole numbers "
                             f"(e.g. {_num(col[frac][0])}); ring numbers must be whole numbers "
                             "0..255")
    return col.astype(np.int16)


def _seconds(path: Path, name: str, col: np.ndarray,
             notes: list[str]) -> tuple[np.ndarray, str]:
    """The time field in float64 seconds and the unit chosen (module docstring: the rule)."""
    if col.dtype.kind not in "iuf":
        raise InputError(f"{path}: field {quote(name)} has type {col.dtype}; expected numbers")
    integer = col.dtype.kind in "iu"
    span: float
    if integer:
        span = int(col.max()) - int(col.min())            # exact, even for 64-bit epochs
    else:
        bad = ~np.isfinite(col)
        if bad.any():
            raise InputError(f"{path}: field {quote(name)} holds NaN or infinite times at "
                             f"{int(bad.sum())} of {len(col)} points")
        span = float(col.max()) - float(col.min())
    order = ("ns", "us", "ms", "s") if integer else ("s", "ms", "us", "ns")
    lo, hi = PLAUSIBLE_SWEEP_S
    unit = next((u for u in order if lo <= span / _TIME_UNITS[u] <= hi), None)
    kind = "integers" if integer else "floats"
    if unit is None:
        unit = order[0]
        if span == 0:
            notes.append(f"time field {quote(name)}: every point has the same time, so its unit "
                         f"cannot be told; read as {_UNIT_WORDS[unit]}")
        else:
            notes.append(f"time field {quote(name)}: its {kind} span {_num(span)} across the cloud, "
                         f"which is no plausible sweep duration ({lo * 1e3:g} ms .. {hi:g} s) "
                         f"in s, ms, us or ns; read as {_UNIT_WORDS[unit]} (a span of "
                         f"{span / _TIME_UNITS[unit]:.6g} s)")
    elif not integer and unit != "s":
        notes.append(f"time field {quote(name)}: its floats span {_num(span)} across the cloud, "
                     f"read as {_UNIT_WORDS[unit]} ({span / _TIME_UNITS[unit]:.3g} s)")
    t = col.astype(np.float64)
    if unit != "s":
        t /= _TIME_UNITS[unit]
    return t, unit


# --- .bin and .npy --------------------------------------------------------------------------------


def _read_bin(path: Path, raw: bytes, declared: str | None) -> tuple[dict[str, np.ndarray], str]:
    """The columns of a ``.bin`` file in the declared layout, or in ``kitti`` when it fits."""
    size = len(raw)
    if declared is not None:
        lay = BIN_LAYOUTS[declared]
        if size % lay.record_bytes:
            raise InputError(f"{path}: size {size} bytes is not a multiple of "
                             f"{lay.record_bytes} (layout {declared!r}: {lay.describe()}); the "
                             "file is truncated or not in that layout")
        name = declared
    else:
        name = "kitti"
        kitti = BIN_LAYOUTS[name]
        others = [k for k, lay in BIN_LAYOUTS.items()
                  if k != name and size and size % lay.record_bytes == 0]
        fits = [k for k in others if _fits_ring_layout(raw, BIN_LAYOUTS[k])]
        if size % kitti.record_bytes:
            base = (f"{path}: size {size} bytes is not a multiple of {kitti.record_bytes} "
                    "(float32 x, y, z, intensity); the file is truncated or not a KITTI .bin "
                    "sweep")
            if fits:
                raise InputError(f"{base}; its data fits layout {fits[0]!r} "
                                 f"({BIN_LAYOUTS[fits[0]].describe()}): declare it "
                                 f"({DECLARE_LAYOUT.format(fits[0])})")
            if others:
                listed = ", ".join(f"{k} ({BIN_LAYOUTS[k].describe()})" for k in others)
                raise InputError(f"{base}; its size fits layout{'s' * (len(others) > 1)} "
                                 f"{listed}: declare the one it is "
                                 f"({DECLARE_LAYOUT.format('NAME')})")
            tried = ", ".join(f"{k} {lay.record_bytes}" for k, lay in BIN_LAYOUTS.items())
            raise InputError(f"{base}, and fits no other layout (tried {tried} bytes per "
                             "point)")
        if fits:
            lay = BIN_LAYOUTS[fits[0]]
            raise InputError(f"{path}: the data does not look like KITTI's float32 x, y, z, "
                             f"intensity: it fits layout {fits[0]!r} ({lay.describe()}), every "
                             "record's ring being a whole number 0..255; declare it "
                             f"({DECLARE_LAYOUT.format(fits[0])}), or declare 'kitti' if the "
                             "file is KITTI's")
    _check_points(path, size // BIN_LAYOUTS[name].record_bytes, size, f"its size ({name} layout)")
    arr = np.frombuffer(raw, dtype=BIN_LAYOUTS[name].dtype)
    return {c: arr[c] for c, _ in BIN_LAYOUTS[name].columns}, name


def _check_points(path: Path, n: int, nbytes: int, source: str) -> None:
    """Refuse a cloud of more than :data:`MAX_CLOUD_POINTS` points or :data:`MAX_CLOUD_BYTES`
    bytes of data (``source`` says where the counts come from: the header, the size) before
    anything is allocated for it."""
    if n > MAX_CLOUD_POINTS:
        raise InputError(f"{path}: {n:,} points by {source}, more than the {MAX_CLOUD_POINTS:,} "
                         "a point cloud file may hold")
    if nbytes > MAX_CLOUD_BYTES:
        raise InputError(f"{path}: {nbytes:,} bytes of point data by {source}, more than the "
                         f"{mib(MAX_CLOUD_BYTES)} a point cloud file may hold")


def _fits_ring_layout(raw: bytes, lay: BinLayout) -> bool:
    """Whether ``raw`` reads as ``lay``, a layout with a ring column, better than as KITTI.

    True when every record's ring is a whole number 0..255 while the coordinates are mostly not
    whole numbers. Read with the wrong record length the ring column cycles through the other
    fields, coordinates among them, so a KITTI file never passes; coordinates that are whole
    numbers (synthetic or zeroed clouds) prove nothing either way, hence the second condition.
    """
    if "ring" not in [n for n, _ in lay.columns] or len(raw) % lay.record_bytes:
        return False
    arr = np.frombuffer(raw, dtype=lay.dtype)
    if len(arr) < _MIN_LAYOUT_EVIDENCE:
        return False
    ring = arr["ring"]
    if not (np.isfinite(ring).all() and (ring >= 0).all() and (ring <= 255).all()
            and (ring == np.round(ring)).all()):
        return False
    xyz = np.stack([arr[c] for c in "xyz"])
    finite = np.isfinite(xyz)
    whole = finite & (xyz == np.round(xyz))
    return bool(whole.sum() < 0.5 * finite.sum())


def _read_npy(path: Path, declared: str | None) -> tuple[dict[str, np.ndarray], str | None]:
    """The columns of a ``.npy`` file: a record array's fields or a plain array's columns."""
    arr = _load_npy(path)
    fields = arr.dtype.fields
    if arr.dtype.names and fields is not None:
        if arr.ndim == 0:
            raise InputError(f"{path}: the record array holds a single record, not a cloud")
        arr = arr.reshape(-1)
        wanted = ("x", "y", "z") + INTENSITY_FIELDS + RING_FIELDS + TIME_FIELDS
        cols = {}
        for name in arr.dtype.names or ():
            ft = fields[name][0]
            if ft.shape or ft.kind not in "iuf":
                if name.lower() in wanted:
                    raise InputError(f"{path}: field {quote(name)} has type {ft}; expected one real "
                                     "number per point")
                continue
            cols[name] = arr[name]
        return cols, None
    cols_n = arr.shape[1] if arr.ndim == 2 else None
    if declared is not None:
        lay = BIN_LAYOUTS[declared]
        if cols_n != len(lay.columns):
            raise InputError(f"{path}: layout {declared!r} has {len(lay.columns)} columns "
                             f"({', '.join(n for n, _ in lay.columns)}), the array has shape "
                             f"{arr.shape}")
        names = [n for n, _ in lay.columns]
    elif cols_n in (3, 4):
        names = ["x", "y", "z", "intensity"][:cols_n]
    else:
        hint = ""
        if cols_n is not None and cols_n > 4:
            same = [k for k, lay in BIN_LAYOUTS.items() if len(lay.columns) == cols_n]
            hint = ("; a wider array needs a declared layout"
                    + (f" ({', '.join(same)} have {cols_n} columns)" if same else "")
                    + " or named fields (a record array)")
        raise InputError(f"{path}: expected an N x 3 or N x 4 array, got shape {arr.shape}{hint}")
    if arr.dtype.kind not in "iuf":
        raise InputError(f"{path}: expected real numbers, got dtype {arr.dtype}")
    return {n: arr[:, j] for j, n in enumerate(names)}, declared


def _load_npy(path: Path) -> np.ndarray:
    """The array of a ``.npy`` file, read by the safe reader (:mod:`paretocal.io.arrays`),
    what its header claims checked before numpy allocates it: the points (records, or rows of
    a plain array) within :data:`MAX_CLOUD_POINTS`, and the data within the file (a header
    saying (10**12, 4) must not make numpy reserve 29 TiB)."""
    with open(path, "rb") as fh:
        shape, fortran, dtype = npy_header(fh, str(path))
        have = os.fstat(fh.fileno()).st_size - fh.tell()
        if not dtype.hasobject:                 # refused by npy_data, naming what it holds
            count = math.prod(shape)
            rows = count if dtype.names or len(shape) < 2 else count // max(shape[-1], 1)
            _check_points(path, rows, count * dtype.itemsize,
                          f"its header (shape {shape}, {dtype})")
        return npy_data(fh, str(path), shape, fortran, dtype, have)


def _loadtxt(body: bytes, **kw) -> np.ndarray:
    """Whitespace-separated numbers as a 2-D float64 table; (0, 0) for no data.

    numpy warns (UserWarning) on empty input: here that is an error the caller reports by
    comparing the table's shape with the header, so the warning is silenced.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return np.loadtxt(io.BytesIO(body), dtype=np.float64, ndmin=2, comments=None, **kw)


def _ascii_column(col: np.ndarray, dtype: str) -> np.ndarray:
    """A float64 column of an ascii table back in its declared type.

    Integer fields become integers again, so that the time-unit rule sees their type (64-bit
    values beyond 2**53 keep float64's rounding, below what float64 seconds resolve anyway). A
    column that does not hold whole numbers in the type's range stays float64, for the ring
    and time checks to name.
    """
    target = np.dtype(dtype)
    if target.kind not in "iu" or len(col) == 0:
        return col
    info = np.iinfo(target)
    if not (np.isfinite(col).all() and (col == np.round(col)).all()
            and info.min <= col.min() and col.max() <= info.max):
        return col
    return col.astype(target)



# --- PCD (PCL) -----------------------------------------------------------------------------------

_PCD_TYPES = {("F", 4): "f4", ("F", 8): "f8", ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4",
              ("U", 8): "u8", ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4", ("I", 8): "i8"}
_PCD_DATA = ("ascii", "binary", "binary_compressed")
#: Fields that must hold one value per point (COUNT 1) when present.
_SCALAR_FIELDS = ("x", "y", "z") + INTENSITY_FIELDS + RING_FIELDS + TIME_FIELDS
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
            start = quote(key) if is_name(key) else "a word that is no PCD keyword"
            raise InputError(f"{path}: not a PCD file: the header starts with {start} "
                             "instead of VERSION or FIELDS")
        entries[key.upper()] = values
        lines.append(line)
    return entries, pos


def _pcd_int(path: Path, entries: dict[str, list[str]], key: str) -> int:
    try:
        value = int(entries[key][0])
    except (KeyError, IndexError, ValueError):
        raise InputError(f"{path}: PCD header {key} must be a non-negative integer, got "
                         f"{excerpt(' '.join(entries.get(key, [])) or 'nothing')}") from None
    if value < 0:
        raise InputError(f"{path}: PCD header {key} must be a non-negative integer, got {value}")
    return value


def _read_pcd(path: Path, raw: bytes) -> dict[str, np.ndarray]:
    """The fields of a PCL point cloud file, in their declared types.

    binary_compressed data is decoded by :func:`_pcd_compressed`. Fields with COUNT > 1 and
    padding (``_``) are left out.
    """
    entries, offset = _pcd_header(path, raw)
    fields, types, sizes, counts = _pcd_fields(path, entries)
    n, data = _pcd_size(path, entries)
    _check_points(path, n, n * sum(s * c for s, c in zip(sizes, counts)), "its header")
    # One column per field and count; padding fields are named "_" and may repeat.
    names, formats = [], []
    for k, (name, t, s, c) in enumerate(zip(fields, types, sizes, counts)):
        for j in range(c):
            names.append(name if c == 1 and name != "_" else f"_{k}_{j}_{name}")
            formats.append(_PCD_TYPES[(t, s)])
    if len(set(names)) != len(names):
        raise InputError(f"{path}: PCD header FIELDS names a field twice ({excerpt(' '.join(fields))})")
    body = raw[offset:]
    if n == 0:
        return {name: np.zeros(0, f) for name, f in zip(names, formats) if name[0] != "_"}
    if data == "ascii":
        cols = _pcd_ascii(path, body, names, formats, n)
    elif data == "binary":
        dtype = np.dtype({"names": names, "formats": ["<" + f for f in formats]})
        need = n * dtype.itemsize
        if len(body) < need:
            raise InputError(f"{path}: PCD binary data is truncated: {len(body)} bytes for "
                             f"POINTS {n} of {dtype.itemsize} bytes ({need} bytes)")
        arr = np.frombuffer(body, dtype=dtype, count=n)
        cols = {name: arr[name] for name in names}
    else:
        cols = dict(zip(names, _pcd_compressed(path, body, types, sizes, counts, n)))
    return {k: v for k, v in cols.items() if not k.startswith("_")}


def _pcd_fields(path: Path, entries: dict) -> tuple[list[str], list[str], list[int], list[int]]:
    """FIELDS, TYPE (upper case), SIZE and COUNT of a PCD header, checked against each other
    and against the types this reader decodes."""
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
            raise InputError(f"{path}: PCD field {quote(name)} has unsupported TYPE {t} SIZE {s}")
        if c < 1:
            raise InputError(f"{path}: PCD field {quote(name)} has COUNT {c}")
    if sum(counts) > MAX_POINT_VALUES:
        raise InputError(f"{path}: PCD header COUNT sums to {sum(counts):,} values per point, "
                         f"more than the {MAX_POINT_VALUES:,} a point may hold")
    for name, c in zip(fields, counts):
        if name.lower() in _SCALAR_FIELDS and c != 1:
            raise InputError(f"{path}: PCD field {quote(name)} has COUNT {c}, expected 1")
    return fields, types, sizes, counts


def _pcd_size(path: Path, entries: dict) -> tuple[int, str]:
    """The number of points and the DATA kind of a PCD header."""
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
        raise InputError(f"{path}: PCD header DATA {quote(data)} is not one of {', '.join(_PCD_DATA)}")
    return n, data


def _pcd_ascii(path: Path, body: bytes, names: list[str], formats: list[str],
               n: int) -> dict[str, np.ndarray]:
    """Whitespace-separated values, one point per line (tolerant of tabs and trailing blanks)."""
    try:
        table = _loadtxt(body)
    except ValueError as exc:
        raise InputError(f"{path}: PCD ascii data cannot be parsed ({first_line(exc)})") from None
    if table.shape != (n, len(names)):
        raise InputError(f"{path}: PCD ascii data has {table.shape[0]} rows of "
                         f"{table.shape[1] if table.size else 0} values; the header says "
                         f"POINTS {n} of {len(names)} values (truncated or wrong header)")
    return {name: _ascii_column(table[:, j], f)
            for j, (name, f) in enumerate(zip(names, formats)) if name[0] != "_"}


def _pcd_compressed(path: Path, body: bytes, types: list[str], sizes: list[int],
                    counts: list[int], n: int) -> list[np.ndarray]:
    """Decode binary_compressed data: two size words, then LZF (python-neo-lzf, the codec
    PCL's files use) of the values field by field, each field's values point by point (PCL's
    layout: a field of COUNT c holds c values per point, together). One array per value
    column, in the header's order."""
    import lzf

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
    try:
        raw = lzf.decompress(body[8:8 + packed], unpacked)
    except Exception as exc:  # any decoder failure means a corrupt file
        raise InputError(f"{path}: PCD binary_compressed data cannot be decoded "
                         f"({first_line(exc)}); the file is truncated or corrupt") from None
    if raw is None or len(raw) != unpacked:
        raise InputError(f"{path}: PCD binary_compressed data cannot be decoded (it expands to "
                         f"{0 if raw is None else len(raw)} bytes, its size word says "
                         f"{unpacked}); the file is truncated or corrupt")
    out, offset = [], 0
    for t, s, c in zip(types, sizes, counts):
        values = np.frombuffer(raw, "<" + _PCD_TYPES[(t, s)], count=n * c,
                               offset=offset).reshape(n, c)
        out += [values[:, j] for j in range(c)]
        offset += n * s * c
    return out


# --- PLY ------------------------------------------------------------------------------------------

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2",
              "int16": "i2", "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4",
              "uint": "u4", "uint32": "u4", "float": "f4", "float32": "f4", "double": "f8",
              "float64": "f8"}
_PLY_FORMATS = {"ascii": "", "binary_little_endian": "<", "binary_big_endian": ">"}


def _read_ply(path: Path, raw: bytes) -> dict[str, np.ndarray]:
    """The properties of the ``vertex`` element of a PLY file, in their declared types."""
    if not re.match(rb"ply\r?\n", raw[:5]):
        raise InputError(f"{path}: not a PLY file (the first line is not 'ply')")
    end = re.search(rb"(^|\n)end_header[ \t]*\r?\n", raw[:1 << 20])
    if end is None:
        raise InputError(f"{path}: PLY header has no 'end_header' line")
    try:
        header = raw[:end.start()].decode("ascii").splitlines()[1:]
    except UnicodeDecodeError:
        raise InputError(f"{path}: PLY header is not text") from None
    fmt, elements = _ply_header(path, header)
    names = [e[0] for e in elements]
    if "vertex" not in names:
        raise InputError(f"{path}: PLY file has no 'vertex' element")
    iv = names.index("vertex")
    _, n, props = elements[iv]
    lists = [p for p, t in props if t is None]
    if lists:
        raise InputError(f"{path}: PLY vertex property {quote(lists[0])} is a list; points need "
                         "scalar properties")
    pnames = [p for p, _ in props]
    if len(set(pnames)) != len(pnames):
        raise InputError(f"{path}: PLY vertex element names a property twice")
    _check_points(path, n, n * sum(np.dtype(t).itemsize for _, t in props),
                  "its header (element vertex)")
    body = raw[end.end():]
    if fmt == "ascii":
        return _ply_ascii(path, body, elements, iv)
    endian = _PLY_FORMATS[fmt]
    start = 0
    for name, count, eprops in elements[:iv]:
        if any(t is None for _, t in eprops):
            raise InputError(f"{path}: PLY element {quote(name)} before 'vertex' has list "
                             "properties; binary files with that layout are not supported")
        start += count * sum(np.dtype(t).itemsize for _, t in eprops)
    dtype = np.dtype([(p, endian + t) for p, t in props])
    need = start + n * dtype.itemsize
    if len(body) < need:
        raise InputError(f"{path}: PLY binary data is truncated: {len(body)} bytes after the "
                         f"header, {need} needed for {n} vertices of {dtype.itemsize} bytes")
    arr = np.frombuffer(body, dtype=dtype, count=n, offset=start)
    return {p: arr[p] for p in pnames}


def _ply_header(path: Path, header: list[str]) -> tuple[str, list[list]]:
    """The format and the elements of a PLY header (its lines after ``ply``): each element as
    ``[name, count, [(property, numpy type), or (property, None) for a list]]``."""
    fmt = None
    elements: list[list] = []
    for line in header:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        try:
            if words[0] == "format":
                fmt = words[1]
                if fmt not in _PLY_FORMATS:
                    raise InputError(f"{path}: unsupported PLY format {quote(fmt)} (supported: "
                                     f"{', '.join(_PLY_FORMATS)})")
            elif words[0] == "element":
                elements.append([words[1], int(words[2]), []])
                if elements[-1][1] < 0:
                    raise ValueError
            elif words[0] == "property":
                elements[-1][2].append(_ply_property(path, words))
            else:
                raise ValueError
        except (IndexError, ValueError):
            raise InputError(f"{path}: malformed PLY header line {quote(line)}") from None
    if fmt is None:
        raise InputError(f"{path}: PLY header has no 'format' line")
    return fmt, elements


def _ply_property(path: Path, words: list[str]) -> tuple[str, str | None]:
    """``(name, numpy type)`` of a ``property`` line, ``(name, None)`` for a list property."""
    if words[1] == "list":
        return words[4], None
    if words[1] not in _PLY_TYPES:
        raise InputError(f"{path}: PLY property {quote(words[2])} has unknown type {quote(words[1])}")
    return words[2], _PLY_TYPES[words[1]]


def _ply_ascii(path: Path, body: bytes, elements: list[list], iv: int) -> dict[str, np.ndarray]:
    """The vertex columns of ascii PLY data: one line per element instance, the lines of the
    elements before the vertices skipped."""
    _, n, props = elements[iv]
    if n == 0:
        return {p: np.zeros(0, t) for p, t in props}
    skip = sum(e[1] for e in elements[:iv])
    lines = body.count(b"\n") + (not body.endswith(b"\n"))
    if skip + n > lines:
        # Checked first: numpy reserves max_rows rows before it parses any.
        raise InputError(f"{path}: PLY ascii data has {lines} lines; the header says {skip} "
                         f"before the {n} vertex lines (truncated or wrong header)")
    try:
        table = _loadtxt(body, skiprows=skip, max_rows=n)
    except ValueError as exc:
        raise InputError(f"{path}: PLY ascii vertex data cannot be parsed "
                         f"({first_line(exc)})") from None
    if table.shape != (n, len(props)):
        raise InputError(f"{path}: PLY ascii data has {table.shape[0]} vertex lines of "
                         f"{table.shape[1] if table.size else 0} values; the header says "
                         f"{n} of {len(props)} (truncated or wrong header)")
    return {p: _ascii_column(table[:, j], t) for j, (p, t) in enumerate(props)}
