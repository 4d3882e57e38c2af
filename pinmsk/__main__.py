"""``python -m pinmsk`` is the ``pinmsk`` command."""
import sys

from ._blas import one_thread

one_thread()        # before numpy loads BLAS (pinmsk/_blas.py)

from .presentation.cli import main  # noqa: E402

sys.exit(main())
