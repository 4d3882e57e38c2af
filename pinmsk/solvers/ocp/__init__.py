"""The optimal-control engine: CasADi + IPOPT direct collocation with exact derivatives (thesis Ch. 3, 5).

::

    from pinmsk.solvers import ocp
    target = ocp.Target("cycle", amplitude=1.6, period=1.9, offset=0.3)
    fit = ocp.Collocation(model, cost=ocp.Effort(3, weights="volume"),
                          constraints=[ocp.TrackingTolerance(target, 0.1), ocp.ExcitationBounds(0, 1)],
                          duration=1.9, intervals=50).fit()
    fit.result_.report()

- :mod:`.problem` -- :class:`Collocation` (transcription, NLP, IPOPT, result);
- :mod:`.physics` -- the model's components at one collocation point;
- :mod:`.skeleton` -- Pinocchio's RNEA on CasADi values (and the callback alternative);
- :mod:`.costs`, :mod:`.constraints`, :mod:`.controls`, :mod:`.target` -- the problem's parts;
- :mod:`.tasks` -- ``pinmsk optimize`` task files.

CasADi is needed only when a problem is solved (``pip install casadi``).
"""
from .constraints import (AverageSpeed, Bounds, Constraint, CoordinateBounds, ExcitationBounds, FinalState, InitialState,
                          Periodic,
                          Symmetric, TrackingTolerance)
from .controls import GlobalControls, NodeControls
from .costs import (ActuatorEffort, ContactTracking, ControlEffort, Cost, CostSum, Effort, FinalTime, MetabolicEnergy,
                    Smoothness, StateTracking, TrackCoordinates, TrackSignals)
from .problem import SCHEMES, Collocation
from .target import Target

__all__ = ["Collocation", "SCHEMES", "Target", "NodeControls", "GlobalControls",
           "Cost", "CostSum", "Effort", "ActuatorEffort", "MetabolicEnergy", "TrackCoordinates", "TrackSignals", "Smoothness", "FinalTime",
           "ControlEffort", "StateTracking", "ContactTracking",
           "Constraint", "TrackingTolerance", "ExcitationBounds", "CoordinateBounds", "InitialState", "FinalState", "Periodic",
           "Symmetric", "AverageSpeed", "Bounds"]
