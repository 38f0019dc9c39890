"""One error family: everything a user can fix by changing input or options.

The CLI maps :class:`ParetocalError` (and subclasses) to exit status 2 with a single line on
stderr; anything else is a bug and exits 1.
"""

from __future__ import annotations


class ParetocalError(Exception):
    """Bad input or bad usage, with a message that names the file or option at fault."""


class InputError(ParetocalError):
    """A file is missing, unreadable or malformed."""


class SettingsError(ParetocalError):
    """An option or configuration value is out of range or inconsistent."""


class DegenerateSceneError(ParetocalError):
    """The frames hold too little information to calibrate (no edges, no points in view)."""
