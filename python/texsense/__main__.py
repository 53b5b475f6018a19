"""``python -m texsense``: the command line (the same as ``texsense``)."""

import sys

from texsense.cli import main

sys.exit(main())
