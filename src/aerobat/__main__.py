"""``python -m aerobat``: the ``aerobat`` command."""

import sys

from aerobat.cli import main

if __name__ == "__main__":
    sys.exit(main())
