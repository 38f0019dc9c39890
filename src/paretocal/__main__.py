"""``python -m paretocal`` and the ``paretocal`` console script.

Kept free of heavy imports, so that an interrupt while the command line loads (numpy, OpenCV,
numba take about a second) still ends with one line instead of a traceback.
"""

import os
import signal
import sys


def console() -> None:
    try:
        from .cli import main
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)      # a second Ctrl-C: no traceback
        sys.stderr.write("paretocal: interrupted while starting; nothing was written\n")
        sys.exit(130)
    # final: SIGINT and SIGTERM stay ignored after the command, so that a Ctrl-C while the
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
