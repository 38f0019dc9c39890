"""What is wrong with a path that leads nowhere: a symbolic link loop or a dangling link, told
apart from a plain missing file so that messages say which."""

from __future__ import annotations

import errno
import os
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



def missing(path: Path) -> str:
    """Why ``path`` cannot be opened, for a message: "not found", or "not reachable: ..." when
    a symbolic link on the way leads nowhere (:func:`broken_link`)."""
    link = broken_link(path)
    return f"not reachable: {link}" if link else "not found"


def not_found(path: Path, what: str) -> str:
    """``"PATH: WHAT not found"``, or why a symbolic link on the way leads nowhere."""
    return f"{path}: {what} {missing(path)}"
