"""Long trials: start-up, writing 1M frames, and static optimization's memory and speed, before vs after.

    python benchmarks/bench_longtrials.py            # ~2-3 min: writes 1M frames, SO on 1e4 and 1e6 frames
    python benchmarks/bench_longtrials.py --quick    # ~40 s: 2e5 frames for both

* start-up: ``import pinmsk`` and ``pinmsk --help`` in a fresh interpreter (best
  of 3), beside the modules the package used to import eagerly (Pinocchio, the
  model and dynamics modules, ``scipy.signal`` / ``scipy.interpolate``);
* writing an inverse-dynamics-sized trial (time + 11 coordinates + 11 moments)
  with :func:`pinmsk.write_trial`: the old writer (``np.savetxt`` at ``%.17g``)
  against the new default (vectorised ``%.9g``), seconds (CPU, best of 2) and MB;
* static optimization of ``gait2d`` on the walking motion of the SO benchmark
  (16 muscles, the 6 hip/knee/ankle coordinates balanced), each case in its own
  process: peak resident memory (``ru_maxrss``) and microseconds per frame of
  the whole ``fit``, in one piece (``chunk_size = N``, the old code path's
  arrays) and in chunks of :data:`pinmsk.solvers.static.CHUNK_FRAMES`.

Targets: ``--help`` <= 0.5 s, ``import pinmsk`` <= 1 s; writing ~5x
faster; SO on 1M frames under 2 GB with a near-constant cost per frame.
Run on one core: OMP_NUM_THREADS=1 is set below before numpy loads.
"""
import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

QUICK = "--quick" in sys.argv
WRITE_FRAMES = 200_000 if QUICK else 1_000_000
SO_FRAMES = (10_000, 200_000 if QUICK else 1_000_000)
GAIT_DOFS = ("hip_l", "knee_l", "ankle_l", "hip_r", "knee_r", "ankle_r")


def fresh(code: str, repeat: int = 3) -> tuple[float, float]:
    """Best wall and CPU (user + system) time (s) of ``python -c code`` in a new interpreter."""
    import resource
    wall = cpu = np.inf
    for _ in range(repeat):
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", code], check=True, stdout=subprocess.DEVNULL)
        wall = min(wall, time.perf_counter() - t0)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = min(cpu, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime))
    return wall, cpu


def startup() -> None:
    print("\nStart-up (fresh interpreter, best of 3; Python itself included)      wall      CPU")
    rows = [
        ("python (nothing imported)", "pass"),
        ("import pinmsk", "import pinmsk"),
        ("pinmsk --help", "import sys; sys.argv = ['pinmsk', '--help']\n"
                          "from pinmsk.presentation.cli import main\ntry: main()\nexcept SystemExit: pass"),
        ("pinmsk --version", "import sys; sys.argv = ['pinmsk', '--version']\n"
                             "from pinmsk.presentation.cli import main\ntry: main()\nexcept SystemExit: pass"),
        ("old eager imports", "import pinmsk.model, pinmsk.dynamics, pinmsk.io, scipy.signal, scipy.interpolate"),
    ]
    for label, code in rows:
        wall, cpu = fresh(code)
        print(f"  {label:<28} {wall:6.2f} s {cpu:6.2f} s")
    print("  (old eager imports: what 'import pinmsk' and 'pinmsk --help' loaded before: Pinocchio, "
          "the model, and scipy.signal via pinmsk.signals.filtering)")


