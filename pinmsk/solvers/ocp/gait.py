"""Predictive and tracking 2-D gait on ``gait2d`` (thesis Ch. 5), built on the collocation engine.

::

    from pinmsk.solvers.ocp import gait
    fit = gait.predictive_gait(speed=1.3).fit()          # a Collocation (problem, costs, constraints)
    stride, summary = gait.full_stride(fit)             # one stride, GRF channels r_ground_force_vy ...

The half gait cycle (thesis Sec. 5.2, as Moco's ``example2DWalking``):

- model: ``gait2d`` with its 16 muscles, Riener & Edrich passive moments (Eq. 5.11) and three
  hyper-volumetric contact spheres per foot (Table 4.4, :func:`~pinmsk.contact.foot.foot_contacts`),
  their penetration smoothed over ``contact_smoothing`` (m) so the force has usable gradients,
  and a passive spring and damper at each toe joint (:func:`with_toe_joints`, in the predictive
  problem);
  by default its muscles become De Groote 2016 units with a rigid tendon (same parameters) and
  IPOPT uses a limited-memory Hessian, the two changes that make the solve converge (Moco's and
  PredSim's choices; the reasons in :func:`predictive_gait` and :func:`_solver`);
- constraints: the end state is the start state mirrored left/right (Eq. 5.8), the unpaired
  coordinates and the forward speed periodic (Eq. 5.9), no knee hyper-extension (Eq. 5.10),
  a prescribed average speed (or free), and box bounds on every coordinate, speed, acceleration
  and tendon-force rate (what Moco and PredSim bound; they also set the variables' scales);
- cost: metabolic energy per distance and body mass (Umberger 2003, Eq. 5.6) plus a small
  effort term (mean squared activation);
- guess: walking-like (one sinusoid per joint and stride from the speed and duration only,
  :func:`walking_guess`; the default), standing (feet on the ground, pelvis moving forward at
  the target speed, low activations) or quasi-random (PredSim's habit: the same plus random
  joint-angle waves); solved coarse-to-fine (15 then 25 intervals, :class:`CoarseToFine`).
"""
from __future__ import annotations

import numpy as np

from ...errors import ModelError
from ...trial import Trial
from .constraints import AverageSpeed, Bounds, CoordinateBounds, Periodic, Symmetric, _mirror_name
from .costs import Effort, MetabolicEnergy, Smoothness, TrackSignals
from .problem import Collocation

__all__ = ["CoarseToFine", "with_toe_joints", "walking_guess", "stride_result", "build_gait_task", "gait_model", "standing_height", "standing_guess", "predictive_gait", "tracking_gait",
           "full_stride", "GAIT2D_PAIRS"]

#: right -> left coordinate pairs of gait2d
GAIT2D_PAIRS = {f"{j}_r": f"{j}_l" for j in ("hip", "knee", "ankle", "mtp")}
FORWARD, HEIGHT, TRUNK = "torso_x", "torso_y", "torso_angle"
G = 9.81


def gait_model(model="gait2d", *, contact: str = "hypervolumetric", contact_smoothing: float = 2e-3,
               muscle_model: str | None = None, tendon: str | None = None, friction_velocity: float | None = None,
               mtp_stiffness: float | None = None, mtp_damping: float = 0.0, contact_values=None):
    """``gait2d`` (or ``model``) with three contact spheres per foot (heel, metatarsal, toe).

    ``contact_smoothing``: the width (m) of the smooth positive part of the penetration; the
    thesis's 0.1 mm makes the contact force's derivative a step IPOPT cannot cross (the
    smoothed SmoothSphereHalfSpaceForce of Moco spreads it over about 3 mm).
    ``friction_velocity``: the transition velocity ``v_s`` (m/s) of every site's regularized
    Coulomb friction (None: the thesis's 5-50 mm/s, Table 4.4); ``contact_values``: per-site
    parameter overrides (:func:`~pinmsk.contact.foot.foot_contacts`).

    ``muscle_model``: None keeps the model's muscles; ``"degroote2016"`` rebuilds the same
    muscles (f_max, l_opt, l_slack, pennation, activation time constants, volumes, fast
    fractions, paths) as :class:`~pinmsk.muscles.models.DeGroote2016` units, as Moco and
    PredSim do for gradient-based optimal control: their curves are smooth everywhere,
    whereas gait2d's Nagano-Gerritsen force-velocity relation has a slope jump at v = 0 and
    the Winters tendon a zero stiffness at zero force (thesis App. A.4-A.5).
    ``tendon``: ``"rigid"`` / ``"compliant"`` sets the muscle set's tendon (None: keep).
    """
    from ...contact.foot import foot_contacts
    from ...contact.smooth_sphere import SmoothSphereHalfSpaceForce
    from ...model import load_model
    base = load_model(model) if isinstance(model, str) else model
    base = _convert_muscles(base, muscle_model, tendon)
    base = with_toe_joints(base, mtp_stiffness, mtp_damping)
    if tuple(base.contacts):
        return base
    out = base
    vals = {k: dict(v) for k, v in (contact_values or {}).items()}
    if friction_velocity is not None:
        for site in ("heel", "metatarsal", "toe"):
            vals.setdefault(site, {})["v_s"] = float(friction_velocity)
    if contact == "smooth_sphere":
        for side in ("r", "l"):
            for site, R in SMOOTH_SPHERE_RADII.items():
                p = dict(MOCO_SMOOTH_SPHERE, radius=R)
                if friction_velocity is not None:
                    p["transition_velocity"] = float(friction_velocity)
                p.update(vals.get(site, {}))
                out = out + SmoothSphereHalfSpaceForce(f"{site}_{side}", location=(0.0, p["radius"], 0.0), **p)
        return out
    for side in ("r", "l"):
        for c in foot_contacts(base, contact, side=side, smoothing=contact_smoothing, values=vals):
            out = out + c
    return out


