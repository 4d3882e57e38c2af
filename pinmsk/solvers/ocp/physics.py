"""The model at one collocation point: every component of a :class:`~pinmsk.model.Model`, as CasADi.

:class:`PointModel` turns the model's components into the quantities and
residuals of one collocation point, calling the *same* component code the
numpy analyses call (written once against :mod:`pinmsk.backend`):

- skeleton: :class:`~pinmsk.solvers.ocp.skeleton.SymbolicSkeleton` (Pinocchio's
  model, RNEA on CasADi, tested against ``pin.rnea`` and
  ``computeRNEADerivatives``); implicit dynamics, the residual
  ``rnea(q, v, qdd) - R(q)^T F - sum_k Q_k(q, v) - sum_c J_c^T f_c = 0``;
- muscles: the muscle set's paths (``lengths_at``, ``moment_arms_at``) and its
  muscle model (``rigid_force``; with a compliant tendon the implicit
  Hill-equilibrium residual of De Groote et al. 2016, ``implicit_residual``);
- activation dynamics (thesis Eq. A.2) with the model's activation component's
  time constants and its electromechanical delay (:func:`~pinmsk.effects.activation.excitation_path`);
- effects: ``generalized_force_at`` (passive moments Eq. 5.11, damping, springs, ...);
- contacts: ``wrench_at`` on their site frames' world kinematics;
- metabolic rate (:mod:`pinmsk.energy`, App. B) when a cost needs it.

Formulations (thesis Sec. 5.1) differ in which signal the controls represent:
``"ff"`` the excitations, ``"ifm"`` the muscle-tendon forces, ``"ift"`` the
joint torques of the driven coordinates; the others become point variables
tied by equality constraints, so with node-wise controls the three have the
same optimum, and with a global parametrization (Sec. 3.3) each restricts a
different signal to the basis.
"""
from __future__ import annotations

import numpy as np

from ...effects._base import SignalEffect
from ...effects.activation import excitation_path
from ...errors import ModelError

__all__ = ["PointModel", "FORMULATIONS"]

FORMULATIONS = ("ff", "ifm", "ift")


