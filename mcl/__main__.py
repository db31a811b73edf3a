"""``python -m mcl`` is the ``mcl`` command."""

import sys

from mcl.cli import main

sys.exit(main())