def with_toe_joints(model, stiffness: float | None, damping: float = 0.0):
    """``model`` with a passive spring (``stiffness`` N m/rad about 0) and damper (``damping`` N m s/rad)
    at both toe joints (``mtp_r``, ``mtp_l``; :class:`~pinmsk.effects.spring.JointSpring`,
    :class:`~pinmsk.effects.damping.JointDamping`); None / a model without toes: unchanged.

    gait2d's toes carry no muscle and no passive moment of their own (Riener & Edrich's Eq. 5.11
    covers hip, knee and ankle): without one they rest on their joint limits in swing and the
    forefoot cannot push off through them (measured in :func:`predictive_gait`)."""
    if stiffness is None or "mtp_r" not in model.coordinates:
        return model
    from ...effects.damping import JointDamping
    from ...effects.spring import JointSpring
    for side in ("r", "l"):
        model = model.with_effect(JointSpring(f"mtp_{side}", k=float(stiffness), q0=0.0))
        if damping:
            model = model.with_effect(JointDamping(f"mtp_{side}", c=float(damping)))
    return model


#: Moco's 2D walking model's SmoothSphereHalfSpaceForce values (2D_gait.osim: contactHeel_r ...)
MOCO_SMOOTH_SPHERE = dict(stiffness=3067776.0, dissipation=2.0, static_friction=0.8, dynamic_friction=0.8,
                          viscous_friction=0.5, transition_velocity=0.2)
#: sphere radii (m) at gait2d's sole sites: Moco's heel (0.035) and front (0.015) spheres,
#: a metatarsal one between them
SMOOTH_SPHERE_RADII = {"heel": 0.035, "metatarsal": 0.025, "toe": 0.015}


def _convert_muscles(model, muscle_model, tendon):
    """``model`` with its muscles as ``muscle_model`` units and/or another tendon (see gait_model)."""
    ms = model.muscles
    if ms is None or (muscle_model is None and tendon is None):
        return model
    from ...muscles.muscle_set import MuscleSet
    tendon = ms.tendon if tendon is None else tendon
    mtu = ms.mtu
    if muscle_model is not None and muscle_model != ms.model_type:
        if muscle_model != "degroote2016":
            raise ModelError(f"gait_model: muscle_model must be None or 'degroote2016', not {muscle_model!r}")
        from ...muscles.models import DeGroote2016
        mtu = DeGroote2016(f_max=ms.f_max, l_opt=ms.l_opt, l_slack=ms.l_slack, pennation=ms.pennation,
                           names=ms.names, fast_fraction=ms.fast_fraction, volume=ms.volume,
                           tau_rise=float(mtu.tau_rise), tau_fall=float(mtu.tau_fall))
    new = MuscleSet(names=ms.names, model_type=mtu.model_type, mtu=mtu, path=ms.path, tendon=tendon,
                    display_points=dict(ms.display_points))
    return model.with_muscles(new)


def standing_height(model) -> float:
    """Pelvis height (m) at which the lowest foot site of the zero posture touches the ground."""
    import pinocchio as pin
    pm = model.pin
    d = pm.createData()
    pin.framesForwardKinematics(pm, d, np.zeros(pm.nq))
    ys = [d.oMf[model.frame_id(f"{s}_{side}")].translation[1]
          for s in ("heel", "metatarsal", "toe") for side in "rl"]
    return -float(min(ys))


def standing_guess(model, speed: float, duration: float, *, n: int = 21, sink: float = 0.005,
                   seed: int | None = None, amplitude: float = 0.2) -> Trial:
    """A generic guess: standing, the pelvis moving forward at ``speed``, ``sink`` (m) into the ground.

    ``seed``: quasi-random joint-angle waves (amplitude rad, one random phase per joint,
    one period over the half cycle) and random activations in 0.05-0.2 on top (PredSim).
    """
    t = np.linspace(0.0, duration, n)
    h0 = standing_height(model)
    ch = {FORWARD: speed * t, HEIGHT: np.full(n, h0 - sink), f"{FORWARD}_speed": np.full(n, speed)}
    if seed is not None:
        rng = np.random.default_rng(seed)
        w = 2 * np.pi / duration
        for c in model.coordinates:
            if c in (FORWARD, HEIGHT, TRUNK):
                continue
            ph = rng.uniform(0, 2 * np.pi)
            lo, hi = model.pin.lowerPositionLimit[model.coordinate_index(c)], \
                model.pin.upperPositionLimit[model.coordinate_index(c)]
            ch[c] = np.clip(amplitude * np.sin(w * t + ph), lo, hi)
            ch[f"{c}_speed"] = amplitude * w * np.cos(w * t + ph)
        for mu in model.muscle_names:
            ch[f"{mu}_activation"] = np.full(n, rng.uniform(0.05, 0.2))
    return Trial(t, ch)


