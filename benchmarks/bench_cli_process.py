"""``pinmsk id`` as a whole process against OpenSim's InverseDynamicsTool as a process, in one run.

    python benchmarks/bench_cli_process.py [--repeat 3] [--data DIR]

What a user waits for: each command is a fresh interpreter (start-up, imports, reading the files, the
model, filtering, solving, writing the .sto), timed by its wall clock, best of ``--repeat``:

* **Gait10dof18musc** (``subject01.osim``, ``IK/subject01_walk_IK.mot``, 151 frames, 6 Hz,
  ``ExperimentalData/subject01_walk_grf.xml``):
  - ``pinmsk id`` on the ``.osim`` with an empty import cache (the import done in the process);
  - ``pinmsk id`` on the ``.osim`` again (the import read from the cache: ``pinmsk.io.cache``);
  - ``pinmsk id`` on the model's imported sidecar ``.toml`` (``pinmsk import``, done beforehand);
  - OpenSim: ``python -c`` running the folder's ``ID/walk_Setup_ID.xml`` (``InverseDynamicsTool(setup).run()``,
    its paths made absolute, results to a temporary folder), ``import opensim`` included.
  Targets: the cached ``.osim`` within 0.3 s of the ``.toml``, and not slower than OpenSim.
* **RajagopalWalk** (``subject_walk_scaled.osim``, the walk of ``real/opensim-moco-walk-emg``: 1,350
  frames, its ``grf_walk.xml``), no filter on either side (``--cutoff 0 --grf-cutoff 0`` / cut-off -1), on a
  coordinates file in OpenSim's coordinates written beforehand (the mtp angles at their defaults, the
  patella angles the coupling's, as tests/test_osim_id.py compares them): the same four rows.

Each pinmsk row runs with its own import cache folder (``PINMSK_CACHE_DIR``); ratios are printed
beside the rows (OpenSim's time / pinmsk's: > 1 is pinmsk faster).  Python's bytecode cache is on for
every process (``PYTHONDONTWRITEBYTECODE`` removed, the bytecode under a temporary
``PYTHONPYCACHEPREFIX``), warmed by one untimed run of each command.  Without the shared data the
script says so and exits 0; without the optional peer ``opensim`` it times pinmsk only.
"""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def _env(cache: Path, pycache: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env.update(PINMSK_CACHE_DIR=str(cache), PYTHONPYCACHEPREFIX=str(pycache))
    env.pop("PINMSK_NO_CACHE", None)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    return env


def _run(cmd, env, cwd) -> float:
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    dt = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd))} failed:\n{proc.stderr[-2000:]}")
    return dt


def _best(cmd, env, cwd, repeat, *, before=None) -> float:
    """Best wall time of ``repeat`` runs (``before()`` runs untimed ahead of each)."""
    best = np.inf
    for _ in range(repeat):
        if before is not None:
            before()
        best = min(best, _run(cmd, env, cwd))
    return best


def _opensim_available(env) -> bool:
    return subprocess.run([sys.executable, "-c", "import opensim"], env=env, capture_output=True).returncode == 0


_OPENSIM_ID = """
import sys, opensim as osim
osim.Logger.setLevelString("Off")
model, coords, loads, results, cutoff, t0, t1 = sys.argv[1:8]
tool = osim.InverseDynamicsTool()
tool.setModelFileName(model)
tool.setCoordinatesFileName(coords)
tool.setExternalLoadsFileName(loads)
tool.setLowpassCutoffFrequency(float(cutoff))
tool.setStartTime(float(t0))
tool.setEndTime(float(t1))
excluded = osim.ArrayStr()
excluded.append("Muscles")
tool.setExcludedForces(excluded)
tool.setResultsDir(results)
tool.setOutputGenForceFileName("id.sto")
assert tool.run()
"""


def _case(title, *, osim_file, coords, loads, flags, cutoff, t_range, work, repeat, opensim, pycache) -> None:
    py = sys.executable
    out = work / "out.sto"
    pin = [py, "-m", "pinmsk", "id"]
    tail = [str(coords), "--external-loads", str(loads), "-o", str(out), *flags]
    cold_cache, warm_cache, toml_cache = work / "cache-cold", work / "cache-warm", work / "cache-toml"

    def empty():
        shutil.rmtree(cold_cache, ignore_errors=True)

    env_cold, env_warm, env_toml = (_env(c, pycache) for c in (cold_cache, warm_cache, toml_cache))
    sidecar_dir = work / "imported"
    _run(pin[:3] + ["import", str(osim_file), "-o", str(sidecar_dir), "--name", "model"], env_toml, work)
    sidecar = sidecar_dir / "model.toml"
    _run(pin + [str(osim_file)] + tail, env_warm, work)             # warms the bytecode and the cache
    _run(pin + [str(sidecar)] + tail, env_toml, work)
    t_cold = _best(pin + [str(osim_file)] + tail, env_cold, work, repeat, before=empty)
    t_warm = _best(pin + [str(osim_file)] + tail, env_warm, work, repeat)
    t_toml = _best(pin + [str(sidecar)] + tail, env_toml, work, repeat)
    t_osim = np.nan
    if opensim:
        cmd = [py, "-c", _OPENSIM_ID, str(osim_file), str(coords), str(loads), str(work / "opensim"),
               str(cutoff), str(t_range[0]), str(t_range[1])]
        _run(cmd, env_warm, work)
        t_osim = _best(cmd, env_warm, work, repeat)

    def ratio(t):
        return f"{t_osim / t:6.2f}x" if np.isfinite(t_osim) else "     -"

    print(f"\n{title}                                   wall (s)   OpenSim / pinmsk")
    print(f"  pinmsk id <.osim>, empty import cache      {t_cold:8.3f}   {ratio(t_cold)}")
    print(f"  pinmsk id <.osim>, import cached           {t_warm:8.3f}   {ratio(t_warm)}")
    print(f"  pinmsk id <.toml> (its pinmsk import)      {t_toml:8.3f}   {ratio(t_toml)}")
    if np.isfinite(t_osim):
        print(f"  OpenSim InverseDynamicsTool (process)      {t_osim:8.3f}")
    else:
        print("  OpenSim InverseDynamicsTool: skipped (opensim is not importable)")
    print(f"  cached .osim - .toml: {t_warm - t_toml:+.3f} s (target <= 0.3 s)")


