"""Optimal-control speed: the new engine against the old one and against a plain
CasADi model of the same equations, all measured in this one run.

    python benchmarks/bench_ocp.py [--old-jobs 2] [--skip-old] [--repeat 3]

Problems (thesis Sec. 3.2.2 and 3.3):

- forearm J4: model ``forearm`` (moment arms as functions of the angle), 1.9 s cycle
  ``0.3 + 0.8 (1 - cos(2 pi t / 1.9))`` tracked within 0.1 rad, ``Effort(3, weights="volume")``,
  11-term Fourier excitations (77 parameters), Hermite-Simpson, 50 intervals;
- finger tapping 6 Hz: ``0.1 Effort(2, normalize=False) + 0.9 TrackCoordinates``, 6th-order
  polynomial excitations (14 parameters), Hermite-Simpson, 50 intervals.

Lines printed:

1. **new** -- :class:`pinmsk.solvers.ocp.Collocation`: the whole ``fit()`` (setup, NLP build,
   guess, IPOPT, result) and the IPOPT part alone (``result_.starts[0]["seconds"]``), best of
   ``--repeat`` runs (the machine is shared: the minimum is the least disturbed run);
2. **old** -- the single-shooting SLSQP engine (``pinmsk.solvers.dynamic``) as the examples ran
   it at commit ``OLD_COMMIT`` (RK4, 2 starts, finite-difference gradients).  That commit's
   ``pinmsk/`` and two examples are extracted with ``git archive`` into a temporary directory and
   run in a subprocess with ``PYTHONPATH`` set to it, so the old code never mixes with this
   checkout's; outside a git checkout the line says so and is skipped.  Run once (~1.5 min);
3. **plain** -- forearm J4 written directly in CasADi (:func:`plain_forearm_j4`): the 1-dof
   pendulum ``M qdd + c1 cos q + c2 sin q = R(q)^T F`` in explicit form, the model's Thelen
   rigid-tendon law and activation rate (the same generic functions, on SX), Fourier
   excitations, compressed Hermite-Simpson collocation, one MX ``nlpsol`` with CasADi's exact
   Hessian; a constant objective factor the only scaling, no guess from static optimization.
   Run once.  It is the floor of what any wrapper can reach on this
   problem.

Ratios printed: old / new (the speed-up) and new / plain (the engine's overhead).
"""
from __future__ import annotations

import os

# MUMPS (through OpenBLAS / OpenMP) starts one thread per core: on a 2-core machine shared with
# other jobs the threads contend and the timings swing several-fold.  One thread each, set before
# casadi (and numpy) load their libraries, which read these once.
os.environ["OMP_NUM_THREADS"] = "1"
os.environ["OPENBLAS_NUM_THREADS"] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import casadi as ca  # noqa: E402
import numpy as np  # noqa: E402

import pinmsk  # noqa: E402
from pinmsk.solvers import ocp  # noqa: E402
from pinmsk.solvers.parametrization import Fourier, Polynomial  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
#: the last commit with the single-shooting engine (pinmsk/solvers/dynamic.py, simulation_designs.py)
OLD_COMMIT = "806da15"
PERIOD, TOL, INTERVALS, FINGER_HZ = 1.9, 0.1, 50, 6.0
#: the plain model's objective factor: J4 is ~1e-4, and IPOPT's tolerances are absolute, so the
#: one scaling any CasADi user applies is a constant bringing the objective near 1
J_SCALE = 1e4


def forearm_target():
    return ocp.Target("cycle", amplitude=1.6, period=PERIOD, offset=0.3)


def new_forearm_j4(model):
    tg = forearm_target()
    return ocp.Collocation(
        model, cost=ocp.Effort(3, weights="volume"),
        constraints=[ocp.TrackingTolerance(tg, TOL),
                     ocp.InitialState(q={"elbow_flexion": 0.3}, v={"elbow_flexion": 0.0})],
        duration=PERIOD, intervals=INTERVALS, scheme="hermite-simpson",
        controls=ocp.GlobalControls(Fourier(5, period=PERIOD)), verbose=False).fit().result_


