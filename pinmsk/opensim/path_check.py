"""Exact (geometric) muscle paths of an imported OpenSim model at a trial's frames, and the check of its
polynomial surrogates against them: :func:`exact_path_kinematics`, :func:`check_surrogates`.

An ``.osim`` import keeps the geometric paths (:class:`pinmsk.opensim.paths.GeometricPaths`, OpenSim's
``GeometryPath`` algorithm) beside the polynomials its solvers evaluate.  The polynomials are fitted over
a coordinate range; away from the poses they were fitted at they can miss the exact paths by centimetres
on large models.  :func:`check_surrogates` measures that miss at the frames an analysis is about to use:
the largest length error and the largest moment-arm error, and which muscle (and coordinate) has it.
:data:`DEFAULT_TOLERANCE` (1 mm) is the error above which an analysis must not take the surrogates
unless asked; ``docs/paths.md`` describes the choice.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .muscle_import import geometric_paths

__all__ = ["DEFAULT_TOLERANCE", "SurrogateCheck", "ExactPaths", "exact_path_kinematics", "check_surrogates",
           "with_exact_paths", "choose_paths"]

#: largest surrogate error (m, of length or moment arm) an analysis accepts without being asked
DEFAULT_TOLERANCE = 1e-3


def _geometric_q(model, gp, q, signals=None):
    """Model coordinates (N, nq) -> the geometric paths' coordinates (N, c); OpenSim coordinates that only
    drive dependent joints are taken from ``signals`` (a mapping of name -> (N,)) when given, else 0."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    qg = np.zeros((q.shape[0], len(gp.coordinates)))
    for k, c in enumerate(gp.coordinates):
        if c in model.coordinates:
            qg[:, k] = q[:, model.coordinate_index(c)]
        elif signals is not None and c in signals:
            qg[:, k] = np.asarray(signals[c], dtype=float)
    return qg


def exact_path_kinematics(model, q, *, signals=None, gp=None):
    """Exact muscle-tendon lengths (N, m) and moment arms (N, m, nv) of ``model``'s muscles at model
    coordinates ``q`` (N, nq), vectorised over frames (one batch of body placements, every wrap solved
    for all frames at once), in the order of ``model.muscles.names``; moment arms only for the model's
    coordinates the geometric paths know (the rest 0).  ``gp`` defaults to the import's geometric paths;
    raises ``ValueError`` if the model has none."""
    gp = gp if gp is not None else geometric_paths(model.meta.get("import_report"))
    if gp is None:
        raise ValueError(f"model '{model.name}' has no geometric paths (not imported from an .osim)")
    names = tuple(model.muscles.names)
    rows = [gp.muscles.index(n) for n in names]
    cols = [c for c in gp.coordinates if c in model.coordinates]
    L, A = gp.lengths_and_moment_arms(_geometric_q(model, gp, q, signals), coordinates=cols)
    arms = np.zeros((L.shape[0], len(names), model.nv))
    for k, c in enumerate(cols):
        arms[:, :, model.coordinate_index(c)] = A[:, rows, k]
    return L[:, rows], arms


@dataclass(frozen=True)
class SurrogateCheck:
    """Largest error of the model's path surrogates against the exact paths at a trial's frames (m)."""

    length_error: float
    length_muscle: str
    moment_arm_error: float
    moment_arm_muscle: str
    moment_arm_coordinate: str
    frames: int

    @property
    def worst(self) -> float:
        return max(self.length_error, self.moment_arm_error)

    def line(self) -> str:
        """One header line: ``path surrogates vs exact paths at N frames: length <= x mm (muscle), moment arm
        <= y mm (muscle, coordinate)``."""
        return (f"path surrogates vs exact paths at {self.frames} frames: length <= "
                f"{1e3 * self.length_error:.3g} mm ({self.length_muscle}), moment arm <= "
                f"{1e3 * self.moment_arm_error:.3g} mm ({self.moment_arm_muscle}, {self.moment_arm_coordinate})")


