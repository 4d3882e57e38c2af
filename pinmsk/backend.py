"""The math backend: one namespace of elementwise functions, numpy or CasADi.

Each physical law in pinmsk (muscle curves, activation dynamics, heat rates,
contacts, effects, paths) is written once against this namespace, so that the
same code gives numbers over whole trials (numpy arrays) and the exact
derivatives of the optimal-control engine (CasADi ``SX``/``MX`` expressions,
differentiated by algorithmic differentiation).  A law picks its backend from
its inputs::

    xp = backend_of(l_norm, a)
    f = xp.exp(-(l_norm - 1.0) ** 2 / gamma)

``backend_of`` returns :data:`NUMPY` unless an argument is a CasADi value, so
numpy callers see no change.  CasADi is imported only when a CasADi value is
actually passed (it is an optional dependency of the optimizer).

What differs between the two is kept here, in one place:

- ``where(c, a, b)`` is ``np.where`` / ``casadi.if_else`` (both evaluate both
  branches, so a branch must be finite where it is not taken);
- ``maximum``/``minimum`` are ``np.maximum`` / ``casadi.fmax``;
- ``asarray`` converts numbers to float arrays under numpy and leaves CasADi
  values alone (``np.asarray`` of an ``SX`` would make an object array).
"""
from __future__ import annotations

import sys
import types

import numpy as np

__all__ = ["NUMPY", "backend_of", "casadi_backend", "is_symbolic"]


def _np_asarray(x):
    return np.asarray(x, dtype=float)


NUMPY = types.SimpleNamespace(
    name="numpy", symbolic=False,
    asarray=_np_asarray, exp=np.exp, expm1=np.expm1, log=np.log, log1p=np.log1p, sqrt=np.sqrt,
    tanh=np.tanh, sin=np.sin, cos=np.cos, tan=np.tan, arcsin=np.arcsin, arccos=np.arccos,
    arctan=np.arctan, arctan2=np.arctan2, arcsinh=np.arcsinh, sinh=np.sinh, cosh=np.cosh, abs=np.abs, sign=np.sign,
    maximum=np.maximum, minimum=np.minimum, clip=np.clip, where=np.where, square=np.square,
    power=np.power, erf=None,
)
"""The numpy backend (the default of every law)."""

_CASADI = None


def casadi_backend():
    """The CasADi backend (built on first use; needs ``pip install casadi``)."""
    global _CASADI
    if _CASADI is None:
        import casadi as ca

        def _clip(x, lo, hi):
            return ca.fmin(ca.fmax(x, lo), hi)

        def _where(c, a, b):
            return ca.if_else(c, a, b)

        def _expm1(x):
            return ca.exp(x) - 1.0

        def _log1p(x):
            return ca.log(1.0 + x)

        _CASADI = types.SimpleNamespace(
            name="casadi", symbolic=True,
            asarray=lambda x: x if isinstance(x, (ca.SX, ca.MX, ca.DM)) else _np_asarray(x),
            exp=ca.exp, expm1=_expm1, log=ca.log, log1p=_log1p, sqrt=ca.sqrt, tanh=ca.tanh,
            sin=ca.sin, cos=ca.cos, tan=ca.tan, arcsin=ca.asin, arccos=ca.acos, arctan=ca.atan,
            arctan2=ca.atan2, arcsinh=ca.asinh, sinh=ca.sinh, cosh=ca.cosh, abs=ca.fabs, sign=ca.sign,
            maximum=ca.fmax, minimum=ca.fmin, clip=_clip, where=_where, square=lambda x: x * x,
            power=lambda x, p: x ** p, erf=ca.erf,
        )
    return _CASADI


def is_symbolic(x) -> bool:
    """Whether ``x`` is a CasADi value (SX, MX or DM)."""
    ca = sys.modules.get("casadi")
    return ca is not None and isinstance(x, (ca.SX, ca.MX, ca.DM))


def backend_of(*xs):
    """:data:`NUMPY`, or the CasADi backend if any of ``xs`` is a CasADi value.

    CasADi is looked up in ``sys.modules`` only: if nothing imported it, no
    argument can be a CasADi value and numpy callers pay one dict lookup.
    """
    ca = sys.modules.get("casadi")
    if ca is not None:
        for x in xs:
            if isinstance(x, (ca.SX, ca.MX, ca.DM)):
                return casadi_backend()
    return NUMPY
