"""``python -m paretocal.cli``: the command line, as ``python -m paretocal`` runs it."""

import sys

from . import main


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
