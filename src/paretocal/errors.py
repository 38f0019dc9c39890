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
    """

    def __init__(self, phase: str, generation: int | None = None, X=None, F=None,
                 checkpoint=None):
        super().__init__(f"interrupted while {phase}")
        self.phase, self.generation = phase, generation
        self.X, self.F, self.checkpoint = X, F, checkpoint


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
