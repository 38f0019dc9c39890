"""One error family: everything a user can fix by changing input or options.

The CLI maps :class:`ParetocalError` (and subclasses) to exit status 2 with a single line on
stderr; anything else is a bug and exits 1.
"""

from __future__ import annotations

import re
from pathlib import Path

#: Characters of a file's content that one error message quotes at most: enough to recognise
#: a key, a value or the start of a line, too few to copy a file out through messages, which
#: reach terminals, logs and a batch's summary table.
EXCERPT_CHARS = 80
#: Characters of a path read from a file that a message shows: longer than the paths people
#: use (the system allows 4096; a folder of 20 levels of 50 characters is 1000).
PATH_CHARS = 1024
#: Characters of a whole message where it is stored or printed as one line (the command line's
#: error line, a batch entry's reason): two paths and some excerpts, with room to spare.
MESSAGE_CHARS = 4096
#: A name shown as it is in a list of keys or fields (:func:`key_list`): up to 40 letters,
#: digits, ``_ - . /`` and spaces. Anything else (a line of a text file read as a YAML key, a
#: password hash) is counted, not shown.
_NAME = re.compile(r"[\w.\-/ ]{1,40}")


def excerpt(text, limit: int = EXCERPT_CHARS) -> str:
    """``text`` (or ``str()`` of it) as one line of at most ``limit`` characters, for a message.

    Control and format characters (line breaks, tabs, terminal escape sequences, bidirectional
    overrides) are written as Python escapes (``\\n``, ``\\x1b``, ``\\u202e``), so that the
    message stays one line and cannot drive the terminal; longer text is cut and ends in
    ``...``.
    """
    text = text if isinstance(text, str) else str(text)
    head = text[:limit + 1]                     # escapes only lengthen: the rest is cut anyway
    safe = "".join(c if c.isprintable() else ascii(c)[1:-1] for c in head)
    if len(safe) > limit:
        safe = safe[:max(limit - 3, 0)] + "..."
    return safe


def quote(value, limit: int = EXCERPT_CHARS) -> str:
    """``repr(value)`` for a message, at most ``limit`` characters (:func:`excerpt`); long
    strings, lists and mappings are abbreviated before they are formatted, so a huge value
    costs no more than a short one."""
    import reprlib

    short = reprlib.Repr()
    short.maxstring = short.maxother = short.maxlong = limit
    short.maxlist = short.maxtuple = short.maxdict = short.maxset = 8
    return excerpt(short.repr(value), limit)


def first_line(exc: BaseException, limit: int = 2 * EXCERPT_CHARS) -> str:
    """The first line of a library's exception message (its type name when it has none), as
    an :func:`excerpt`: the library's words with, at most, a short piece of the file they
    quote."""
    text = str(exc).strip()
    return excerpt(text.splitlines()[0], limit) if text else type(exc).__name__


def is_name(value) -> bool:
    """Whether ``value`` is a plain name that a message may show as it is (``_NAME``)."""
    return isinstance(value, (str, int, float)) and bool(_NAME.fullmatch(str(value)))


def key_list(keys, limit: int = EXCERPT_CHARS) -> str:
    """The keys (or field or frame names) a file holds, for a message: comma-separated, at
    most about ``limit`` characters, ``and N more`` for the rest; keys that are not plain
    names (see ``_NAME``) are counted, not shown; ``none`` for no keys."""
    keys = list(keys)
    shown, size = [], 0
    for k in keys:
        name = str(k)
        if is_name(k) and size + len(name) <= limit:
            shown.append(name)
            size += len(name) + 2
    if not keys:
        return "none"
    if not shown:
        return f"{len(keys)} not shown (not plain names)"
    rest = len(keys) - len(shown)
    return ", ".join(shown) + (f" and {rest} more" if rest else "")


class ParetocalError(Exception):
    """Bad input or bad usage, with a message that names the file or option at fault."""


class InputError(ParetocalError):
    """A file is missing, unreadable or malformed."""


class SettingsError(ParetocalError):
    """An option or configuration value is out of range or inconsistent."""


class DegenerateSceneError(ParetocalError):
    """The frames hold too little information to calibrate (no edges, no points in view)."""


class Interrupted(Exception):
    """A run stopped on SIGINT (or SIGTERM turned into one) and says where.

    Not a :class:`ParetocalError`: nothing was wrong with the input. The CLI prints one line
    from it and exits 130.

    Attributes
    ----------
    phase : str
        What the run was doing, in words ("extracting features", "the search", ...).
    generation : int or None
        The last completed generation of the search, when the search had started.
    X, F : ndarray or None
        The best front known when it stopped, shapes (k, 7) and (k, 2): the search's
        non-dominated set once the search has run.
    checkpoint : path or None
        The saved search state a resume continues from, when there is one.
    run_dir : path or None
        The run folder to resume, set by a caller that runs several (a rig's cameras); None
        when it is the folder the command was given.
    """

    def __init__(self, phase: str, generation: int | None = None, X=None, F=None,
                 checkpoint=None):
        super().__init__(f"interrupted while {phase}")
        self.phase, self.generation = phase, generation
        self.X, self.F, self.checkpoint = X, F, checkpoint
        self.run_dir: Path | None = None


class StopRequest:
    """Whether the user asked the run to stop (SIGINT or SIGTERM), kept beside the
    ``KeyboardInterrupt`` the command line's handler raises.

    Library code may swallow that exception (a third-party module's guarded optional import
    turns it into a caught error and a warning), which would let a stopped run go on to the
    end. The run's phases and generations call :meth:`check`, so a stop is never lost: at the
    latest it takes effect at the next phase or generation.
    """

    def __init__(self):
        self.requested = False

    def request(self) -> None:
        """Record a stop (the signal handler, beside the KeyboardInterrupt it raises)."""
        self.requested = True

    def clear(self) -> None:
        """Forget the request: it was taken (the interrupt reached a handler), or a new
        command starts."""
        self.requested = False

    def check(self) -> None:
        """Raise ``KeyboardInterrupt`` when a stop was requested and not yet taken."""
        if self.requested:
            self.clear()
            raise KeyboardInterrupt


#: The process's stop request: set by the command line's signal handler, cleared when taken.
STOP = StopRequest()
