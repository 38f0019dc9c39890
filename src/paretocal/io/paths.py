"""What is wrong with a path that leads nowhere: a symbolic link loop or a dangling link, told
apart from a plain missing file so that messages say which; and what stands at a path that
should be a plain file or folder (a run folder's own files are never followed through a link)."""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from ..errors import InputError


def broken_link(path: Path) -> str | None:
    """Why ``path`` cannot be followed because of a symbolic link, or None.

    Returns ``"symlink loop"`` when resolving ``path`` runs in a circle, ``"a symbolic link to
    TARGET, which does not exist"`` when it is a link whose target is missing (``... at
    FOLDER`` / ``FOLDER is ...`` when the link is a folder on the way), and None when ``path``
    resolves or is plainly absent.
    """
    path = Path(path)
    try:
        os.stat(path)
        return None
    except OSError as exc:
        if exc.errno not in (errno.ELOOP, errno.ENOENT, errno.ENOTDIR):
            return None
        loop = exc.errno == errno.ELOOP
    # The first component on the way that cannot be followed, from the root down.
    for p in (*reversed(path.parents), path):
        try:
            os.stat(p)
            continue
        except OSError as exc:
            failed = exc.errno
        if loop:
            if failed == errno.ELOOP:
                return "symlink loop" + ("" if p == path else f" at {p}")
            continue
        if not p.is_symlink():
            return None                        # plainly missing
        try:
            target = os.readlink(p)
        except OSError:
            target = "a missing target"
        what = f"a symbolic link to {target}, which does not exist"
        return what if p == path else f"{p} is {what}"
    return "symlink loop" if loop else None



#: What a stat mode is, in words, for messages.
_KINDS = ((stat.S_ISREG, "a regular file"), (stat.S_ISDIR, "a folder"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
          (stat.S_ISFIFO, "a named pipe (FIFO)"), (stat.S_ISSOCK, "a socket"))


def kind_of(path: Path) -> str | None:
    """What stands at ``path`` (links followed), in words: ``"a regular file"``, ``"a
    folder"``, ``"a character device"`` (``/dev/zero``), ``"a named pipe (FIFO)"``, ...; None
    when nothing can be reached there. Only the file's metadata is read, so a FIFO is never
    opened (which would wait for a writer)."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return None
    return next((words for test, words in _KINDS if test(mode)), "not a regular file")


def missing(path: Path, want: str = "a regular file") -> str:
    """Why ``path`` cannot be opened as ``want`` (``"a regular file"`` or ``"a folder"``), for
    a message: ``"is a character device, not a regular file"`` when something else stands
    there, else "not found", "not reachable: ..." when a symbolic link on the way leads
    nowhere (:func:`broken_link`), or "cannot be reached (...)" with the system's reason (a
    name too long, a folder on the way without permission)."""
    kind = kind_of(path)
    if kind is not None and kind != want:
        return f"is {kind}, not {want}"
    if "\0" in str(path):
        return "cannot be reached (the name holds a NUL character)"
    link = broken_link(path)
    if link:
        return f"not reachable: {link}"
    try:
        os.stat(path)
    except OSError as exc:
        if exc.errno not in (errno.ENOENT, errno.ENOTDIR):
            return f"cannot be reached ({exc.strerror})"    # a name too long, no permission
    return "not found"


def not_found(path: Path, what: str, want: str = "a regular file") -> str:
    """``"PATH: WHAT not found"``, or why a symbolic link on the way leads nowhere, or what
    stands there instead of ``want`` (:func:`missing`)."""
    return f"{path}: {what} {missing(path, want)}"


def odd_kind(path: Path, folder: bool = False) -> str | None:
    """What stands at ``path`` when it is not a plain file (``folder``: not a plain folder),
    without following a symbolic link there: ``"a symbolic link"``, ``"a directory"``, ``"a
    file"`` or ``"a special file"``; None when it is the expected kind or absent."""
    try:
        mode = os.lstat(path).st_mode
    except (FileNotFoundError, NotADirectoryError):
        return None
    if stat.S_ISLNK(mode):
        return "a symbolic link"
    if (stat.S_ISDIR if folder else stat.S_ISREG)(mode):
        return None
    return ("a directory" if stat.S_ISDIR(mode) else "a file" if stat.S_ISREG(mode)
            else "a special file")


def not_plain(path: Path, kind: str, what: str = "a plain file") -> InputError:
    """The one-line error for ``path``, which is ``kind`` (:func:`odd_kind`) instead of
    ``what``."""
    return InputError(f"{path}: is {kind}, not {what}; remove it (paretocal does not follow "
                      "or replace it)")


def open_plain(path: Path, what: str = "a plain file"):
    """``path`` opened for reading in binary, never through a symbolic link at its last
    component and never blocking on a FIFO. Raises FileNotFoundError when it is absent and
    :func:`not_plain`'s error (naming ``what`` it should be) when it is not a plain file."""
    flags = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        if exc.errno in (errno.ELOOP, errno.EISDIR, errno.ENXIO):
            raise not_plain(path, odd_kind(path) or "a special file", what) from None
        raise
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise not_plain(path, odd_kind(path) or "a special file", what)
    return os.fdopen(fd, "rb")


def require_file(path: Path, what: str) -> None:
    """Fail naming ``path`` when it is missing or not a regular file (a folder, a device, a
    FIFO: it is not opened, so a FIFO cannot block the reader)."""
    kind = kind_of(path)
    if kind == "a regular file":
        return
    if kind is not None:
        raise InputError(f"{path}: {what} expected, but this is {kind}")
    raise InputError(not_found(path, what))


def require_size(path: Path, limit: int, what: str) -> int:
    """The size of the regular file ``path`` in bytes; an :class:`InputError` when it is above
    ``limit`` (one of the limits at the top of this module), before anything is read."""
    size = path.stat().st_size
    if size > limit:
        raise InputError(f"{path}: {size:,} bytes, more than the {mib(limit)} a {what} may "
                         "hold")
    return size


def mib(nbytes: int) -> str:
    """A size limit in words: ``8 MiB``, ``2 GiB``."""
    return f"{nbytes / 2**30:g} GiB" if nbytes >= 2**30 else f"{nbytes / 2**20:g} MiB"
