"""The skeleton's inverse dynamics and its Jacobian at 100 collocation nodes: AD through CasADi
against Pinocchio's analytic derivatives in a CasADi callback.

    python benchmarks/bench_ocp_skeleton.py [--jit]

For gait2d and human3d, ``tau = rnea(q, v, a)`` and its full Jacobian ``d tau / d(q, v, a)`` at 100
random nodes, evaluated by:

(a) ``SymbolicSkeleton``'s SX Function and its SX Jacobian Function (CasADi AD): in a Python loop of
    plain Function calls, and as one ``Function.map(100)`` call (what an NLP does: no Python per node);
    with ``--jit`` also compiled to C by the system compiler (compile time printed);
(b) ``RneaCallback`` (``pin.rnea`` + ``pin.computeRNEADerivatives`` in a CasADi callback): a Python
    loop of its Function and Jacobian Function calls, and an MX Function of both mapped over 100 nodes;
(c) a bare ``pin.rnea`` + ``pin.computeRNEADerivatives`` loop (the floor of (b)).

One run, best of 5 repeats (the machine may be shared); ratios are against (c).
"""
from __future__ import annotations

import argparse
import time

import casadi as ca
import numpy as np
import pinocchio as pin

from pinmsk import load_model
from pinmsk.solvers.ocp.skeleton import RneaCallback, SymbolicSkeleton

NODES = 100


def best(fn, repeat=5):
    out = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t)
    return min(out)


def bench(name: str, jit: bool) -> None:
    pm = load_model(name).pin
    data = pm.createData()
    rng = np.random.default_rng(0)
    Q, V, A = rng.uniform(-1, 1, (NODES, pm.nq)), rng.normal(0, 2, (NODES, pm.nv)), rng.normal(0, 5, (NODES, pm.nv))

    t0 = time.perf_counter()
    sk = SymbolicSkeleton(pm)
    f = sk.casadi_function()
    q, v, a = f.sx_in()
    tau = f(q, v, a)
    jf = ca.Function("rnea_jac", [q, v, a], [tau, ca.jacobian(tau, ca.vertcat(q, v, a))])
    build = time.perf_counter() - t0
    fm, jfm = f.map(NODES), jf.map(NODES)
    QT, VT, AT = Q.T.copy(), V.T.copy(), A.T.copy()

    def sx_loop():
        for k in range(NODES):
            f(Q[k], V[k], A[k])
            jf(Q[k], V[k], A[k])

    def sx_map():
        fm(QT, VT, AT)
        jfm(QT, VT, AT)

    cb = RneaCallback(pm)
    cbj = cb.jacobian()
    qm, vm, am = ca.MX.sym("q", pm.nq), ca.MX.sym("v", pm.nv), ca.MX.sym("a", pm.nv)
    out = cb(qm, vm, am)
    cb_fun = ca.Function("cb_both", [qm, vm, am], [out, ca.jacobian(out, ca.vertcat(qm, vm, am))]).map(NODES)

    def cb_loop():
        for k in range(NODES):
            t = cb(Q[k], V[k], A[k])
            cbj(Q[k], V[k], A[k], t)

    def cb_map():
        cb_fun(QT, VT, AT)

    def pin_loop():
        for k in range(NODES):
            pin.rnea(pm, data, Q[k], V[k], A[k])
            pin.computeRNEADerivatives(pm, data, Q[k], V[k], A[k])

    # same numbers on all roads before timing anything
    T1, J1 = (np.asarray(x) for x in jfm(QT, VT, AT))
    T2, J2 = (np.asarray(x) for x in cb_fun(QT, VT, AT))
    assert np.abs(T1 - T2).max() < 1e-10 and np.abs(J1 - J2).max() < 1e-10

    rows = [("(a) SX Function, Python loop", best(sx_loop)), ("(a) SX Function, map(100)", best(sx_map))]
    if jit:
        t0 = time.perf_counter()
        opts = {"jit": True, "compiler": "shell", "jit_options": {"flags": ["-O1"], "verbose": False}}
        fj = ca.Function("rnea_c", [q, v, a], [tau], opts).map(NODES)
        jfj = ca.Function("rnea_jac_c", [q, v, a], [tau, ca.jacobian(tau, ca.vertcat(q, v, a))], opts).map(NODES)
        fj(QT, VT, AT)
        jfj(QT, VT, AT)
        compile_s = time.perf_counter() - t0
        rows.append((f"(a) SX compiled -O1, map(100) [compile {compile_s:.1f} s]",
                     best(lambda: (fj(QT, VT, AT), jfj(QT, VT, AT)))))
    rows += [("(b) RneaCallback, Python loop", best(cb_loop)), ("(b) RneaCallback in MX, map(100)", best(cb_map)),
             ("(c) pin.rnea + computeRNEADerivatives loop", best(pin_loop))]
    floor = rows[-1][1]
    jac_sp = jf.sparsity_out(1)
    print(f"\n{name}: nq = {pm.nq}, {NODES} nodes; SX build {build * 1e3:.0f} ms, rnea {f.n_instructions()} "
          f"instructions, jacobian {jf.n_instructions()} instructions, {jac_sp.nnz()} of "
          f"{jac_sp.numel()} Jacobian entries structurally nonzero")
    for label, t in rows:
        print(f"  {label:<58s} {t * 1e3:8.2f} ms  ({t / floor:6.2f} x pin)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jit", action="store_true", help="also compile the SX Functions to C (needs a C compiler)")
    args = ap.parse_args()
    for name in ("gait2d", "human3d"):
        bench(name, args.jit)


if __name__ == "__main__":
    from _record import run
    run(main)
