"""Foundation speed: batch inverse dynamics and the muscle layer, each beside a reference run now.

    python benchmarks/bench_foundation.py            # ~20 s

* batch ID (``pinmsk.skeleton.rnea``) vs a bare ``pin.rnea`` loop over
  the same frames, on forearm, gait2d and human3d (target: >= 80 % of the bare loop);
* muscle layer (force-length-velocity capacity + compliant-tendon equilibrium over
  all 16 gait2d muscles, vectorised over frames) in muscle-frames/s (target: >= 2e6),
  beside the same calls made frame by frame from Python.
Run on one core: set OMP_NUM_THREADS=1 (done below before numpy loads).
"""
import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import platform  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402

import pinmsk  # noqa: E402
from pinmsk import skeleton  # noqa: E402


def best_of(fn, repeat=5):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def bench_id(name, n=20000):
    model = pinmsk.load_model(name)
    rng = np.random.default_rng(0)
    q = rng.uniform(-1, 1, (n, model.nq))
    v = rng.uniform(-1, 1, (n, model.nv))
    a = rng.uniform(-1, 1, (n, model.nv))
    pm = model.pin
    pd = pm.createData()        # the bare loop's Pinocchio workspace (a pinmsk Data is not one)

    def bare():
        out = np.empty((n, pm.nv))
        for i in range(n):
            out[i] = pin.rnea(pm, pd, q[i], v[i], a[i])
        return out

    def ours():
        return skeleton.rnea(model, q, v, a)

    t_bare = best_of(bare)
    t_ours = best_of(ours)
    return n / t_ours, n / t_bare


def bench_muscles(n=20000):
    model = pinmsk.load_model("gait2d")
    ms = model.muscles
    rng = np.random.default_rng(1)
    q = np.zeros((n, model.nv))
    # a walking-like range where every muscle-tendon unit stays taut
    for coord, lo, hi in (("hip", -0.5, 0.2), ("knee", 0.0, 0.9), ("ankle", -0.3, 0.3)):
        for side in "rl":
            q[:, model.coordinate_index(f"{coord}_{side}")] = rng.uniform(lo, hi, n)
    v = rng.uniform(-2, 2, (n, model.nv))
    l_mt = ms.lengths(q)
    v_mt = ms.velocities(q, v)
    act = rng.uniform(0.05, 1.0, l_mt.shape)

    def vectorised():
        ms.mtu.force_limits(l_mt, v_mt)
        ms.mtu.equilibrium(l_mt, act)

    t_vec = best_of(vectorised, 3)
    k = 300   # reference: the same calls frame by frame (a per-frame Python loop), on a subset, scaled
    def per_frame():
        for i in range(k):
            ms.mtu.force_limits(l_mt[i:i + 1], v_mt[i:i + 1])
            ms.mtu.equilibrium(l_mt[i:i + 1], act[i:i + 1])
    t_sca = best_of(per_frame, 1) / k * n
    return n * ms.n / t_vec, n * ms.n / t_sca


def cpu_name() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "cpu"


def main():
    print(f"machine: {platform.machine()}, {cpu_name()}, {os.cpu_count()} cores, "
          f"python {platform.python_version()}, pinocchio {pin.__version__}, numpy {np.__version__}")
    print("batch inverse dynamics (frames/s)                    pinmsk     bare pin.rnea loop   ratio")
    for name in ("forearm", "gait2d", "human3d"):
        ours, bare = bench_id(name)
        model = pinmsk.load_model(name)
        print(f"  {name:<8} ({model.nv:>2} dof)                            {ours:>10,.0f}   {bare:>10,.0f}        {ours / bare:5.2f}")
    vec, sca = bench_muscles()
    print("muscle layer, gait2d 16 muscles (muscle-frames/s)     vectorised   per-frame loop       ratio")
    print(f"  force limits + compliant equilibrium                {vec:>12,.0f} {sca:>12,.0f}      {vec / sca:7.0f}")


if __name__ == "__main__":
    from _record import run
    run(main)
