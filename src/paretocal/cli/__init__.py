"""Command line: a thin layer that parses options, calls the library and maps errors to exits.

Exit status: 0 success, 2 bad input or usage (one line on stderr naming the file or option),
1 anything unexpected, 130 interrupted; 3 ``calibrate --strict`` with a result judged
unreliable; 4 ``batch`` with at least one failed entry (the others are done and summary.csv
is written); 141 the work done but stdout's reader gone (``| head``).

The package holds one module per command (``calibrate``, with ``run`` and ``rig`` beside it,
``perturb``, ``check``, ``compare``, ``study``, ``depth``, ``extract``, ``batch``), each
registering its command on :data:`app` when imported; ``options`` declares the options several
commands share, ``_common`` the logging, the progress display and the line an interrupted
command ends with. This module holds the application and :func:`main`, which maps errors to
exit statuses.
"""

from __future__ import annotations

import logging
import sys
from typing import Annotated

import click
import typer

from ..errors import MESSAGE_CHARS, STOP, ParetocalError, excerpt
from ._common import STOP_HANDLER, STOP_SIGNALS, ReaderMayLeave, StageProgress, report


#: The application; each command's module registers its command on it (declared with its type
#: for the type checker, which reads those modules while this one is still being imported).
app: typer.Typer = typer.Typer(
    add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
    help="Targetless camera-LiDAR calibration as a Pareto search over accuracy and "
         "computational cost.")
log = logging.getLogger("paretocal")


def _version(value: bool) -> None:
    if value:
        from .. import __version__

        typer.echo(f"paretocal {__version__}")
        raise typer.Exit(0)


@app.callback()
def _main(version: Annotated[bool, typer.Option(
        "--version", callback=_version, is_eager=True,
        help="Print the version and exit.")] = False) -> None:
    """Targetless camera-LiDAR calibration as a Pareto search over accuracy and computational
    cost. Units: metres, degrees and milliseconds unless an option says otherwise."""


# The commands register on app as they are imported, in the order --help lists them.
from . import calibrate  # noqa: E402, F401
from . import perturb  # noqa: E402, F401
from . import check  # noqa: E402, F401
from . import compare  # noqa: E402, F401
from . import study  # noqa: E402, F401
from . import depth  # noqa: E402, F401
from . import extract  # noqa: E402, F401
from . import batch  # noqa: E402, F401
# Imported from paretocal.cli by the tests and benchmarks.
from .batch import BATCH_FAILED_EXIT  # noqa: E402
from .check import features_line  # noqa: E402
from .run import STRICT_EXIT, interrupted_line, verdict_line  # noqa: E402

__all__ = ["BATCH_FAILED_EXIT", "PIPE_EXIT", "STRICT_EXIT", "app", "interrupted_line", "log",
           "main", "verdict_line"]

#: Exit status of a command whose stdout's reader left before it finished (``paretocal ... |
#: head``): 128 + SIGPIPE, as a tool the pipe's signal stops has. Its work is done (its files
#: written) and its errors are said on stderr; a command that failed keeps its own status.
PIPE_EXIT = 141

#: The SIGINT, SIGTERM and SIGHUP handler that :func:`main` installs.
_STOP = STOP_HANDLER
#: Names the tests use from when the commands were one module.
_Progress = StageProgress
_features_line = features_line


#: The option parser's usage errors: click's, and those of the click that recent typer
#: releases carry inside (``typer.BadParameter`` and its kin derive from TyperException there).
_USAGE_ERRORS = tuple({click.ClickException,
                       getattr(typer.exceptions, "TyperException", click.ClickException)})


#: What an interrupted command leaves behind, when the command has not said it itself
#: (calibrate and batch say more once their work has started).
_INTERRUPTED = {
    "calibrate": "interrupted before the run started; nothing was written; run the same "
                 "command again",
    "check": "interrupted; nothing was written; run the same command again",
    "perturb": "interrupted; nothing was written; run the same command again",
    "depth": "interrupted; the depth maps already in --out are whole files, the others are "
             "missing; run the same command again",
    "study": "interrupted; the study is incomplete (no report.html); run the same command again",
    "extract": "interrupted; nothing was written to --out (the partial extraction was "
               "removed); run the same command again",
}


def _interrupted(command: str | None) -> int:
    if not _STOP.reported:
        default = "interrupted; run the command again"
        said = default if command is None else _INTERRUPTED.get(command, default)
        report(f"paretocal: {said}")
    return 130


