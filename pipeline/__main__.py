# PYTHON_ARGCOMPLETE_OK
"""``python -m meshphase``: the ``meshphase`` command (:func:`meshphase.cli.console_main`)."""

import sys

from .cli import console_main

if __name__ == "__main__":
    sys.exit(console_main())