def walking_guess(model, speed: float, duration: float, *, n: int = 21, sink: float = 0.005,
                  activation: float = 0.1) -> Trial:
    """A generic walking-like guess built from the speed and the half-cycle duration only.

    Not a tracking solution: every joint is one sinusoid per stride (phase ``p = t / (2 T)``,
    right heel strike at ``p = 0``), the left side the right shifted by half a stride:
    hip ``-A cos(2 pi p)`` with ``A = d / (2 L)`` the angle a step of length ``d = speed T``
    spans on a leg of length ``L`` (hip to ground when standing), knee ``0.5 (1 - cos(2 pi (p -
    0.72)))`` (straight in mid-stance, 1 rad in mid-swing), ankle ``0.1 cos(2 pi (p - 0.6))``;
    the pelvis moves forward at ``speed`` and at each node its height puts the lowest foot site
    ``sink`` (m) into the ground; activations ``activation``.
    """
    import pinocchio as pin
    t = np.linspace(0.0, duration, n)
    w = np.pi / duration                            # one stride = 2 half cycles
    h0 = standing_height(model)
    A = float(np.clip(speed * duration / (2 * h0), 0.05, 0.6))
    waves = {"hip": lambda p: -A * np.cos(2 * np.pi * p),
             "knee": lambda p: 0.5 * (1 - np.cos(2 * np.pi * (p - 0.72))),
             "ankle": lambda p: 0.1 * np.cos(2 * np.pi * (p - 0.6))}
    ch = {FORWARD: speed * t, f"{FORWARD}_speed": np.full(n, speed)}
    ph = {"r": t * w / (2 * np.pi), "l": t * w / (2 * np.pi) + 0.5}
    for j, f in waves.items():
        for side, p in ph.items():
            c = f"{j}_{side}"
            if c in model.coordinates:
                ch[c] = f(p)
                ch[f"{c}_speed"] = np.gradient(ch[c], t)
    # the pelvis height: the lowest sole site of each node's posture on the ground
    pm = model.pin
    d = pm.createData()
    sites = [model.frame_id(f"{s}_{side}") for s in ("heel", "metatarsal", "toe") for side in "rl"]
    y = np.empty(n)
    for k in range(n):
        q = np.zeros(pm.nq)
        for c in model.coordinates:
            if c in ch and c not in (FORWARD,):
                q[model.coordinate_index(c)] = ch[c][k]
        pin.framesForwardKinematics(pm, d, q)
        y[k] = -min(d.oMf[i].translation[1] for i in sites) - sink
    ch[HEIGHT] = y
    ch[f"{HEIGHT}_speed"] = np.gradient(y, t)
    for mu in model.muscle_names:
        ch[f"{mu}_activation"] = np.full(n, float(activation))
    return Trial(t, ch)


def gait_bounds(model, *, speed_max: float = 3.0, trunk=(-0.6, 0.6)) -> Bounds:
    """Box bounds of a walking half cycle (Moco's example2DWalking / PredSim ranges);
    ``trunk``: the range (rad) of the trunk's angle to the vertical (positive: leaning forward)."""
    h0 = standing_height(model)
    return Bounds(q={HEIGHT: (h0 - 0.25, h0 + 0.1), TRUNK: tuple(float(x) for x in trunk)},
                  v={FORWARD: (0.0, speed_max), HEIGHT: (-1.5, 1.5), TRUNK: (-3.0, 3.0)}, default_v=(-15.0, 15.0),
                  qdd={FORWARD: (-30.0, 30.0), HEIGHT: (-30.0, 30.0), TRUNK: (-100.0, 100.0)},
                  default_qdd=(-500.0, 500.0), df_t=(-20.0, 20.0))


def half_cycle_constraints(model, *, speed: float | None, knee_min: float = 0.0, trunk=(-0.6, 0.6)) -> list:
    """Eq. 5.8 (symmetry), Eq. 5.9 (periodicity of the rest, the forward speed included),
    Eq. 5.10 (no knee hyper-extension), the average speed, and the box bounds."""
    others = [c for c in model.coordinates if c != FORWARD]
    cons = [Symmetric(GAIT2D_PAIRS, exclude=(FORWARD,)), Periodic(("v",), exclude=others),
            CoordinateBounds("knee_r", knee_min, 2.5), CoordinateBounds("knee_l", knee_min, 2.5),
            gait_bounds(model, trunk=trunk)]
    if speed is not None:
        cons.append(AverageSpeed(float(speed), coordinate=FORWARD))
    return cons