def main(argv: list[str] | None = None, final: bool = False) -> int:
    """Entry point of the ``paretocal`` console script; returns the exit status.

    ``final``: the process exits right after (the console script): the stop signals are then
    left ignored instead of restored, so a late second Ctrl-C cannot interrupt the exit."""
    import signal
    import threading

    args = sys.argv[1:] if argv is None else list(argv)
    verbose = "--verbose" in args or "-v" in args
    name = next((a for a in args if not a.startswith("-")), None)
    _STOP.signals, _STOP.reported = 0, False
    STOP.clear()
    # SIGTERM and SIGHUP (the terminal closed) stop a run the way Ctrl-C does: checkpoint
    # kept, partial front written.
    main_thread = threading.current_thread() is threading.main_thread()
    # A signal ignored when the process started (a background job of a shell, nohup) stays
    # ignored, as Python itself does for SIGINT.
    previous = ({sig: signal.signal(sig, _STOP) for sig in STOP_SIGNALS
                 if signal.getsignal(sig) is not signal.SIG_IGN} if main_thread else {})
    unraisable, sys.unraisablehook = sys.unraisablehook, _quiet_stops(sys.unraisablehook)
    stdout = sys.stdout = ReaderMayLeave(sys.stdout)
    try:
        command = typer.main.get_command(app)
        _flags_take_no_value(command)
        rv = command.main(args=args, prog_name="paretocal", standalone_mode=False)
        # typer turns KeyboardInterrupt into exit status 130 itself.
        status = _interrupted(name) if rv == 130 else int(rv) if isinstance(rv, int) else 0
        return PIPE_EXIT if stdout.left and status == 0 else status
    except ParetocalError as exc:
        # One line, whatever the message holds (control characters escaped, length bounded).
        print(f"paretocal: error: {excerpt(exc, MESSAGE_CHARS)}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, typer.Abort, click.exceptions.Abort):
        return _interrupted(name)
    except (typer.Exit, click.exceptions.Exit) as exc:
        return _interrupted(name) if exc.exit_code == 130 else int(exc.exit_code)
    except _USAGE_ERRORS as exc:
        # A usage error from the option parser (unknown option, bad value, ...).
        text = exc.format_message() if hasattr(exc, "format_message") else str(exc)
        if text.strip():              # no command at all: the help was shown, nothing to add
            print(f"paretocal: error: {' '.join(text.split())}", file=sys.stderr)
        return 2
    except Exception as exc:  # noqa: BLE001 - the last line of defence
        if STOP.requested:
            # The user's stop, wrapped by code it interrupted (a compiled function's
            # dispatch turns it into SystemError): an interrupt, not an error.
            return _interrupted(name)
        if verbose:
            import traceback

            traceback.print_exc()
        print(f"paretocal: unexpected error: {type(exc).__name__}: "
              f"{excerpt(exc, MESSAGE_CHARS)} (rerun with --verbose for the traceback)",
              file=sys.stderr)
        return 1
    finally:
        sys.stdout = stdout.stream
        sys.unraisablehook = unraisable
        for sig, handler in previous.items():
            signal.signal(sig, signal.SIG_IGN if final else handler)


def _flags_take_no_value(command) -> None:
    """Clear the value placeholder of every flag of ``command`` and its subcommands, the help
    option's included: a flag takes no value, yet typer's help shows ``<bool>`` beside it
    (0.29). The help options are made here in the contexts the commands run in, so that they
    carry the application's names (``-h``, ``--help``)."""
    root = command.context_class(command, info_name="paretocal", **command.context_settings)
    subs = getattr(command, "commands", {})
    for cmd, ctx in [(command, root)] + [
            (c, c.context_class(c, info_name=n, parent=root, **c.context_settings))
            for n, c in subs.items()]:
        help_option = cmd.get_help_option(ctx)
        for param in [*cmd.params, *([help_option] if help_option is not None else [])]:
            if getattr(param, "is_flag", False):
                param.metavar = ""


def _quiet_stops(hook):
    """``sys.unraisablehook`` that stays silent about the stop signal's KeyboardInterrupt.

    Raised while Python runs a callback from C (numba's compiler cache is one), the exception
    cannot propagate and would be printed with a traceback; the stop itself is not lost
    (``errors.STOP``: the run stops at its next phase or generation)."""
    def quiet(unraisable):
        if not (isinstance(unraisable.exc_type, type)
                and issubclass(unraisable.exc_type, KeyboardInterrupt)):
            hook(unraisable)
    return quiet