def check_surrogates(model, q, *, signals=None, gp=None) -> SurrogateCheck:
    """Compare ``model.muscles`` (its surrogate paths) with the exact paths at frames ``q`` (N, nq)."""
    L, A = exact_path_kinematics(model, q, signals=signals, gp=gp)
    q = np.atleast_2d(np.asarray(q, dtype=float))
    Ls = np.asarray(model.muscles.lengths(q), dtype=float)
    As = np.asarray(model.muscles.moment_arms(q), dtype=float)
    el = np.abs(Ls - L)
    ea = np.abs(As - A)
    names = tuple(model.muscles.names)
    i = int(np.argmax(el.max(axis=0)))
    n, j, v = np.unravel_index(int(np.argmax(ea)), ea.shape)
    return SurrogateCheck(length_error=float(el.max()), length_muscle=names[i],
                          moment_arm_error=float(ea.max()), moment_arm_muscle=names[j],
                          moment_arm_coordinate=model.coordinates[v] if v < len(model.coordinates)
                          else str(v), frames=int(q.shape[0]))


class ExactPaths:
    """The exact paths of an imported model as a muscle set's path (numpy, frames in rows): ``lengths``,
    ``velocities``, ``moment_arms`` and ``lengths_and_moment_arms`` of model coordinates, from
    :func:`exact_path_kinematics`.  It has no CasADi form: optimal control refuses it by name."""

    def __init__(self, model, gp=None):
        self._model = model
        self._gp = gp if gp is not None else geometric_paths(model.meta.get("import_report"))
        if self._gp is None:
            raise ValueError(f"model '{model.name}' has no geometric paths (not imported from an .osim)")

    def __repr__(self):
        return f"ExactPaths({len(self._gp.muscles)} muscles)"

    def lengths_and_moment_arms(self, q):
        q = np.asarray(q, dtype=float)
        L, A = exact_path_kinematics(self._model, np.atleast_2d(q), gp=self._gp)
        return (L[0], A[0]) if q.ndim == 1 else (L, A)

    def lengths(self, q):
        return self.lengths_and_moment_arms(q)[0]

    def moment_arms(self, q):
        return self.lengths_and_moment_arms(q)[1]

    def velocities(self, q, v):
        """Lengthening velocities ``dl/dt = -R v`` (the paths' convention)."""
        R = np.atleast_3d(self.moment_arms(np.atleast_2d(q)))
        out = -np.einsum("nmj,nj->nm", R, np.atleast_2d(np.asarray(v, dtype=float)))
        return out[0] if np.asarray(q).ndim == 1 else out


def with_exact_paths(model):
    """``model`` with its muscles' paths replaced by :class:`ExactPaths` (parameters, bounds and what
    varies kept); a model without geometric paths comes back unchanged."""
    import copy
    if model.muscles is None or geometric_paths(model.meta.get("import_report")) is None:
        return model
    ms = copy.copy(model.muscles)
    object.__setattr__(ms, "path", ExactPaths(model))     # a copy: the original set is unchanged
    return model.with_muscles(ms)


def choose_paths(model, q, *, surrogate: bool = False, tolerance: float = DEFAULT_TOLERANCE,
                 exact_hint: str = "or use the exact paths (leave out --surrogate-paths)"):
    """The model an analysis runs on and the header line naming its paths.

    By default (``surrogate`` False) the exact paths of an imported model (:func:`with_exact_paths`).
    With ``surrogate`` the model's polynomial paths, checked against the exact ones at frames ``q``
    (:func:`check_surrogates`); a largest error above ``tolerance`` (m) raises
    :class:`pinmsk.errors.ModelError` naming the muscle.  A model without geometric paths keeps its own."""
    from ..errors import ModelError
    if model.muscles is None or geometric_paths(model.meta.get("import_report")) is None:
        return model, f"paths: the model's own ({type(getattr(model.muscles, 'path', None)).__name__})"
    if not surrogate:
        return with_exact_paths(model), "paths: exact (OpenSim's geometric path algorithm)"
    check = check_surrogates(model, q)
    if check.worst > tolerance:
        raise ModelError(f"{check.line()}: above the {1e3 * tolerance:.3g} mm path tolerance; fit the "
                         f"surrogates over this trial (pinmsk import --fit-over), raise --path-tolerance"
                         + (f", {exact_hint}" if exact_hint else ""))
    return model, check.line()
