"""pinmsk: human musculoskeletal dynamics on Pinocchio.

    import pinmsk
    model = pinmsk.load_model("forearm")
    trial = pinmsk.read_trial("trial.csv")
    tau = pinmsk.inverse_dynamics(model, trial)

Public names are re-exported here; see the submodules for the rest.  They are
imported on first use (PEP 562), so ``import pinmsk`` and ``pinmsk --help``
do not pay for Pinocchio and SciPy until something needs them.
"""
from __future__ import annotations

from ._lazy import lazy_attributes
from .errors import ConvergenceError, InfeasibleError, ModelError, PinmskError, SolverError, TrialError

__version__ = "0.1.0"

#: Public name -> the submodule that defines it (imported when the name is first used).
_LAZY = {
    "Component": "components", "Motion": "components", "Parameter": "components",
    "Parameters": "components",
    "Data": "model", "Model": "model", "load_model": "model",
    "Trial": "trial",
    "read_trial": "io", "write_trial": "io",
    "ExternalForce": "skeleton",
    "component_forces": "dynamics", "inverse_dynamics": "dynamics", "simulate": "dynamics",
    "builtin_names": "builtin_models",
    "Fitter": "fitting", "FitStatistics": "fitting", "Result": "fitting",
}

__all__ = [
    "Component", "ConvergenceError", "Data", "ExternalForce", "FitStatistics", "Fitter", "InfeasibleError",
    "Model", "ModelError", "Motion", "Parameter", "Parameters", "PinmskError", "Result", "SolverError", "Trial",
    "TrialError", "builtin_names",
    "component_forces", "inverse_dynamics", "load_model", "read_trial", "simulate", "write_trial",
]


__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, __all__)
