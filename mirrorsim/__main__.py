"""``python -m mirrorsim``: the same as the ``mirrorsim`` command."""

import sys

from mirrorsim.cli.entry import main

sys.exit(main())
