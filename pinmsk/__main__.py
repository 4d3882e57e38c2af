"""``python -m pinmsk`` is the ``pinmsk`` command."""
import sys

from .cli import main

sys.exit(main())
