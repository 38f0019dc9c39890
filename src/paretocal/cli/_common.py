"""What the commands share besides their options: the logging setup, the progress display on
stderr, an error against the reference in one phrase, and the line that says how an
interrupted command ended (with the SIGINT, SIGTERM and SIGHUP handler that
:func:`paretocal.cli.main` installs)."""

from __future__ import annotations

import logging
import os
import signal
import sys
from typing import Any

from ..errors import STOP


def setup_logging(verbose: bool, quiet: bool) -> None:
    level = logging.INFO if verbose else logging.ERROR if quiet else logging.WARNING
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("paretocal: %(levelname)s: %(message)s"))
    root = logging.getLogger("paretocal")
    root.handlers[:] = [handler]
    root.setLevel(level)
    root.propagate = False


class StageProgress:
    """A command's progress on stderr: rich bars on a terminal; on anything else (a pipe, a log
    file, CI) one line per stage as it begins, with the time since the command started, so
    that a long run shows where it is; nothing with ``--quiet``.

    Called as ``progress(stage, done, total)``. The pipeline's phases without a count of
    their own (``paretocal.pipeline.PHASES``: loading, locating the LiDAR, ...) report
    ``(phase, 0, 1)`` and ``(phase, 1, 1)``: a line each, no bar."""

    LABELS = {"features": "features", "search": "NSGA-II generations", "polish": "polish"}
    #: What the line of a counted stage says, ``{total}`` its count.
    LINES = {"features": "extracting features ({total} frames)",
             "search": "searching ({total} NSGA-II generations)",
             "polish": "polishing the front",
             "check": "checking the extrinsic", "depth maps": "writing {total} depth maps",
             "frames": "writing the frames ({total} files)",
             "entries": "running {total} entries"}

    def __init__(self, quiet: bool, stream=None):
        self.stream = stream if stream is not None else sys.stderr
        self.mode = None if quiet else "bars" if self.stream.isatty() else "lines"
        self.bar = None
        self.tasks: dict[str, Any] = {}         # rich's task ids by stage
        self.stage: str | None = None

    def __enter__(self):
        import time

        self.t0 = time.perf_counter()
        if self.mode == "bars":
            from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                                       TimeElapsedColumn)
            self.bar = Progress(TextColumn("{task.description:<22}"), BarColumn(),
                                MofNCompleteColumn(), TimeElapsedColumn(), transient=False)
            self.bar.__enter__()
        return self

    def __call__(self, stage: str, done: int, total: int) -> None:
        if self.mode == "lines":
            self._line(stage, total)
        if self.bar is None or (stage not in self.LABELS and stage in _phases()):
            return
        if stage not in self.tasks:
            self.tasks[stage] = self.bar.add_task(self.LABELS.get(stage, stage), total=total)
        self.bar.update(self.tasks[stage], completed=done, total=total)

    def _line(self, stage: str, total: int) -> None:
        """One line when a new stage begins (a stage reports many times)."""
        import time

        if stage == self.stage:
            return
        self.stage = stage
        text = self.LINES.get(stage) or _phases().get(stage) or stage
        print(f"paretocal: {time.perf_counter() - self.t0:7.1f} s  {text.format(total=total)}",
              file=self.stream, flush=True)

    def __exit__(self, *exc):
        if self.bar is not None:
            self.bar.__exit__(*exc)


def _phases() -> dict:
    """The pipeline's phases and what the run does in each (``paretocal.pipeline.PHASES``)."""
    from ..pipeline import PHASES

    return PHASES


class ReaderMayLeave:
    """``sys.stdout`` for a command whose reader may go away (``paretocal ... | head``): a
    write or flush that meets a closed pipe (BrokenPipeError) is dropped, the rest of the
    output goes to /dev/null, and :attr:`left` says so. The command then finishes its work and
    its errors still reach stderr (option parsers stop at a closed stdout: click exits 1 and
    says nothing). Everything else is the wrapped stream's."""

    def __init__(self, stream):
        self.stream = stream
        self.left = False

    def write(self, text: str) -> int:
        if not self.left:
            try:
                return self.stream.write(text)
            except BrokenPipeError:
                self._gone()
        return len(text)

    def flush(self) -> None:
        if not self.left:
            try:
                self.stream.flush()
            except BrokenPipeError:
                self._gone()

    def _gone(self) -> None:
        """The reader left: what the stream still buffers goes to /dev/null when it is
        flushed (at exit), not into a second BrokenPipeError."""
        self.left = True
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self.stream.fileno())
            os.close(devnull)
        except (OSError, ValueError, AttributeError):
            pass                           # no descriptor (a test's capture): nothing to flush

    def __getattr__(self, name: str):
        return getattr(self.stream, name)


def fmt_err(e: dict | None) -> str:
    if not e:
        return "n/a"
    return f"{e['rotation_deg']:.3f} deg / {e['translation_cm']:.2f} cm"


class StopHandler:
    """SIGINT, SIGTERM and SIGHUP handler: the first signal raises KeyboardInterrupt (the run stops and
    saves what it has) and records the request (``errors.STOP``: should library code swallow
    the exception, the run stops at its next phase or generation); later signals only say so,
    so that saving is not cut short."""

    def __init__(self):
        self.signals = 0
        self.reported = False

    def __call__(self, signum, frame):
        self.signals += 1
        if self.signals == 1:
            STOP.request()
            raise KeyboardInterrupt
        import os

        os.write(2, b"paretocal: stopping, saving what the run has (kill -9 to abort at once)\n")


STOP_HANDLER = StopHandler()
#: The signals that stop a command as Ctrl-C does: SIGINT, SIGTERM and SIGHUP (the terminal
#: closed), where the system has them.
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP")
                     if hasattr(signal, name))


def report(line: str) -> None:
    """Print the one line that says how an interrupted command ended."""
    print(line, file=sys.stderr)
    STOP_HANDLER.reported = True
