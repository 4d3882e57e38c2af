"""pinmsk: human musculoskeletal dynamics on Pinocchio.

    import pinmsk
    model = pinmsk.load_model("forearm")
    trial = pinmsk.read_trial("trial.csv")
    tau = pinmsk.inverse_dynamics(model, trial)

Public names are re-exported here; see the submodules for the rest.
"""
from .errors import (ConvergenceError, InfeasibleError, ModelError, PinmskError, SolverError,
                     TrialError)
from .components import Component, Motion, Parameter
from .model import Model, load_model
from .trial import Trial
from .io import read_trial, write_trial
from .skeleton import ExternalForce
from .dynamics import component_forces, inverse_dynamics, simulate
from .builtin_models import builtin_names

__version__ = "0.1.0"

__all__ = [
    "Component", "ConvergenceError", "ExternalForce", "InfeasibleError", "Model", "ModelError",
    "Motion", "Parameter", "PinmskError", "SolverError", "Trial", "TrialError", "builtin_names",
    "component_forces", "inverse_dynamics", "load_model", "read_trial", "simulate", "write_trial",
]
