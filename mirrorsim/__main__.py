"""``python -m mirrorsim``: the same as the ``mirrorsim`` command."""

import sys

from mirrorsim.cli import main

sys.exit(main())
