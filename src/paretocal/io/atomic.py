"""Atomic file output: write to a temporary file in the same folder, then rename.

A reader never sees a half-written file, and an interrupted run leaves the previous version.
A write that fails for a reason the user can fix (a full disk, a quota, a read-only file
system, no permission) raises :class:`~paretocal.errors.InputError` naming the file.
"""

from __future__ import annotations

import errno
import os
import re
import tempfile
from contextlib import contextmanager
from pathlib import Path

from ..errors import InputError, SettingsError
from .paths import broken_link

#: Reasons a write fails that the user can fix: room on the disk or quota, a writable file
#: system or folder, a file or link where a folder is expected, a shorter name. Anything else
#: (an I/O error of the device, a bad descriptor) is left to surface as a bug.
USER_WRITE_ERRORS = frozenset(getattr(errno, name) for name in (
    "ENOSPC", "EDQUOT", "EFBIG", "EROFS", "EACCES", "EPERM", "EISDIR", "ENOTDIR", "ELOOP",
    "ENAMETOOLONG", "EEXIST") if hasattr(errno, name))


def write_error(path: Path, exc: OSError) -> InputError:
    """The one-line error for ``exc``, raised while writing ``path``."""
    why = os.strerror(exc.errno) if exc.errno else str(exc)
    return InputError(f"{path}: cannot write ({why})")


@contextmanager
def atomic_path(path: Path):
    """Yield a temporary path beside ``path``; on success it replaces ``path`` atomically.

    An :class:`OSError` of :data:`USER_WRITE_ERRORS` raised here or by the caller's writing
    becomes an :class:`~paretocal.errors.InputError` naming ``path`` (not the temporary file).
    """
    path = Path(path)
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp" + path.suffix,
                                   dir=path.parent)
        os.close(fd)
        # mkstemp creates 0600 files; give the result the permissions a plain open() would.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        yield Path(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        if exc.errno not in USER_WRITE_ERRORS:
            raise
        raise write_error(path, exc) from None
    finally:
        if tmp is not None and os.path.exists(tmp):
            os.unlink(tmp)


def temporary_pattern(path: Path) -> re.Pattern:
    """The names :func:`atomic_path` gives the temporaries of ``path``:
    ``.NAME.XXXXXXXX.tmpSUFFIX``, the X being :func:`tempfile.mkstemp`'s eight random
    letters, digits or underscores. A kill before the rename leaves one behind."""
    path = Path(path)
    return re.compile(re.escape(f".{path.name}.") + "[a-z0-9_]{8}"
                      + re.escape(".tmp" + path.suffix))


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())


def _check_parents(path: Path, option: str) -> None:
    """The nearest existing folder above ``path`` must be a writable folder."""
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise SettingsError(f"{option} {path}: {parent} is a file, not a folder")
            if not os.access(parent, os.W_OK | os.X_OK):
                raise SettingsError(f"{option} {path}: {_not_writable(parent)}")
            return


def _not_writable(folder: Path) -> str:
    """Why a folder ``os.access`` finds unwritable cannot be written: its file system is
    mounted read-only (EROFS, which no permission fixes) or there is no permission."""
    try:
        if os.statvfs(folder).f_flag & os.ST_RDONLY:
            return "read-only file system"
    except (OSError, AttributeError):            # AttributeError: no statvfs (Windows)
        pass
    return "no permission to write there"


def check_output_dir(path: Path, option: str = "--out") -> Path:
    """Fail before any work when ``path`` cannot become an output folder.

    Raises :class:`~paretocal.errors.SettingsError` naming ``option`` when ``path`` is a file,
    a symbolic link that leads nowhere (a loop, a missing target), when a file stands where
    one of its parent folders should be, or when ``path`` (or the nearest existing folder
    above it) is not writable.
    """
    path = Path(path)
    link = broken_link(path)
    if link:
        raise SettingsError(f"{option} {path}: {link}")
    if path.exists():
        if not path.is_dir():
            raise SettingsError(f"{option} {path}: exists and is not a folder")
        if not os.access(path, os.W_OK | os.X_OK):
            raise SettingsError(f"{option} {path}: {_not_writable(path)}")
        return path
    _check_parents(path, option)
    return path


def check_output_file(path: Path, option: str = "--out") -> Path:
    """Fail before any work when the file ``path`` cannot be written.

    Raises :class:`~paretocal.errors.SettingsError` naming ``option`` when ``path`` is a
    folder, a symbolic link that leads nowhere (a loop, a missing target: writing would
    replace the link, not create its target), or when the folder it goes into (or the nearest
    existing one above it) is a file or not writable. An existing file is replaced.
    """
    path = Path(path)
    link = broken_link(path)
    if link:
        raise SettingsError(f"{option} {path}: {link}")
    if path.is_dir():
        raise SettingsError(f"{option} {path}: is a directory (give the name of the file "
                            "to write)")
    _check_parents(path, option)
    return path


def check_own_folder(path: Path, marks: tuple[str, ...], what: str,
                     option: str = "--out", force: str = "add --force") -> None:
    """Refuse a folder ``path`` that is not empty and holds none of ``marks`` (names only a
    paretocal ``what`` folder holds): writing there would replace the user's files of the same
    names. Raises :class:`~paretocal.errors.SettingsError` naming ``option`` and how to write
    there all the same (``force``: the command line's ``--force``).
    """
    try:
        names = set(os.listdir(path))
    except (FileNotFoundError, NotADirectoryError):
        return
    except OSError as exc:
        raise SettingsError(f"{option} {path}: cannot list the folder ({exc.strerror})"
                            ) from None
    if names and not names & set(marks):
        raise SettingsError(f"{option} {path}: the folder is not empty and is not a paretocal "
                            f"{what} folder (none of {', '.join(marks)}); choose a new or "
                            f"empty folder, or {force} to write the {what} into it (its "
                            "files of the same names are replaced)")
