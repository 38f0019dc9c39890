"""Atomic file output: write to a temporary file in the same folder, then rename.

A reader never sees a half-written file, and an interrupted run leaves the previous version.
"""

from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager
from pathlib import Path


@contextmanager
def atomic_path(path: Path):
    """Yield a temporary path beside ``path``; on success it replaces ``path`` atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp" + path.suffix,
                               dir=path.parent)
    os.close(fd)
    # mkstemp creates 0600 files; give the result the permissions a plain open() would.
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())


def check_output_dir(path: Path, option: str = "--out") -> Path:
    """Fail before any work when ``path`` cannot become an output folder.

    Raises :class:`~paretocal.errors.SettingsError` naming ``option`` when ``path`` is a file,
    when a file stands where one of its parent folders should be, or when the nearest existing
    folder is not writable.
    """
    from ..errors import SettingsError

    path = Path(path)
    if path.exists() and not path.is_dir():
        raise SettingsError(f"{option} {path}: exists and is not a folder")
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise SettingsError(f"{option} {path}: {parent} is a file, not a folder")
            if not os.access(parent if not path.exists() else path, os.W_OK | os.X_OK):
                raise SettingsError(f"{option} {path}: no permission to write there")
            break
    return path