def _rajagopal_coordinates(raj: Path, walk: Path, dst: Path) -> tuple[float, float]:
    """The walk in OpenSim's coordinates (tests/test_osim_id.py's file): (start, end) time."""
    import warnings

    from pinmsk.io.tables import read_trial
    from pinmsk.kinematics import coordinate_map
    from pinmsk.model import import_osim
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model, _ = import_osim(raj, nonlinear="exact", hooks=())
        raw = read_trial(walk / "coordinates.sto", strict=False)
    cmap = coordinate_map(model)
    ch = {n.split("/")[-2]: np.asarray(raw[n]) for n in raw.names}
    ch.update({c: np.full(raw.n_frames, cmap.defaults[c]) for c in cmap.osim_coordinates if c not in ch})
    for dep, indep, f, scale in cmap.couplers:
        ch[dep] = scale * f.value(ch[indep[0]])
    names = list(cmap.osim_coordinates)
    X = np.column_stack([raw.time] + [ch[c] for c in names])
    with open(dst, "w") as fh:
        fh.write(f"Coordinates\nversion=1\nnRows={X.shape[0]}\nnColumns={X.shape[1]}\ninDegrees=no\nendheader\n")
        fh.write("\t".join(["time"] + names) + "\n")
        np.savetxt(fh, X, delimiter="\t", fmt="%.12g")
    return float(raw.time[0]), float(raw.time[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--data", type=Path, default=None, help="the shared data folder (default ../shared/data)")
    args = ap.parse_args(argv)
    from pinmsk.io.shared_data import shared_data_dir
    data = args.data or shared_data_dir()
    gait = None if data is None else Path(data) / "opensim-models" / "Gait10dof18musc"
    if gait is None or not (gait / "subject01.osim").is_file():
        print("bench_cli_process: ../shared/data/opensim-models is absent; nothing to time")
        return 0
    with tempfile.TemporaryDirectory(prefix="pinmsk-bench-cli-") as tmp:
        tmp = Path(tmp)
        pycache = tmp / "pycache"
        opensim = _opensim_available(_env(tmp / "probe", pycache))
        print(f"pinmsk id as a process against OpenSim's InverseDynamicsTool as a process (best of {args.repeat}; "
              f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.1f})")
        work = tmp / "gait"
        work.mkdir()
        _case("Gait10dof18musc (151 frames, 6 Hz)", osim_file=gait / "subject01.osim",
              coords=gait / "IK" / "subject01_walk_IK.mot", loads=gait / "ExperimentalData" / "subject01_walk_grf.xml",
              flags=[], cutoff=6.0, t_range=(0.0, 2.5), work=work, repeat=args.repeat, opensim=opensim,
              pycache=pycache)
        raj = Path(data) / "opensim-models" / "RajagopalWalk" / "subject_walk_scaled.osim"
        walk = Path(data) / "real" / "opensim-moco-walk-emg"
        if not (raj.is_file() and (walk / "coordinates.sto").is_file()):
            print("\nRajagopalWalk or real/opensim-moco-walk-emg is absent: skipped")
            return 0
        work = tmp / "rajagopal"
        work.mkdir()
        t_range = _rajagopal_coordinates(raj, walk, work / "coordinates.sto")
        xml = (raj.parent / "grf_walk.xml").read_text().replace(
            "<datafile>grf_walk.mot</datafile>", f"<datafile>{walk / 'grf_walk.mot'}</datafile>")
        (work / "grf_walk.xml").write_text(xml)
        _case("RajagopalWalk (1,350 frames, no filter)", osim_file=raj, coords=work / "coordinates.sto",
              loads=work / "grf_walk.xml", flags=["--cutoff", "0", "--grf-cutoff", "0"], cutoff=-1.0,
              t_range=t_range, work=work, repeat=args.repeat, opensim=opensim, pycache=pycache)
    return 0


if __name__ == "__main__":
    from _record import run
    sys.exit(run(main))
