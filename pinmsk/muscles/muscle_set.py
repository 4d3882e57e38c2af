"""The muscles of a model as one component.

A :class:`MuscleSet` joins a muscle-tendon model (``Thelen2003`` or
``NaganoGerritsen``, vectorised over muscles) with the muscles' paths
(lengths and moment arms as functions of the coordinates).  Muscle forces
``F`` (N, m) map to generalized forces by ``tau = R(q)^T F`` with ``R`` the
(N, m, nv) moment arms (thesis Eq. 3.14 in one dof).
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from ..components import Component, Motion
from ..errors import ModelError


class MuscleSet(Component):
    """All muscles of a model: parameters, paths, force capacity and joint moments."""

    family = "muscles"
    kind = "muscle"
    target_kind = "model"

    def __init__(self, *, names, model_type: str, mtu, path, tendon: str = "rigid",
                 volume=None, fast_fraction=None, display_points=None):
        super().__init__(None)
        self.names = tuple(names)
        if len(set(self.names)) != len(self.names):
            dup = sorted({n for n in self.names if self.names.count(n) > 1})
            raise ModelError(f"duplicate muscle names {dup}")
        self.model_type = model_type
        self.mtu = mtu
        self.path = path
        if tendon not in ("rigid", "compliant"):
            raise ModelError(f"muscle tendon must be 'rigid' or 'compliant', not {tendon!r}")
        self.tendon = tendon
        m = len(self.names)
        self.f_max = _per_muscle(mtu.f_max, m, "f_max", self.names)
        self.l_opt = _per_muscle(mtu.l_opt, m, "l_opt", self.names)
        self.l_slack = _per_muscle(mtu.l_slack, m, "l_slack", self.names)
        self.pennation = _per_muscle(mtu.pennation, m, "pennation", self.names)
        for arr, what in ((self.f_max, "f_max"), (self.l_opt, "l_opt"), (self.l_slack, "l_slack")):
            bad = np.flatnonzero(~(arr > 0))
            if bad.size:
                raise ModelError(f"muscle '{self.names[bad[0]]}': {what} = {arr[bad[0]]} must be > 0")
        sigma = 0.25e6  # Pa, specific tension (thesis Eq. B.3)
        self.volume = (self.f_max * self.l_opt / sigma if volume is None
                       else _per_muscle(volume, m, "volume", self.names))
        self.fast_fraction = (np.full(m, 0.5) if fast_fraction is None
                              else _per_muscle(fast_fraction, m, "fast_fraction", self.names))
        self.display_points = display_points or {}

    @property
    def n(self) -> int:
        return len(self.names)

    @property
    def pcsa(self) -> np.ndarray:
        """Physiological cross-sectional area, volume / optimal fibre length (m^2)."""
        return self.volume / self.l_opt

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            import difflib
            close = difflib.get_close_matches(name, self.names, n=3)
            hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
            raise ModelError(f"no muscle '{name}'{hint} (muscles: {', '.join(self.names)})") from None

    # -- paths --------------------------------------------------------------
    def lengths(self, q) -> np.ndarray:
        return self.path.lengths(q)

    def velocities(self, q, v) -> np.ndarray:
        return self.path.velocities(q, v)

    def moment_arms(self, q) -> np.ndarray:
        return self.path.moment_arms(q)

    # -- forces -------------------------------------------------------------
    def force_limits(self, q, v) -> tuple[np.ndarray, np.ndarray]:
        """Rigid-tendon force capacity ``(F_active, F_passive)``, each (N, m).

        Muscle force is ``F = a * F_active + F_passive`` with ``0 <= a <= 1``:
        ``F_active = F_max f_L f_V cos(alpha)`` at the current fibre length and
        velocity, ``F_passive`` the parallel element along the tendon (zero for
        models without one).
        """
        return self.mtu.force_limits(self.lengths(q), self.velocities(q, v))

    def joint_moments(self, q, forces) -> np.ndarray:
        """``tau = R(q)^T F`` over frames: (N, nv) from forces (N, m)."""
        R = self.moment_arms(q)
        F = np.asarray(forces, dtype=float)
        if F.ndim == 1:
            F = F[None, :]
        return np.einsum("nm,nmj->nj", F, R)

    def generalized_force(self, model, motion: Motion, params: Mapping[str, float] | None = None,
                          cache: Any = None) -> np.ndarray:
        """Joint moments of the forces in the motion's ``<muscle>_force`` signals."""
        F = np.column_stack([motion.signal(f"{n}_force") for n in self.names])
        return self.joint_moments(motion.q, F)

    def __repr__(self) -> str:
        return f"MuscleSet({self.model_type}, {self.n} muscles: {', '.join(self.names)})"


def _per_muscle(x, m: int, what: str, names) -> np.ndarray:
    arr = np.broadcast_to(np.asarray(x, dtype=float), (m,)).copy()
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise ModelError(f"muscle '{names[bad[0]]}': {what} is {arr[bad[0]]}; it must be finite")
    arr.flags.writeable = False
    return arr
