"""Exceptions raised by pinmsk.

Every error pinmsk raises on bad input derives from :class:`PinmskError`, a
``ValueError``, so scripts can catch one type.  Messages say what is wrong,
where (file, column, row, frame, dof) and what to do next.
"""


class PinmskError(ValueError):
    """Base class of all pinmsk input and solver errors."""


class ModelError(PinmskError):
    """A model file, sidecar, component or name is invalid."""


class TrialError(PinmskError):
    """Measurement data (a Trial or a file) is invalid for the requested use."""


class SolverError(PinmskError):
    """An optimisation or integration did not produce a valid answer."""


class InfeasibleError(SolverError):
    """The problem has no solution within its bounds (e.g. muscles too weak)."""


class ConvergenceError(SolverError):
    """An iterative solver stopped before meeting its tolerance."""


class OutputError(PinmskError, OSError):
    """An output file or folder cannot be written (missing folder, read-only place, full disk).

    Also an ``OSError``, so code that catches file-system errors still catches it.
    """


class MissingDependencyError(PinmskError, ImportError):
    """An optional dependency needed for this input is not installed (the message says how to)."""


class RepairWarning(UserWarning):
    """A lenient read (``read_trial(strict=False)``, ``--lenient``) repaired the file; the message says how."""


class ResidualWarning(UserWarning):
    """A floating base without external loads: its residuals carry the body weight."""