def writing() -> None:
    import pinmsk
    import pinmsk.io.tables as pio

    n = WRITE_FRAMES
    rng = np.random.default_rng(0)
    t = np.arange(n) / 1000.0
    names = [f"q{i}" for i in range(11)] + [f"q{i}_moment" for i in range(11)]
    values = np.column_stack([0.8 * np.sin(t[:, None] * rng.uniform(1, 5, 11) + rng.uniform(0, 6, 11)),
                              rng.uniform(1, 300, 11) * np.cos(t[:, None] * rng.uniform(1, 5, 11))])
    trial = pinmsk.Trial.from_array(t, names, values)

    def old_rows(fh, table, delimiter, precision=17):
        np.savetxt(fh, table, fmt="%.17g", delimiter=delimiter)   # the former writer (%.17g, one np.savetxt)

    print(f"\nWriting {n:,} frames x 23 columns (.sto, write_trial, CPU s, atomic write included)")
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "id.sto"
        for label, rows_fn, precision, repeat in (("old: np.savetxt %.17g", old_rows, 17, 1),
                                                  ("new: %.17g (precision=17)", None, 17, 1),
                                                  ("new: vectorised %.9g (default)", None, None, 2)):
            best = np.inf
            for _ in range(repeat):
                saved = pio._write_rows
                if rows_fn is not None:
                    pio._write_rows = rows_fn
                try:
                    c0 = time.process_time()
                    pio.write_trial(trial, path, precision=precision)
                    best = min(best, time.process_time() - c0)
                finally:
                    pio._write_rows = saved
            size = path.stat().st_size / 1e6
            out[label] = (best, size)
            print(f"  {label:<32} {best:6.2f} s  {size:7.1f} MB")
        small = Path(tmp) / "head.sto"    # the round trip, on the first 1e5 frames
        pio.write_trial(pinmsk.Trial.from_array(t[:100_000], names, values[:100_000]), small)
        back = pio.read_trial(small)
        ref = values[:back.n_frames]
        err = np.max(np.abs(back.values - ref) / np.maximum(np.abs(ref), 1e-300))
    old = out["old: np.savetxt %.17g"]
    new = out["new: vectorised %.9g (default)"]
    print(f"  speed-up {old[0] / new[0]:.1f}x, size {new[1] / old[1]:.0%} of before; "
          f"re-read max relative error {err:.1e} (%.9g keeps 5e-9)")


_SO_CHILD = r"""
import os, sys, json, time, resource
os.environ["OMP_NUM_THREADS"] = "1"
import numpy as np, pinmsk
from pinmsk.diagnose.synth import walking_motion
from pinmsk.solvers.static import StaticOptimization

def peak_kb():
    # this process's own high-water mark (ru_maxrss also counts the parent's RSS at fork)
    try:
        with open("/proc/self/status") as fh:
            return next(int(l.split()[1]) for l in fh if l.startswith("VmHWM:"))
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss

n, chunk = int(sys.argv[1]), int(sys.argv[2])
model = pinmsk.load_model("gait2d")
motion = walking_motion(model, n_frames=n, duration=n / 1000.0)
before = peak_kb()
t0, c0 = time.perf_counter(), time.process_time()
so = StaticOptimization(dofs=%r, chunk_size=chunk).fit(model, motion)
wall, cpu = time.perf_counter() - t0, time.process_time() - c0
peak = peak_kb()
print(json.dumps({"wall": wall, "cpu": cpu, "solve": so.timing_["solve_s"], "peak_kb": peak,
                  "before_kb": before, "checksum": float(so.forces_.sum())}))
""" % (GAIT_DOFS,)


def static_optimization() -> None:
    from pinmsk.solvers.static import CHUNK_FRAMES

    print(f"\nStatic optimization, gait2d walking motion, P = 2 (each case in its own process; "
          f"chunks of {CHUNK_FRAMES})")
    print(f"  {'frames':>9} {'how':<22} {'peak RSS':>9} {'(motion)':>9} {'fit us/frame':>13} "
          f"{'CPU us/frame':>13} {'solve us/frame':>15}")
    sums = {}
    for n in SO_FRAMES:
        for label, chunk in (("one piece (before)", n), ("chunks (after)", CHUNK_FRAMES)):
            if n <= CHUNK_FRAMES:
                label = "one piece = chunks"
            done = subprocess.run([sys.executable, "-c", _SO_CHILD, str(n), str(chunk)], check=True,
                                  capture_output=True, text=True)
            r = json.loads(done.stdout.strip().splitlines()[-1])
            sums.setdefault(n, []).append(r["checksum"])
            print(f"  {n:>9,} {label:<22} {r['peak_kb'] / 1e6:7.2f} GB {r['before_kb'] / 1e6:6.2f} GB "
                  f"{r['wall'] / n * 1e6:13.1f} {r['cpu'] / n * 1e6:13.1f} {r['solve'] / n * 1e6:15.1f}")
            if n <= CHUNK_FRAMES:
                break
    same = all(len(set(v)) == 1 for v in sums.values())
    print(f"  (motion): resident memory before fit, the motion itself; same forces in one piece and in "
          f"chunks: {'yes, to the bit' if same else 'NO'}")


def main():
    print(f"pinmsk long-trial benchmark -- Python {platform.python_version()}, numpy {np.__version__}, "
          f"{platform.machine()}, OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}"
          f"{' (--quick)' if QUICK else ''}")
    t0 = time.perf_counter()
    startup()
    writing()
    static_optimization()
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    from _record import run
    run(main)