def new_finger(model, f=FINGER_HZ):
    tg = ocp.Target("sine", amplitude=0.21, frequency=f)
    c = model.coordinates[0]
    return ocp.Collocation(
        model, cost=0.1 * ocp.Effort(2, normalize=False) + 0.9 * ocp.TrackCoordinates(tg),
        constraints=[ocp.InitialState(q={c: float(tg(0.0))}, v={c: float(tg(0.0, 1))})],
        duration=1.0 / f, intervals=INTERVALS, scheme="hermite-simpson",
        controls=ocp.GlobalControls(Polynomial(6, duration=1.0 / f)), verbose=False).fit().result_


def best_of(fn, repeat):
    """``(result, whole seconds, solve seconds)`` of the fastest of ``repeat`` runs."""
    runs = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        r = fn()
        runs.append((time.perf_counter() - t0, r))
    sec, r = min(runs, key=lambda x: x[0])
    return r, sec, float(r.starts[0]["seconds"])


# ---------------------------------------------------------------------------- the plain model
def plain_forearm_j4(model):
    """Forearm J4 written directly in CasADi; returns ``(objective, iterations, status, build s, solve s)``.

    States at the 51 nodes ``x = [q, v, a_1..a_7]``, the 77 Fourier coefficients ``P``;
    ``xdot = [v, (R(q)^T F(a, q, v) - g(q)) / M, adot(u, a)]`` with ``g(q) = c1 cos q + c2 sin q``
    (``M``, ``c1``, ``c2`` read from Pinocchio); compressed Hermite-Simpson defects; Simpson's
    rule for ``J4 = 1/(T sum V) int sum V_i a_i^3 dt``; ``|q - q_d| <= 0.1`` and ``0 <= u <= 1``
    at nodes and midpoints; ``q(0) = 0.3``, ``v(0) = 0``, ``a(0) = u(0)``.
    """
    import pinocchio as pin
    from pinmsk.effects.activation import excitation_path
    from pinmsk.muscles.activation import activation_rate

    t_build = time.perf_counter()
    pm, data = model.pin, model.pin.createData()
    M = float(pin.crba(pm, data, np.zeros(1))[0, 0])
    c1 = float(pin.rnea(pm, data, np.zeros(1), np.zeros(1), np.zeros(1))[0])
    c2 = float(pin.rnea(pm, data, np.array([np.pi / 2]), np.zeros(1), np.zeros(1))[0])
    ms, mtu = model.muscles, model.muscles.mtu
    path = excitation_path(model)
    m, V = ms.n, ms.volume
    N, T = INTERVALS, PERIOD
    h = T / N
    tg = forearm_target()

    # one point's right-hand side, as a CasADi Function (inlined into the SX NLP below)
    x, u = ca.SX.sym("x", 2 + m), ca.SX.sym("u", m)
    q, v, a = x[0], x[1], x[2:]
    R = ca.reshape(ms.moment_arms_at(q), m, 1)
    F = mtu.rigid_force(a, ca.vec(ms.lengths_at(q)), -R * v)
    qdd = (ca.dot(R, F) - c1 * ca.cos(q) - c2 * ca.sin(q)) / M
    adot = activation_rate(u, a, tau_rise=path.tau_rise, tau_fall=path.tau_fall)
    f = ca.Function("f", [x, u], [ca.vertcat(v, qdd, adot)])

    # Fourier basis [1, cos(k w t), sin(k w t)], k = 1..5, at nodes and midpoints
    w0 = 2 * np.pi / T
    tn = np.linspace(0, T, N + 1)
    tm = 0.5 * (tn[1:] + tn[:-1])

    def basis(t):
        k = np.arange(1, 6)
        return np.hstack([np.ones((t.size, 1)), np.cos(w0 * np.outer(t, k)), np.sin(w0 * np.outer(t, k))])

    # decision variables as MX; the point function mapped over the nodes and midpoints (one
    # call each, no Python per node).  Not expanded to SX: with "expand" nlpsol took 22 s to build
    # the exact Hessian (the 77 coefficients couple every point) for a 1.5 s solve
    X = ca.MX.sym("X", 2 + m, N + 1)
    P = ca.MX.sym("P", 11, m)
    Un = ca.mtimes(ca.DM(basis(tn)), P).T        # (m, N+1)
    Um = ca.mtimes(ca.DM(basis(tm)), P).T        # (m, N)
    Fn = f.map(N + 1)(X, Un)
    Xm = 0.5 * (X[:, :-1] + X[:, 1:]) + h / 8 * (Fn[:, :-1] - Fn[:, 1:])
    Fm = f.map(N)(Xm, Um)
    defects = X[:, 1:] - X[:, :-1] - h / 6 * (Fn[:, :-1] + 4 * Fm + Fn[:, 1:])
    Sv = ca.DM(V / V.sum()).T
    Ln, Lm = ca.mtimes(Sv, X[2:, :] ** 3), ca.mtimes(Sv, Xm[2:, :] ** 3)
    J = ca.sum2(h / 6 * (Ln[:, :-1] + 4 * Lm + Ln[:, 1:])) / T
    qd, qdm = np.asarray(tg(tn), dtype=float), np.asarray(tg(tm), dtype=float)
    # a(0) = u(0): activation starts at rest (InitialState's default, as the old engine's simulation)
    g = [ca.vec(defects), X[2:, 0] - Un[:, 0], X[0, :].T - qd, Xm[0, :].T - qdm, ca.vec(Un), ca.vec(Um)]
    lbg = [0.0] * ((2 + m) * N + m) + [-TOL] * (2 * N + 1) + [0.0] * (m * (2 * N + 1))
    ubg = [0.0] * ((2 + m) * N + m) + [TOL] * (2 * N + 1) + [1.0] * (m * (2 * N + 1))
    wv = ca.vertcat(ca.vec(X), ca.vec(P))
    nx = (2 + m) * (N + 1)
    lbx, ubx = np.full(wv.numel(), -np.inf), np.full(wv.numel(), np.inf)
    Xl, Xu = np.full((2 + m, N + 1), -np.inf), np.full((2 + m, N + 1), np.inf)
    Xl[2:], Xu[2:] = 0.0, 1.0
    Xl[:2, 0] = Xu[:2, 0] = (0.3, 0.0)            # q(0), v(0)
    lbx[:nx], ubx[:nx] = Xl.ravel(order="F"), Xu.ravel(order="F")
    # the guess: the target motion, every muscle at 5 % (no static optimization)
    X0 = np.vstack([qd, np.asarray(tg(tn, 1), dtype=float), np.full((m, N + 1), 0.05)])
    P0 = np.zeros((11, m))
    P0[0] = 0.05
    x0 = np.concatenate([X0.ravel(order="F"), P0.ravel(order="F")])
    solver = ca.nlpsol("plain", "ipopt", {"x": wv, "f": J * J_SCALE, "g": ca.vertcat(*g)},
                       {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                        "ipopt.tol": 1e-8, "ipopt.mu_strategy": "adaptive"})
    t_solve = time.perf_counter()
    sol = solver(x0=x0, lbx=lbx, ubx=ubx, lbg=np.array(lbg), ubg=np.array(ubg))
    t_end = time.perf_counter()
    st = solver.stats()
    return (float(sol["f"]) / J_SCALE, int(st["iter_count"]), str(st["return_status"]),
            t_end - t_build, t_end - t_solve)