def _solver(solver):
    """Moco's example2DWalking tolerances (1e-4) and its default quasi-Newton Hessian
    (MocoCasADiSolver's ``optim_hessian_approximation = "limited-memory"``).

    With the exact Hessian no gait2d half cycle converged: the Lagrangian's curvature from the
    contact and muscle terms is strongly indefinite away from a gait, IPOPT's inertia
    correction climbs to 1e7-1e10, the steps shrink to ~1e-3 and the dual infeasibility grows
    to 1e9-1e14 (whatever the muscles, contacts, guess or mu strategy).  The limited-memory
    BFGS approximation is positive definite by construction and converges in a few hundred
    iterations (see :func:`predictive_gait`)."""
    s = {"max_iter": 3000, "tol": 1e-4, "constraint_tol": 1e-4, "hessian": "limited-memory"}
    s.update(solver or {})
    return s


def stride_result(fit, *, mirror: bool = True):
    """``(Result, summary)``: a solved gait :class:`Collocation`'s result as one full stride
    (:func:`full_stride`: the half cycle mirrored, ``mirror=False`` keeps a tracked span as it is)
    with the fit's statistics, and the summary numbers (speed, stride length, cost of transport,
    body weight) that ``pinmsk optimize`` adds to ``OUT.sto.json``."""
    from ...fitting import Result
    half = fit.result_
    stride, summ = full_stride(half, model=fit.model, mirror=mirror)
    res = Result(stride.time, {n: stride[n] for n in stride.names}, stats=half.stats,
                 info=dict(half.info, horizon=float(stride.time[-1]),
                           # "duration" would hide the Result's own attribute
                           **{k: v for k, v in summ.items() if k != "duration"}))
    return res, {k: (None if v is None else float(v)) for k, v in summ.items()}


def predictive_gait(model=None, *, speed: float | None = 1.3, duration=0.55, intervals: int = 25,
                    coarse_intervals: int | None = 15,
                    scheme: str = "trapezoidal", effort_weight: float = 0.1,
                    smoothness_weight: float = 0.0, knee_min: float = 0.0, trunk=(-0.15, 0.15),
                    guess="walking", seed: int = 0, tendon: str | None = "rigid",
                    muscle_model: str | None = "degroote2016", contact: str = "hypervolumetric",
                    contact_smoothing: float = 2e-3,
                    friction_velocity: float | None = None, mtp_stiffness: float | None = 20.0,
                    mtp_damping: float = 0.5, sink: float = 0.005, foot_mass: float = 1.0, solver=None,
                    verbose=None) -> Collocation:
    """The predictive half gait cycle (thesis Sec. 5.2): a :class:`Collocation`, not yet solved.

    ``speed`` m/s (None: free); ``duration`` s or ``(lower, upper)`` (free); ``guess``:
    ``"walking"`` (:func:`walking_guess`), ``"standing"``, ``"quasi-random"`` (with ``seed``) or a
    Trial / Result (a warm start); ``trunk``: the trunk angle's range (rad, positive forward);
    ``coarse_intervals``: solve first on that many intervals and start the ``intervals`` problem
    from its solution (coarse-to-fine, :class:`CoarseToFine`; None: one solve);
    ``smoothness_weight``: weight of a mean squared acceleration term (``Smoothness("qdd",
    scale=10)``, 0 = none); ``foot_mass``: both feet's (``foot_r``, ``foot_l``) mass and inertia
    scaled by it (:meth:`~pinmsk.model.Model.with_segment_mass`; thesis Sec. 5.3 reruns at 0.67);
    ``mtp_stiffness`` (N m/rad), ``mtp_damping`` (N m s/rad): the toe joints' passive spring and
    damper (:func:`with_toe_joints`; None: none), left out of the coarse stage.

    Why the defaults (each compared with :func:`pinmsk.gait_validation.validate_gait`: the right joint
    angles against Winter's Table A.1, the GRF against the measured walk; the figures of each
    alternative are on the documentation's benchmarks page):

    - gait2d's 16 muscles as De Groote 2016 units with a rigid tendon and IPOPT with a
      limited-memory Hessian (:func:`_solver`): the only combination that converges (with the
      model's Nagano-Gerritsen muscles, a compliant tendon or the exact Hessian it does not);
    - ``trunk=(-0.15, 0.15)`` (+-9 deg): with a wider range every solution leans the trunk far
      forward, which hides in the hip angle (trunk to thigh); walking trunks lean 0-10 deg (PredSim
      and Moco's example2DWalking bound the pelvis tilt as tightly);
    - ``guess="walking"`` (:func:`walking_guess`, built from the speed alone): from standing the
      optimum is a shuffling gait or a costlier walk with more knee flexion;
    - ``coarse_intervals=15, intervals=25``: the 25-interval problem started from the 15-interval
      solution; other refinements of the same coarse solution can fall into another optimum, and
      a finer grid (50 intervals) gives the same knee and GRF, so the grid does not cause them;
    - ``mtp_stiffness=20, mtp_damping=0.5`` (:func:`with_toe_joints`), the coarse stage without
      them: gait2d's toes have no passive moment, and without one they hang on their -1 rad limit
      in swing and the forefoot cannot push through them (knee far from Winter's, swing flexion too
      small); with the springs in the coarse stage too, the 15-interval solve runs instead of
      walking; stiffer springs (50 N m/rad) do not converge;
    - not defaults: effort ``a^3`` with weight 1 runs; a free speed from the walking guess runs
      (from the 1.3 m/s optimum it settles near 1.3 m/s); a free duration runs to its lower bound;
      a smoothness term does not converge; a loose coarse tolerance saves nothing.
    """
    bare = gait_model("gait2d" if model is None else model, muscle_model=muscle_model, tendon=tendon,
                      contact=contact, contact_smoothing=contact_smoothing, friction_velocity=friction_velocity)
    if foot_mass != 1.0:
        for side in ("r", "l"):
            bare = bare.with_segment_mass(f"foot_{side}", foot_mass)
    model = with_toe_joints(bare, mtp_stiffness, mtp_damping)
    v0 = 1.3 if speed is None else float(speed)
    T0 = float(np.mean(duration)) if np.ndim(duration) else float(duration)
    if isinstance(guess, str):
        if guess not in ("standing", "quasi-random", "walking"):
            raise ModelError(f"guess must be 'walking', 'standing', 'quasi-random' or a Trial, not {guess!r}")
        guess = walking_guess(model, v0, T0, sink=sink) if guess == "walking" else standing_guess(model, v0, T0, sink=sink, seed=seed if guess == "quasi-random" else None)
    cost = MetabolicEnergy(per="distance", coordinate=FORWARD) + effort_weight * Effort(2)
    if smoothness_weight:
        cost = cost + smoothness_weight * Smoothness("qdd", scale=10.0)
    kw = dict(model=model, cost=cost, constraints=half_cycle_constraints(model, speed=speed, knee_min=knee_min,
                                                                          trunk=trunk),
              duration=duration, scheme=scheme, tendon=tendon, solver=_solver(solver), verbose=verbose)
    if not coarse_intervals or int(coarse_intervals) == int(intervals):      # None / 0: one solve
        return Collocation(intervals=intervals, guess=guess, **kw)
    # the coarse stage without the toe springs: with them it ran (CoT 5.4) from the walking guess
    return CoarseToFine(intervals=intervals, coarse_intervals=int(coarse_intervals), guess=guess,
                        coarse_model=bare if bare is not model else None, **kw)


