"""``python -m mirrorsim``: the same as the ``mirrorsim`` command."""

import sys

from mirrorsim.cli.main import main

sys.exit(main())
