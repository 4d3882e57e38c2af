"""Muscle-redundancy solvers (thesis Sec. 2.2, 3.4, 3.5).

- :class:`StaticOptimization` -- SO per frame (force or activation mode, P = 1, 2, 3, ..., min/max).
- :class:`ForwardStaticOptimization` (``FSO``) -- SO inside a forward simulation.
- :class:`ModifiedStaticOptimization` -- SO with activation dynamics between frames (MSO).
- :class:`ExtendedInverseDynamics` (``EID``) -- the whole trial as one sparse QP.
- :mod:`pinmsk.solvers.analytical` -- closed-form 1-dof solutions and the Fig. 3.13 motion.
- :mod:`pinmsk.solvers.qp` -- the shared proxsuite / batched layer.
"""
from . import analytical
from .eid import EID, ExtendedInverseDynamics
from .fso import FSO, ForwardStaticOptimization
from .mso import ModifiedStaticOptimization
from .static import SOProblem, StaticOptimization, build_problem

__all__ = ["StaticOptimization", "SOProblem", "build_problem", "ForwardStaticOptimization", "FSO",
           "ModifiedStaticOptimization", "ExtendedInverseDynamics", "EID", "analytical"]