class CoarseToFine(Collocation):
    """A :class:`Collocation` solved first on ``coarse_intervals`` intervals, whose solution (states,
    controls, activations, excitations) interpolated onto this problem's points is the guess.

    The coarse problem is this one with fewer intervals (same cost, constraints, guess, solver) and,
    if ``coarse_model`` is given, on that model (a continuation: an easier model first, e.g. without
    the toe springs); the result's ``iterations`` and ``seconds`` are those of both solves
    (``info["stages"]`` each one's).  A coarse grid finds the gait's pattern cheaply; the finer one
    sharpens the contacts.
    """

    def __init__(self, model, *, coarse_intervals: int, cost, constraints=(), duration=1.0, intervals: int = 50,
                 scheme: str = "hermite-simpson", controls=None, formulation: str = "ff",
                 tendon: str | None = None, guess=None, n_starts: int = 1, solver: dict | None = None,
                 verbose: bool | None = None, coarse_model=None, monitor=None, solver_log=None):
        super().__init__(model, cost=cost, constraints=constraints, duration=duration, intervals=intervals,
                         scheme=scheme, controls=controls, formulation=formulation, tendon=tendon, guess=guess,
                         n_starts=n_starts, solver=solver, verbose=verbose, monitor=monitor,
                         solver_log=solver_log)
        self.coarse_intervals = coarse_intervals
        self.coarse_model = coarse_model

    def fit(self):
        import dataclasses
        from ...fitting import Result
        params = self.get_params(deep=False)
        params.pop("coarse_intervals")
        coarse_model = params.pop("coarse_model")
        params["intervals"] = int(self.coarse_intervals)
        if coarse_model is not None:
            params["model"] = coarse_model
        coarse = Collocation(**params)
        c = coarse.fit().result_
        self.coarse_ = coarse
        self._warm = c          # the coarse solution is this fit's guess (the guess argument is untouched)
        try:
            super().fit()
        finally:
            del self._warm
        r = self.result_
        stages = [{"intervals": int(self.coarse_intervals), "iterations": int(c.iterations),
                   "seconds": float(c.seconds), "status": c.status},
                  {"intervals": int(self.intervals), "iterations": int(r.iterations),
                   "seconds": float(r.seconds), "status": r.status}]
        it = sum(s["iterations"] for s in stages)
        sec = sum(s["seconds"] for s in stages)
        self.result_ = Result(r.time, {n: r[n] for n in r.names}, stats=dataclasses.replace(r.stats, iterations=it),
                              info=dict(r.info, seconds=sec, nit=it, stages=stages))
        return self


# -- tracking -------------------------------------------------------------------------------------

def contact_rows(model) -> dict:
    """``{side: [rows of the point quantity "contact_forces"]}``: (x, y) rows of each side's spheres."""
    out = {"r": [], "l": []}
    for i, c in enumerate(model.contacts):
        side = c.target.rsplit("_", 1)[-1]
        if side in out:
            out[side].append(3 * i)
    return out


