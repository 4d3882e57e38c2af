"""One thread for the linear algebra inside CasADi's IPOPT (its bundled OpenBLAS and OpenMP runtime).

IPOPT's KKT systems here have a few thousand rows; MUMPS and BLAS threads do not speed them up and
on a shared 2-core machine they contend (measured on forearm J4: 0.56 s wall with 0.38 s of system
time by default, 0.38 s with one thread).  The pip ``casadi`` wheel ships its own
``libcasadi-tp-openblas`` and ``libgomp``, which ``threadpoolctl`` does not see and which read their
thread counts when loaded; :func:`single_threaded` sets both to one thread through their C entry
points, once per process, without touching the environment or numpy's own BLAS.
"""
from __future__ import annotations

import ctypes
import glob
import os

_DONE = False


def single_threaded() -> None:
    global _DONE
    if _DONE:
        return
    _DONE = True
    import casadi
    here = os.path.dirname(casadi.__file__)
    for pattern, entry in (("libcasadi-tp-openblas.so*", "openblas_set_num_threads"),
                           ("libgomp*.so*", "omp_set_num_threads")):
        for path in sorted(glob.glob(os.path.join(here, pattern))):
            try:
                getattr(ctypes.CDLL(path), entry)(1)
                break
            except (OSError, AttributeError):   # another platform's layout: leave it as it is
                continue
