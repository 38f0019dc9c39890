"""``python -m paretocal`` and the ``paretocal`` console script.

The first thing this module does is take over SIGINT, SIGTERM and SIGHUP: until the command
line installs its own handlers (:func:`paretocal.cli.main`, once typer and click are imported,
some 0.1 s later), each ends the process at once with one line, exit status 130 (SIGINT), 143
(SIGTERM) or 129 (SIGHUP): nothing has been written yet. Nothing heavy is imported before, and
``paretocal/__init__.py``, which runs first, imports nothing.
"""

try:
    import _signal as signal    # what the signal module wraps, without its enums (3 ms of imports)
except ImportError:             # pragma: no cover - another Python implementation
    import signal

#: Exit status and word of each signal while the command line starts (128 + the signal).
_STARTING = {signal.SIGINT: (130, "interrupted"), signal.SIGTERM: (143, "terminated"),
             signal.SIGHUP: (129, "hung up")}


def _stop_while_starting(signum, frame):
    """One line, and exit: nothing to save or remove yet, so no exception is raised (it would
    unwind through the imports under way and print a traceback)."""
    import os

    status, words = _STARTING[signum]
    os.write(2, f"paretocal: {words} while starting; nothing was written\n".encode())
    os._exit(status)


# A signal ignored when the process started (nohup, a background job) stays ignored.
for _sig in _STARTING:
    if signal.getsignal(_sig) is not signal.SIG_IGN:
        signal.signal(_sig, _stop_while_starting)

import os  # noqa: E402 - after the handlers, on purpose
import sys  # noqa: E402


def console() -> None:
    from .cli import main

    # final: SIGINT, SIGTERM and SIGHUP stay ignored after the command, so that a Ctrl-C while the
    # interpreter shuts down (joining threads) prints no traceback; the run has said how it ended.
    status = main(final=True)
    if status == 130:
        # Interrupted: everything is saved (atomic files, the checkpoint fsynced). The
        # interpreter's own shutdown restores the default SIGINT action for the handlers it
        # installed, so a second Ctrl-C during it would kill the process (status -2) after
        # the line was printed: leave at once instead.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)
    sys.exit(status)


if __name__ == "__main__":
    console()
