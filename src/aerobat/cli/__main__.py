"""``python -m aerobat.cli``: the same as the ``aerobat`` command."""

import sys

from aerobat.cli import main

sys.exit(main())