def tracking_gait(model=None, kinematics: Trial | None = None, grf: Trial | None = None, *,
                  start: float | None = None, duration: float | None = None, intervals: int = 20,
                  scheme: str = "trapezoidal", tracking_weight: float = 1.0, grf_weight: float = 0.1,
                  effort_weight: float = 0.01, muscle_model: str | None = "degroote2016",
                  tendon: str | None = "rigid", floor_sink: float | None = 0.005,
                  subject_weight: float | str | None = None, solver=None, verbose=None) -> Collocation:
    """Tracking of measured gait2d coordinates (``kinematics``: channels named as the model's
    coordinates, e.g. from :func:`pinmsk.pipeline.opensim_to_gait2d`) and ground reaction forces
    (``grf``: ``r_ground_force_vx``, ``..._vy``, ``l_...``, N) over ``[start, start + duration]``.

    Costs: coordinates (squared error over (0.1 rad)^2 or (0.05 m)^2, Moco's
    MocoStateTrackingGoal habit), GRF x/y per side over body weight (sum of each side's
    spheres), mean squared activation; bounds as the predictive problem, no symmetry.
    ``muscle_model``, ``tendon`` and the solver defaults as :func:`predictive_gait` (why: there).
    ``floor_sink``: the measured pelvis height is shifted so that the lowest sole site sits this
    deep (m) in the ground (median over the frames); None tracks it as measured.
    ``subject_weight``: None (default) tracks the measured forces in newtons, as Moco's
    MocoContactTrackingGoal does; a weight (N), or ``"grf"`` for the mean total vertical GRF over
    the tracked span, tracks them in body weights instead (scaled by the model's weight over the
    subject's).  Measured on the shipped task (gait2d 644 N, the subject 834 N over 0.5-1.1 s):
    in newtons with GRF weight 3 it converges (554 it) with joints 6.9 deg and vertical GRF 23 / 43 %
    BW RMS (right / left); scaled, the model lifts its stance foot in mid-stance (vertical GRF 51-79 %
    BW RMS at GRF weight 0.1-1) or IPOPT stops at its iteration limit (weight >= 1 with the pelvis
    height tracked).
    """
    from .costs import Cost
    model = gait_model("gait2d" if model is None else model, muscle_model=muscle_model, tendon=tendon)
    if kinematics is None:
        raise ModelError("tracking_gait needs the measured kinematics (a Trial of gait2d coordinates)")
    t = np.asarray(kinematics.time, dtype=float)
    t0 = float(t[0]) if start is None else float(start)
    T = float(t[-1] - t0) if duration is None else float(duration)
    mass = float(sum(I.mass for I in model.pin.inertias))
    bw = mass * G
    tt = t - t0
    terms: list[Cost] = []
    coords = [c for c in model.coordinates if c in kinematics.names]
    q_idx = [model.coordinate_index(c) for c in coords]
    scale = [0.05 if c in (FORWARD, HEIGHT) else 0.1 for c in coords]
    vals = np.column_stack([np.asarray(kinematics[c], dtype=float) for c in coords])
    terms.append(TrackSignals("q", q_idx, tt, vals, scale=scale, weight=tracking_weight, name="track_coordinates"))
    if grf is not None:
        gt = np.asarray(grf.time, dtype=float) - t0
        rows = contact_rows(model)
        idx, refs = [], []
        for side in ("r", "l"):
            for k, ax in ((0, "vx"), (1, "vy")):
                idx.append((side, k))
                # trial names (r_ground_force_vx) or the OpenSim/Moco file's (ground_force_r_vx)
                name = f"{side}_ground_force_{ax}"
                if name not in grf.names and f"ground_force_{side}_{ax}" in grf.names:
                    name = f"ground_force_{side}_{ax}"
                refs.append(np.asarray(grf[name], dtype=float))
        refs = np.column_stack(refs)
        if isinstance(subject_weight, str):
            if subject_weight != "grf":
                raise ModelError(f"tracking_gait: subject_weight must be N, 'grf' or None, not {subject_weight!r}")
            span = (gt >= -1e-9) & (gt <= T + 1e-9)
            if not span.any():
                raise ModelError(f"tracking_gait: the GRF record ({grf.time[0]:g}-{grf.time[-1]:g} s) does not "
                                 f"cover the tracked span ({t0:g}-{t0 + T:g} s)")
            subject_weight = float(np.mean(refs[span, 1] + refs[span, 3]))     # r_vy + l_vy
        if subject_weight is not None:
            if not float(subject_weight) > 0:
                raise ModelError(f"tracking_gait: subject_weight must be > 0 N, got {subject_weight}")
            refs = refs * (bw / float(subject_weight))
        terms.append(_TrackGRF(rows, idx, gt, refs, scale=bw, weight=grf_weight))
    terms.append(effort_weight * Effort(2))
    cost = terms[0]
    for c in terms[1:]:
        cost = cost + c
    if HEIGHT in coords and floor_sink is not None:
        # the lab floor and the model's: the mapped pelvis height of a measured walk need not put
        # gait2d's soles on the ground (the Moco walk's float 14-40 mm above it, no support at
        # all); lower it so that the lowest sole site sits floor_sink (m) deep, the median over frames
        j = coords.index(HEIGHT)
        lows = _lowest_site(model, coords, vals)
        vals = vals.copy()
        vals[:, j] -= float(np.median(lows)) + float(floor_sink)
        terms[0] = TrackSignals("q", q_idx, tt, vals, scale=scale, weight=tracking_weight, name="track_coordinates")
    q0 = {c: np.interp(0.0, tt, vals[:, j]) for j, c in enumerate(coords)}
    h = standing_height(model)
    b = gait_bounds(model)
    b.q[HEIGHT] = (min(h - 0.25, q0.get(HEIGHT, h) - 0.1), max(h + 0.1, q0.get(HEIGHT, h) + 0.1))
    b.q[FORWARD] = (float(vals[:, coords.index(FORWARD)].min()) - 0.5, float(vals[:, coords.index(FORWARD)].max()) + 0.5) \
        if FORWARD in coords else (-50.0, 50.0)
    cons = [CoordinateBounds("knee_r", -0.2, 2.5), CoordinateBounds("knee_l", -0.2, 2.5), b]
    sel = (tt >= -1e-9) & (tt <= T + 1e-9)
    guess = Trial(tt[sel], {c: vals[sel, j] for j, c in enumerate(coords)})
    return Collocation(model, cost=cost, constraints=cons, duration=T, intervals=intervals,
                       scheme=scheme, guess=guess, solver=_solver(solver), verbose=verbose)


