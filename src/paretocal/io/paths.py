"""What is wrong with a path that leads nowhere: a symbolic link loop or a dangling link, told
apart from a plain missing file so that messages say which."""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path


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