class PointModel:
    """One collocation point of ``model``: the state/control layout and :meth:`evaluate`.

    ``tendon``: ``"rigid"`` or ``"compliant"`` (implicit tendon-force state);
    ``formulation``: one of :data:`FORMULATIONS`; ``driven``: coordinates whose torque
    is the IFT signal (default those the muscles span); ``metabolic``: None or the
    smoothing width of the heat-rate model when a cost needs the metabolic rate;
    ``activation_smooth``: width of the tanh blend of the rise/fall switch of Eq. A.2.
    """

    def __init__(self, model, *, tendon: str = "rigid", formulation: str = "ff", driven=None,
                 metabolic: float | None = None, activation_smooth: float = 0.0):
        from .skeleton import SymbolicSkeleton
        if formulation not in FORMULATIONS:
            raise ModelError(f"unknown formulation '{formulation}'; valid: {', '.join(FORMULATIONS)}")
        if tendon not in ("rigid", "compliant"):
            raise ModelError(f"tendon must be 'rigid' or 'compliant', not {tendon!r}")
        self.model = model
        self.nv = model.nv
        if model.pin.nq != model.nv:
            raise ModelError(f"model '{model.name}' has joints with nq != nv (free-flyer or spherical); "
                             "the optimal-control engine takes 1-dof joints (a planar floating base "
                             "is three of them)")
        self.sk = SymbolicSkeleton(model)
        self.ms = model.muscles
        self.m = 0 if self.ms is None else self.ms.n
        self.tendon, self.formulation = tendon, formulation
        self.compliant = tendon == "compliant" and self.m > 0
        self.metabolic = metabolic
        self.activation_smooth = float(activation_smooth)
        if self.m == 0 and formulation != "ff":
            raise ModelError(f"formulation '{formulation}' needs muscles; model '{model.name}' has none")
        if self.m:
            path = excitation_path(model)
            self.tau_rise, self.tau_fall, self.delay = path.tau_rise, path.tau_fall, path.delay
            mtu = self.ms.mtu
            for meth in ("rigid_force", "implicit_residual"):
                if not hasattr(mtu, meth):
                    raise ModelError(f"muscle model {type(mtu).__name__} has no closed form the "
                                     "optimal-control engine can use")
        else:
            self.delay = np.zeros(0)
        from ...actuators import CoordinateActuator, IdealActuator
        self.effects, self.contacts, self.actuators = [], [], []
        for c in model.components:
            if isinstance(c, SignalEffect):
                continue               # read through excitation_path above
            if c in tuple(model.contacts):
                self.contacts.append(c)
            elif isinstance(c, CoordinateActuator):
                self.actuators.append(c)   # one control each, in [min_control, max_control]
            elif isinstance(c, IdealActuator):
                raise ModelError(f"{c.label}: the optimal-control engine drives CoordinateActuators; a "
                                 f"{type(c).__name__}'s direction depends on the pose and is not supported yet "
                                 "(remove it: model.without(label))")
            elif c is not self.ms:
                self.effects.append(c)
        self._act_cols = [model.coordinate_index(a.target) for a in self.actuators]
        if formulation == "ift":
            if driven is None:
                R = np.abs(self.ms.moment_arms(np.zeros((1, self.nv)))[0])
                driven = [model.coordinates[j] for j in range(self.nv) if R[:, j].max() > 0]
            self.driven = [model.coordinate_index(c) for c in driven]
        else:
            self.driven = []
        self.mass = float(sum(I.mass for I in model.pin.inertias))

    # -- layout ----------------------------------------------------------------------
    @property
    def n_signal(self) -> int:
        """Rows of the control signal: excitations (FF), forces (IFM) or driven torques (IFT)."""
        return {"ff": self.m, "ifm": self.m, "ift": len(self.driven)}[self.formulation]

    def layout(self) -> tuple[dict, dict]:
        """``(states, controls)``: name -> row indices of the point's state and control vectors."""
        nv, m = self.nv, self.m
        st = {"q": list(range(nv)), "v": list(range(nv, 2 * nv))}
        k = 2 * nv
        if m:
            st["a"] = list(range(k, k + m))
            k += m
            if self.compliant:
                st["f_t"] = list(range(k, k + m))
                k += m
        co = {"qdd": list(range(nv))}
        k = nv
        if self.compliant:
            co["df_t"] = list(range(k, k + m))
            k += m
        if m and self.formulation != "ff":
            co["e"] = list(range(k, k + m))       # excitations are point variables
            k += m
        if self.formulation == "ift":
            co["F"] = list(range(k, k + m))       # and so are the muscle forces
            k += m
        if self.actuators:
            co["act"] = list(range(k, k + len(self.actuators)))   # the actuators' controls
            k += len(self.actuators)
        return st, co

    # -- one point -------------------------------------------------------------------
    def evaluate(self, x, u, s, s_delayed, t):
        """Quantities (dict of SX) and residual rows at one point.

        ``x`` states, ``u`` point controls, ``s`` the signal, ``s_delayed`` the signal
        through the electromechanical delay (equal to ``s`` without one), ``t`` time.
        Returns ``(pt, residuals)``: ``residuals`` a list of ``(label, expr, scale)``
        equality rows (expr = 0), ``scale`` the nominal size the row is divided by.
        """
        import casadi as ca
        st, co = self.layout()
        rows = lambda vec, idx: vec[idx[0]: idx[-1] + 1] if idx else ca.SX.zeros(0)   # noqa: E731
        q, v = rows(x, st["q"]), rows(x, st["v"])
        qdd = rows(u, co["qdd"])
        pt = {"t": t, "q": q, "v": v, "qdd": qdd}
        res = []
        tau = ca.SX.zeros(self.nv)
        if self.m:
            a = rows(x, st["a"])
            ms, mtu = self.ms, self.ms.mtu
            l_mt = ca.vec(ms.lengths_at(q))
            R = ms.moment_arms_at(q)                          # (m, nv), r = -dl/dq
            R = ca.reshape(R, self.m, self.nv) if not isinstance(R, ca.SX) or R.shape != (self.m, self.nv) else R
            v_mt = -ca.mtimes(R, v)
            if self.formulation == "ff":
                e, e_act = s, s_delayed
            else:
                e = rows(u, co["e"])
                e_act = e if not np.any(self.delay > 0) else self._delayed_node_excitation(e, s_delayed)
            from ...muscles.activation import activation_rate
            adot = activation_rate(e_act, a, tau_rise=self.tau_rise, tau_fall=self.tau_fall,
                                   smooth=self.activation_smooth)
            if self.compliant:
                f_t, df_t = rows(x, st["f_t"]), rows(u, co["df_t"])
                F_muscle = mtu.f_max * f_t
                res.append(("Hill equilibrium", mtu.implicit_residual(a, f_t, df_t, l_mt, v_mt), 1.0))
                l_ce, v_ce, _ = mtu.fiber_from_tendon(f_t, df_t, l_mt, v_mt)
                pt.update(f_t=f_t, df_t=df_t)
            else:
                F_muscle = mtu.rigid_force(a, l_mt, v_mt)
                l_ce, v_ce, _ = mtu.fiber_rigid(l_mt, v_mt)
            if self.formulation == "ff":
                F = F_muscle
            elif self.formulation == "ifm":
                F = s
                res.append(("muscle force = signal", (F - F_muscle) / mtu.f_max, 1.0))
            else:
                F = rows(u, co["F"])
                res.append(("muscle force", (F - F_muscle) / mtu.f_max, 1.0))
            tau_m = ca.mtimes(R.T, F)
            if self.formulation == "ift":
                for k, j in enumerate(self.driven):
                    res.append((f"muscle moment = torque signal ({self.model.coordinates[j]})",
                                tau_m[j] - s[k], None))
            tau = tau + tau_m
            pt.update(a=a, e=e, e_act=e_act, F=F, l_mt=l_mt, v_mt=v_mt, l_ce=l_ce, v_ce=v_ce,
                      tau_muscles=tau_m)
            xdot_m = [adot]
            if self.compliant:
                xdot_m.append(df_t)
            if self.metabolic is not None:
                pt["metabolic_rate"] = self._metabolic(e_act, a, l_ce, v_ce)
        for c in self.effects:
            if hasattr(c, "generalized_force_on"):        # a force between two frames (a bushing)
                tau = tau + ca.vec(c.generalized_force_on(self.sk, q, v))
            else:
                tau = tau + ca.vec(c.generalized_force_at(self.model, q, v))
        if self.actuators:
            u_act = rows(u, co["act"])
            for k_, (a_, j) in enumerate(zip(self.actuators, self._act_cols)):
                tau[j] = tau[j] + a_.values["optimal_force"] * u_act[k_]
            pt["act"] = u_act
        grf = []
        for c in self.contacts:
            Rw, p = self.sk.frame_placement(c.target, q)
            vl, w = self.sk.frame_velocity(c.target, q, v)
            f, mom = c.wrench_at(p, Rw, vl, w)
            tau = tau + self.sk.world_wrench_torque(q, c.target, f, mom)
            grf.append(ca.vec(f))
        pt["contact_forces"] = ca.vertcat(*grf) if grf else ca.SX.zeros(0)
        id_res = self.sk.rnea(q, v, qdd) - tau
        res.insert(0, ("skeleton dynamics (inverse-dynamics residual)", id_res, None))
        xdot = ca.vertcat(v, qdd, *(xdot_m if self.m else []))
        return pt, res, xdot

    def _delayed_node_excitation(self, e, s_delayed):
        raise ModelError("an electromechanical delay with formulation 'ifm'/'ift' is not supported: the "
                         "delay acts on the excitations, which these formulations do not parametrize; "
                         "use formulation 'ff'")

    def _metabolic(self, u, a, l_ce, v_ce):
        """Umberger 2003 heat and work rates (W) per muscle (App. B.2), C1-smoothed switches."""
        from ... import energy
        mtu = self.ms.mtu
        ff = mtu.fiber_forces(a, l_ce, v_ce)
        w = float(self.metabolic)
        fast = self.ms.fast_fraction
        kw = dict(u=energy.smooth_clip(u, 0.0, 1.0, w), a=energy.smooth_clip(a, 0.0, 1.0, w), l_ce=l_ce,
                  v_ce=v_ce, f_ce=ff["f_active"], f_isom=ff["f_isom"], l_opt=mtu.l_opt, f_max=mtu.f_max,
                  fast_fraction=fast, smooth=w)
        return energy.umberger2003(**kw)["total"]