def _lowest_site(model, coords, vals) -> np.ndarray:
    """Per frame, the height (m) of the lowest sole site (heel, metatarsal, toe of both feet)."""
    import pinocchio as pin
    pm = model.pin
    d = pm.createData()
    ids = [model.frame_id(f"{s}_{side}") for s in ("heel", "metatarsal", "toe") for side in "rl"]
    cols = [model.coordinate_index(c) for c in coords]
    out = np.empty(vals.shape[0])
    for k in range(vals.shape[0]):
        q = np.zeros(pm.nq)
        q[cols] = vals[k]
        pin.framesForwardKinematics(pm, d, q)
        out[k] = min(d.oMf[i].translation[1] for i in ids)
    return out


class _TrackGRF(TrackSignals):
    """Each side's ground reaction force (x, y), the sum of its spheres' forces, against measured
    GRF, mean squared error over body weight."""

    def __init__(self, rows, idx, time, values, *, scale, weight=1.0, name="track_grf"):
        self.rows, self.pairs = {k: list(v) for k, v in rows.items()}, list(idx)
        super().__init__("contact_forces", list(range(len(idx))), time, values, scale=scale,
                         weight=weight, name=name)

    def integrand(self, pt, ref=None):
        import casadi as ca
        f = pt["contact_forces"]
        x = ca.vertcat(*[sum(f[r + k] for r in self.rows[side]) / self.scale[j]
                         for j, (side, k) in enumerate(self.pairs)])
        return ca.sumsqr(x - ref) / len(self.pairs)


# -- one stride -----------------------------------------------------------------------------------

def ground_reaction_channels(result, model) -> dict:
    """``{r_ground_force_vx, _vy, _vz, l_...}`` (N) per side: the sum of its spheres' forces."""
    out = {}
    for side in ("r", "l"):
        for ax in "xyz":
            s = 0.0
            for c in model.contacts:
                if c.target.endswith(f"_{side}"):
                    s = s + np.asarray(result[f"{c.label}_force_{ax}"], dtype=float)
            out[f"{side}_ground_force_v{ax}"] = np.asarray(s, dtype=float) * np.ones(len(result.time))
    return out


def full_stride(fit, model=None, *, mirror: bool = True):
    """``(stride, summary)``: the half cycle and its left/right mirror, one full stride.

    ``fit``: a solved :class:`Collocation` (or a Result with ``model``).  The second half is the
    first with every ``_r``/``_l`` channel swapped and the forward translation advanced by the
    half cycle's distance.  ``stride`` is a Trial with the coordinate channels (rad, m), speeds,
    excitations, activations, forces and ``r_ground_force_vx`` ... (N); ``summary`` holds
    ``speed`` (m/s), ``stride_length`` (m), ``cost_of_transport`` (J/kg/m; metabolic energy per
    distance and body mass, None without metabolic rates), ``body_weight`` (N) and
    ``duration`` (s, the stride).
    """
    if model is None:
        model, res = fit.model, getattr(fit, "half_cycle_", fit.result_)
    else:
        res = fit
    t = np.asarray(res.time, dtype=float)
    T = float(t[-1] - t[0])
    ch = {n: np.asarray(res[n], dtype=float) for n in res.names if np.ndim(res[n]) == 1 and len(res[n]) == t.size}
    ch.update(ground_reaction_channels(res, model))
    d = float(ch[FORWARD][-1] - ch[FORWARD][0])
    mass = float(sum(I.mass for I in model.pin.inertias))
    rates = [n for n in ch if n.endswith("_metabolic_rate")]
    cot = float(np.trapezoid(sum(ch[n] for n in rates), t) / (mass * d)) if rates and d > 0 else None
    if not mirror:
        return Trial(t - t[0], ch), {"speed": d / T, "stride_length": None, "cost_of_transport": cot,
                                     "body_weight": mass * G, "duration": T}
    second = {}
    for n, x in ch.items():
        src = _mirror_name(n)
        y = ch.get(src, x)
        second[n] = y + d if n == FORWARD else y
    time = np.concatenate([t, t[1:] + T])
    stride = Trial(time - time[0], {n: np.concatenate([x, second[n][1:]]) for n, x in ch.items()},
                   meta={"source": "pinmsk predictive gait (half cycle mirrored)"})
    summary = {"speed": d / T, "stride_length": 2 * d, "cost_of_transport": cot, "body_weight": mass * G,
               "duration": 2 * T}
    return stride, summary


