"""``python -m paretocal`` and the ``paretocal`` console script.

Kept free of heavy imports, so that an interrupt while the command line loads (numpy, OpenCV,
numba take about a second) still ends with one line instead of a traceback.
"""

import signal
import sys


def console() -> None:
    try:
        from .cli import main
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)      # a second Ctrl-C: no traceback
        sys.stderr.write("paretocal: interrupted while starting; nothing was written\n")
        sys.exit(130)
    status = main()
    # A Ctrl-C while the interpreter shuts down (joining threads) would print a traceback
    # from the threading module; the run has already said how it ended.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    sys.exit(status)


if __name__ == "__main__":
    console()
