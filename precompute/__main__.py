"""``python -m precompute`` entry point."""

import sys

from .commands.cli import main

sys.exit(main())
