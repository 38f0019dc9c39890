"""Reading NumPy ``.npy`` and ``.npz`` files without trusting their headers: the one reader of
a cloud's ``.npy`` (:mod:`paretocal.io.clouds`) and of a checkpoint's ``.npz``
(:mod:`paretocal.search.checkpoint`).

A header is text that numpy evaluates as a Python literal; what it claims is checked before
anything is allocated for it: its length (numpy's own bound), its form (a dictionary of a
dtype, an order and a tuple of sizes, however deeply a hostile file nests the expression), and
the bytes of data it declares against the bytes that follow. Arrays of Python objects (which
numpy would unpickle) are never loaded, nor are compressed archive members (a small file that
expands without bound).

Every failure raises :class:`~paretocal.errors.InputError` beginning with the ``where`` the
caller gives (the file, or the file and what it is).
"""

from __future__ import annotations

import ast
import math
import zipfile

import numpy as np

from ..errors import InputError, excerpt, first_line

#: Bytes of a ``.npy`` header: numpy's own readers refuse longer ones unless told to trust the
#: file (``max_header_size``); numpy writes a few hundred.
MAX_NPY_HEADER = 10_000
#: The ``.npy`` format versions numpy writes: the bytes of the header's length, its encoding.
_VERSIONS = {(1, 0): (2, "latin1"), (2, 0): (4, "latin1"), (3, 0): (4, "utf8")}


def npy_header(fh, where: str) -> tuple[tuple[int, ...], bool, np.dtype]:
    """``(shape, fortran_order, dtype)`` that the ``.npy`` header at the current position of
    the binary file object ``fh`` declares (format 1.0, 2.0 or 3.0); ``fh`` is left at the
    start of the data.

    Raises :class:`InputError` (``where: ...``) for no ``.npy`` header, another version, a
    header longer than :data:`MAX_NPY_HEADER`, or one that is not a dictionary of a dtype, an
    order and a tuple of sizes (an expression nested too deeply to evaluate included).
    """
    magic = fh.read(8)
    if magic[:6] != b"\x93NUMPY":
        raise InputError(f"{where}: not a NumPy .npy file (no .npy header)")
    version = (magic[6], magic[7]) if len(magic) == 8 else None
    if version not in _VERSIONS:
        got = "unknown" if version is None else f"{version[0]}.{version[1]}"
        raise InputError(f"{where}: .npy format version {got} is not one numpy writes "
                         "(1.0, 2.0 or 3.0)")
    width, encoding = _VERSIONS[version]
    size = int.from_bytes(fh.read(width), "little")
    if size > MAX_NPY_HEADER:
        raise InputError(f"{where}: a .npy header of {size:,} bytes, more than the "
                         f"{MAX_NPY_HEADER:,} numpy writes and reads")
    text = fh.read(size)
    if len(text) < size:
        raise InputError(f"{where}: unreadable .npy header (the file ends inside it)")
    try:
        header = ast.literal_eval(text.decode(encoding))
    except (RecursionError, MemoryError):
        # The parser's own limits (a shape of thousands of nested unary minuses); the header
        # is at most MAX_NPY_HEADER bytes, so nothing large was built.
        raise InputError(f"{where}: unreadable .npy header (its shape is nested too deeply "
                         "to be read)") from None
    except (ValueError, SyntaxError, TypeError, UnicodeDecodeError) as exc:
        raise InputError(f"{where}: unreadable .npy header ({first_line(exc)})") from None
    if not isinstance(header, dict) or set(header) != {"descr", "fortran_order", "shape"}:
        raise InputError(f"{where}: unreadable .npy header (not a dictionary of descr, "
                         "fortran_order and shape)")
    shape, fortran = header["shape"], header["fortran_order"]
    if not (isinstance(shape, tuple) and all(type(n) is int and n >= 0 for n in shape)):
        raise InputError(f"{where}: unreadable .npy header (shape {excerpt(repr(shape))} is not "
                         "a tuple of sizes)")
    if not isinstance(fortran, bool):
        raise InputError(f"{where}: unreadable .npy header (fortran_order "
                         f"{excerpt(repr(fortran))} is not true or false)")
    try:
        dtype = np.lib.format.descr_to_dtype(header["descr"])
    except (ValueError, TypeError, KeyError, IndexError, RecursionError) as exc:
        raise InputError(f"{where}: unreadable .npy header (its descr is no dtype: "
                         f"{first_line(exc)})") from None
    return shape, fortran, dtype


def npy_data(fh, where: str, shape: tuple[int, ...], fortran: bool, dtype: np.dtype,
             available: int) -> np.ndarray:
    """The array of ``shape`` and ``dtype`` read from ``fh`` (after :func:`npy_header`),
    whose ``available`` bytes of data follow. Raises :class:`InputError` (``where: ...``) for
    an array of Python objects, or data shorter than the header says, before anything is
    allocated for it."""
    if dtype.hasobject:
        raise InputError(f"{where}: the array holds Python objects (dtype {dtype}), which "
                         "paretocal never loads (numpy would unpickle them)")
    count = math.prod(shape)
    need = count * dtype.itemsize
    if need > available:
        raise InputError(f"{where}: the .npy header says shape {shape} of {dtype} ({need:,} "
                         f"bytes), but {available:,} bytes of data follow; the file is "
                         "truncated or its header is wrong")
    data = bytearray(need)
    if fh.readinto(data) != need:
        raise InputError(f"{where}: the .npy data ends before the {need:,} bytes its header "
                         "says")
    return np.frombuffer(data, dtype=dtype, count=count).reshape(
        shape, order="F" if fortran else "C")


def load_npz(fh, where: str) -> dict[str, np.ndarray]:
    """Every array of the ``.npz`` archive ``fh`` (a binary file object), by name, each
    member read by :func:`npy_header` and :func:`npy_data` against the bytes the archive
    holds for it. Raises :class:`InputError` (``where, member NAME.npy: ...``) for a member
    that is compressed or not a ``.npy``, and as those do; ``zipfile.BadZipFile`` for a file
    that is no archive."""
    out = {}
    with zipfile.ZipFile(fh) as archive:
        for info in archive.infolist():
            member = f"{where}, member {excerpt(info.filename)}"
            if not info.filename.endswith(".npy"):
                raise InputError(f"{member}: not a .npy array")
            if info.compress_type != zipfile.ZIP_STORED:
                raise InputError(f"{member}: compressed; paretocal writes its .npz archives "
                                 "uncompressed")
            with archive.open(info) as stream:
                shape, fortran, dtype = npy_header(stream, member)
                available = info.file_size - stream.tell()
                out[info.filename[:-4]] = npy_data(stream, member, shape, fortran, dtype,
                                                   available)
    return out
