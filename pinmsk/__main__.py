"""``python -m pinmsk`` is the ``pinmsk`` command."""
import sys

from .presentation.cli import main

sys.exit(main())