# ---------------------------------------------------------------------------- the old engine
OLD_SCRIPT = r"""
import json, sys, time
sys.path.insert(0, sys.argv[1])
import pinmsk
import finger_tapping as ft
import forearm_dynamic_optimization as fa
jobs = int(sys.argv[2])
out = {"pinmsk": pinmsk.__file__}
res, sec = fa.solve(pinmsk.load_model("forearm", moment_arms="angle"), "J4", "fourier", jobs=jobs)
out["forearm"] = dict(seconds=sec, objective=float(res.objective), nit=int(res.nit), converged=bool(res.converged))
res, sec = ft.solve(pinmsk.load_model("finger"), 6.0, jobs=jobs)
out["finger"] = dict(seconds=sec, objective=float(res.objective), nit=int(res.nit), converged=bool(res.converged))
print("OLD-RESULT " + json.dumps(out))
"""


def old_engine(jobs: int, commit: str = OLD_COMMIT):
    """The old examples' ``solve`` at ``commit`` in a subprocess: ``(dict, None)`` or ``(None, reason)``."""
    try:
        ok = subprocess.run(["git", "-C", str(REPO), "cat-file", "-e", f"{commit}^{{commit}}"],
                            capture_output=True).returncode == 0
    except OSError:
        ok = False
    if not ok:
        return None, f"not in a git checkout holding commit {commit}"
    with tempfile.TemporaryDirectory(prefix="pinmsk_old_") as tmp:
        arch = subprocess.run(["git", "-C", str(REPO), "archive", commit, "pinmsk",
                               "examples/finger_tapping.py", "examples/forearm_dynamic_optimization.py"],
                              capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", tmp], input=arch, check=True)
        env = dict(os.environ, PYTHONPATH=tmp, MPLBACKEND="Agg")
        p = subprocess.run([sys.executable, "-c", OLD_SCRIPT, str(Path(tmp) / "examples"), str(jobs)],
                           cwd=tmp, env=env, capture_output=True, text=True, timeout=400)
        line = [ln for ln in p.stdout.splitlines() if ln.startswith("OLD-RESULT ")]
        if p.returncode or not line:
            return None, f"the old engine failed (exit {p.returncode}): {p.stderr.strip()[-300:]}"
        out = json.loads(line[0].split(" ", 1)[1])
        if not out["pinmsk"].startswith(tmp):
            return None, f"the subprocess imported pinmsk from {out['pinmsk']}, not commit {commit}"
        return out, None


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old-jobs", type=int, default=2, help="multi-start workers of the old engine (as its examples)")
    ap.add_argument("--skip-old", action="store_true", help="skip the old engine (~1.5 min)")
    ap.add_argument("--repeat", type=int, default=3, help="runs of the new engine (best kept)")
    args = ap.parse_args(argv)
    t_all = time.perf_counter()
    try:
        load = os.getloadavg()[0]
    except OSError:  # pragma: no cover
        load = float("nan")
    print(f"cores {os.cpu_count()}, load average {load:.2f}, casadi {ca.__version__}, "
          f"OMP/OPENBLAS threads 1, new engine best of {args.repeat}")
    forearm = pinmsk.load_model("forearm", moment_arms="angle")
    finger = pinmsk.load_model("finger")

    new = {"forearm": best_of(lambda: new_forearm_j4(forearm), args.repeat),
           "finger": best_of(lambda: new_finger(finger), args.repeat)}
    plain = plain_forearm_j4(forearm)          # ~9 s: once
    old, why = (None, "skipped (--skip-old)") if args.skip_old else old_engine(args.old_jobs)

    names = {"forearm": "forearm J4, Fourier K=5 (77 par.), HS 50", "finger": "finger 6 Hz, polynomial 6 (14 par.), HS 50"}
    print(f"\n{'problem':44s} {'engine':6s} {'whole s':>8s} {'solve s':>8s} {'objective':>12s} {'iter':>5s}  status")
    for key in ("forearm", "finger"):
        r, sec, solve = new[key]
        print(f"{names[key]:44s} {'new':6s} {sec:8.3f} {solve:8.3f} {r.objective:12.6g} {r.nit:5d}  "
              f"{'converged' if r.converged else 'NOT CONVERGED: ' + r.status}")
        if old is not None:
            o = old[key]
            print(f"{'':44s} {'old':6s} {o['seconds']:8.2f} {'':>8s} {o['objective']:12.6g} {o['nit']:5d}  "
                  f"{'converged' if o['converged'] else 'NOT CONVERGED'} (SLSQP, RK4, 2 starts, "
                  f"{args.old_jobs} worker(s), commit {OLD_COMMIT})")
        else:
            print(f"{'':44s} {'old':6s} skipped: {why}")
        if key == "forearm":
            J, nit, status, whole, solve_p = plain
            print(f"{'':44s} {'plain':6s} {whole:8.3f} {solve_p:8.3f} {J:12.6g} {nit:5d}  {status} "
                  "(hand-written CasADi)")
    print("\nratios")
    for key in ("forearm", "finger"):
        r, sec, solve = new[key]
        if old is not None:
            o = old[key]
            print(f"  {key:8s} old / new (whole fit): {o['seconds'] / sec:6.1f}x   objective new/old - 1: "
                  f"{r.objective / o['objective'] - 1:+.2%}")
        target = 0.5
        print(f"  {key:8s} new whole fit {sec:.3f} s against the target <= {target} s: "
              f"{'met' if sec <= target else 'NOT met'}")
    r, sec, solve = new["forearm"]
    J, nit, status, whole, solve_p = plain
    print(f"  forearm  new / plain: whole {sec / whole:5.2f}x, solve {solve / solve_p:5.2f}x   "
          f"objective new/plain - 1: {r.objective / J - 1:+.2%}")
    print(f"benchmark total {time.perf_counter() - t_all:.0f} s")
    return new, old, plain


if __name__ == "__main__":
    from _record import run
    run(main)