def build_gait_task(spec: dict, *, base_dir=None, verbose=None) -> Collocation:
    """The gait problem of a task file's ``[gait]`` table (``pinmsk optimize``; see tasks.TASK_SCHEMA)."""
    from pathlib import Path
    from ...io.tables import read_trial
    ga, ms, so = dict(spec["gait"]), spec.get("model", {}), dict(spec.get("solver", {}))
    bad = set(spec) - {"gait", "model", "solver"}
    if bad:
        raise ModelError(f"task: section(s) {sorted(bad)} do not apply to a [gait] task; use [gait] keys")
    kind = ga.pop("kind", "predictive")

    def path(k):
        if k not in ga:
            raise ModelError(f"task: [gait] kind '{kind}' needs {k} = \"<file>\"")
        f = Path(ga.pop(k))
        if f.is_absolute():
            return f
        for here in ([Path(base_dir) / f] if base_dir is not None else []) + [f]:
            if here.exists():
                return here
        from ...io.shared_data import shared_data_dir   # a path inside the shared data folder
        root = shared_data_dir()
        if root is not None and (root / f).exists():
            return root / f
        raise ModelError(f"task: [gait] {k} file '{f}' not found (relative to the task file, the "
                         "working directory or the shared data folder, $PINMSK_SHARED_DATA)")
    mm = ga.pop("muscle_model", "degroote2016")
    model = gait_model(ms.get("name", "gait2d"), contact_smoothing=float(ga.pop("contact_smoothing", 2e-3)),
                       muscle_model=None if mm == "model" else mm,
                       tendon=ms.get("tendon", None if mm == "model" else "rigid"))
    solver = {"max_iter": int(so.get("maxiter", 3000)), "tol": float(so.get("tol", 1e-4)),
              "constraint_tol": float(so.get("constraint_tol", 1e-4)),
              "hessian": so.get("hessian", "limited-memory")}
    common = dict(intervals=int(so.get("intervals", 25 if kind == "predictive" else 20)),
                  scheme=so.get("scheme", "trapezoidal"), solver=solver, verbose=verbose)
    if kind == "predictive":
        sp = ga.pop("speed", 1.3)
        ok = {"duration", "effort_weight", "guess", "seed", "knee_min", "trunk", "coarse_intervals",
              "smoothness_weight", "foot_mass", "mtp_stiffness", "mtp_damping"}
        extra = set(ga) - ok
        if extra:
            raise ModelError(f"task: [gait] key(s) {sorted(extra)} do not apply to kind 'predictive'")
        if ga.get("mtp_stiffness") == "none":           # TOML has no null
            ga["mtp_stiffness"] = None
        if ga.get("guess", "walking") not in ("walking", "standing", "quasi-random"):
            # a stride file of pinmsk optimize (Moco's setGuessFile habit): its first half cycle
            stride = read_trial(path("guess"), strict=False)
            tt = np.asarray(stride.time, dtype=float)
            first = tt <= tt[0] + 0.5 * (tt[-1] - tt[0]) + 1e-9
            ga["guess"] = Trial(tt[first] - tt[0], {n: np.asarray(stride[n], dtype=float)[first] for n in stride.names})
        return predictive_gait(model, speed=None if sp == "free" else float(sp), tendon=None, muscle_model=None,
                               **{k: ga[k] for k in ga}, **common)
    if kind == "tracking":
        # pinmsk.pipeline.opensim_to_gait2d's column map (the pipeline imports the task files,
        # so it cannot be imported here): the lab pipeline's mapping of OpenSim coordinates
        from ...io.channel_map import apply_channel_map, opensim_gait2d_map

        def opensim_to_gait2d(coords, model):
            return apply_channel_map(coords, opensim_gait2d_map(knee_sign="auto"), model=model)
        # lenient: Moco's example3DWalking files miscount nColumns in their headers (the reader
        # says so on stderr); the columns themselves are read by their labels
        kin = opensim_to_gait2d(read_trial(path("coordinates"), strict=False), model)
        grf = read_trial(path("grf"), strict=False) if "grf" in ga else None
        extra = set(ga) - {"start", "duration", "effort_weight", "grf_weight", "subject_weight"}
        if extra:
            raise ModelError(f"task: [gait] key(s) {sorted(extra)} do not apply to kind 'tracking'")
        if ga.get("subject_weight") == "none":          # TOML has no null: track the forces in N
            ga["subject_weight"] = None
        return tracking_gait(model, kin, grf, muscle_model=None, tendon=None, **{k: ga[k] for k in ga}, **common)
    raise ModelError(f"task: [gait] kind must be 'predictive' or 'tracking', not {kind!r}")
