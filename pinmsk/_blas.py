"""One BLAS thread for the command line, unless the user chose a thread count.

The commands solve many small linear-algebra problems (least squares of the muscle-path fits, the QPs
of static optimization, the contact fits), for which a threaded BLAS (OpenBLAS, MKL, OpenMP) spends
more on waking its threads than it gains, and on a busy machine several-fold more.  :func:`one_thread`
sets ``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS`` and ``MKL_NUM_THREADS`` to 1 when none of them is
set (read when BLAS is loaded: ``python -m pinmsk`` calls it before numpy is imported; subprocesses
inherit them), and limits a BLAS already loaded with ``threadpoolctl`` if it is installed.  This module
imports nothing heavy.
"""
from __future__ import annotations

import os
import sys

__all__ = ["THREAD_VARIABLES", "one_thread"]

#: The environment variables that set the BLAS / OpenMP thread counts.
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def one_thread() -> bool:
    """One BLAS thread unless one of :data:`THREAD_VARIABLES` is set; returns whether it limited them."""
    if any(os.environ.get(v) for v in THREAD_VARIABLES):
        return False
    for v in THREAD_VARIABLES:
        os.environ[v] = "1"
    if "numpy" in sys.modules:          # BLAS is loaded and has read the variables already
        try:
            from threadpoolctl import threadpool_limits
        except ImportError:
            return True
        threadpool_limits(limits=1)
    return True
