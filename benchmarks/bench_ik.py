"""Inverse kinematics per frame: pinmsk against OpenSim's InverseKinematicsTool, in one run.

    python benchmarks/bench_ik.py [--repeat 3] [--data DIR]

The example IK setups of OpenSim's models (shared data): Gait10dof18musc (``IK/walk_Setup_IK.xml``,
151 frames, 31 markers, 10 coordinates) and Gait2354 (``subject01_Setup_IK.xml`` on the scaled model
of ``OutputReference``, 73 frames, 31 markers, 23 coordinates, 4 coordinate tasks) and the Rajagopal
walk (``subject_walk_scaled.osim`` with the Moco example's ``markers_walk.trc``, 0.5 to 1.5 s: 101
frames, 39 coordinates, coupled knees, clamped ranges, no task set).  OpenSim's side is timed best of
``min(repeat, 2)`` (a Rajagopal run takes seconds).

* **OpenSim**: ``InverseKinematicsTool(setup).run()`` timed (model set-up, reading the .trc, the solves
  and writing cannot be split), and its solver alone: ``InverseKinematicsSolver.assemble`` then
  ``track`` frame after frame, the loop timed.
* **pinmsk**: :func:`pinmsk.tools.inverse_kinematics.inverse_kinematics` on the imported model and
  the read .trc (the import and the file read outside the timing: compute = the task set-up, the
  solves, the marker errors, the result Trials).

Both CPU time (``time.process_time``: what the process spent, robust when other work shares the
machine) and wall time; the ratio is OpenSim's tool per frame over pinmsk's per frame.  It also prints
the largest RMS difference of the two motions (deg, mm).  Without ``../shared/data/opensim-models``
(or ``--data``) it says so and exits 0; without the optional peer ``opensim`` it times pinmsk only.
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
import xml.etree.ElementTree as ET  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_opensim as harness  # noqa: E402

from pinmsk.io.ik_tasks import ik_tasks_from_node  # noqa: E402
from pinmsk.io.opensim_setup import read_setup  # noqa: E402
from pinmsk.io.shared_data import shared_data_dir  # noqa: E402
from pinmsk.io.tables import read_trial  # noqa: E402
from pinmsk.io.trc import read_trc  # noqa: E402
from pinmsk.model import load_model  # noqa: E402
from pinmsk.tools.inverse_kinematics import inverse_kinematics, rotational_coordinates  # noqa: E402


def _best(fn, repeat: int):
    """(best CPU seconds, best wall seconds, last result) of ``repeat`` calls."""
    cpu, wall, out = float("inf"), float("inf"), None
    for _ in range(repeat):
        c0, w0 = time.process_time(), time.perf_counter()
        out = fn()
        cpu, wall = min(cpu, time.process_time() - c0), min(wall, time.perf_counter() - w0)
    return cpu, wall, out


def cases(data: Path, tmp: Path) -> list:
    """(label, setup path) of the example IK setups, each with absolute model and marker paths."""
    out = []
    g10 = data / "opensim-models" / "Gait10dof18musc" / "IK" / "walk_Setup_IK.xml"
    if g10.is_file():
        out.append(("gait10dof18musc walk", _absolute(g10, tmp / "g10_setup.xml")))
    g23 = data / "opensim-models" / "Gait2354Pipeline"
    if (g23 / "subject01_Setup_IK.xml").is_file():
        out.append(("gait2354 walk", _absolute(g23 / "subject01_Setup_IK.xml", tmp / "g23_setup.xml",
                                               model=g23 / "OutputReference" / "subject01_simbody.osim")))
    raj = data / "opensim-models" / "RajagopalWalk" / "subject_walk_scaled.osim"
    trc = data / "real" / "opensim-moco-walk-emg" / "markers_walk.trc"
    if raj.is_file() and trc.is_file():
        setup = tmp / "raj_setup.xml"
        setup.write_text(f'<?xml version="1.0" encoding="UTF-8" ?>\n<OpenSimDocument Version="40600">'
                         f'<InverseKinematicsTool name="raj"><model_file>{raj}</model_file>'
                         f'<marker_file>{trc}</marker_file><time_range>0.5 1.5</time_range>'
                         f'<output_motion_file>{tmp / "os_raj.mot"}</output_motion_file>'
                         f'<results_directory>{tmp}</results_directory><constraint_weight>Inf</constraint_weight>'
                         f'<accuracy>1e-5</accuracy></InverseKinematicsTool></OpenSimDocument>\n')
        out.append(("rajagopal walk (no task set)", setup))
    return out


def _absolute(setup: Path, dst: Path, model: Path | None = None) -> Path:
    """A copy of ``setup`` whose model and marker files are absolute paths (OpenSim resolves them from
    the working folder); ``model`` replaces a model file the setup names but its folder lacks."""
    root = ET.parse(setup).getroot()
    tool = root.find("InverseKinematicsTool")
    for prop, path in (("model_file", model), ("marker_file", None)):
        el = tool.find(prop)
        el.text = str(path if path is not None else (setup.parent / el.text.strip()).resolve())
    for prop in ("output_motion_file", "results_directory"):
        el = tool.find(prop)
        if el is not None:
            el.text = str(dst.parent / ("os_" + dst.stem + ".mot") if prop == "output_motion_file" else dst.parent)
    ET.ElementTree(root).write(dst)
    return dst


def opensim_tool(osim, setup: Path):
    tool = osim.InverseKinematicsTool(str(setup))
    with harness.quiet(osim):
        assert tool.run()
    return Path(tool.getOutputMotionFileName())


def opensim_solver(osim, setup: Path) -> int:
    """OpenSim's IK solver alone, as the tool sets it up (tasks -> references), frame after frame."""
    tool = osim.InverseKinematicsTool(str(setup))
    model = osim.Model(tool.get_model_file())
    state = model.initSystem()
    weights = osim.SetMarkerWeights()
    crefs = osim.SimTKArrayCoordinateReference()
    tasks = tool.getIKTaskSet()
    for i in range(tasks.getSize()):
        t = tasks.get(i)
        if not t.getApply():
            continue
        if t.getConcreteClassName() == "IKMarkerTask":
            weights.cloneAndAppend(osim.MarkerWeight(t.getName(), t.getWeight()))
        else:
            value = model.getCoordinateSet().get(t.getName()).getDefaultValue()
            ref = osim.CoordinateReference(t.getName(), osim.Constant(value))
            ref.setWeight(t.getWeight())
            crefs.push_back(ref)
    markers = osim.MarkersReference(tool.get_marker_file(), weights)
    solver = osim.InverseKinematicsSolver(model, markers, crefs, tool.get_constraint_weight())
    solver.setAccuracy(tool.get_accuracy())
    times = markers.getMarkerTable().getIndependentColumn()
    t0, t1 = tool.get_time_range(0), tool.get_time_range(1)
    frames = [t for t in times if t0 - 1e-9 <= t <= t1 + 1e-9]
    state.setTime(frames[0])
    solver.assemble(state)
    for t in frames:
        state.setTime(t)
        solver.track(state)
    return len(frames)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--data", type=Path, default=None, help="the shared data folder (default ../shared/data)")
    args = ap.parse_args(argv)
    data = args.data or shared_data_dir()
    if data is None or not (Path(data) / "opensim-models").is_dir():
        print("bench_ik: ../shared/data/opensim-models is absent; nothing to time")
        return 0
    osim, why = harness.import_opensim()
    print(f"machine: {harness.machine(osim)}")
    print(f"best of {args.repeat}; per frame, CPU time (wall time in brackets)")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for label, setup_path in cases(Path(data), tmp):
            setup = read_setup(setup_path)
            node = setup.node
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                model = load_model(node.file("model_file"))
            markers = read_trc(node.file("marker_file"), max_gap=0, warn=False)
            tasks = ik_tasks_from_node(node)
            span = node.numbers("time_range", 2)

            def ours():
                return inverse_kinematics(model, markers, tasks=tasks, time_range=span)

            ours()                               # warm-up (first calls of numpy and SciPy paths), not timed
            c_ours, w_ours, res = _best(ours, args.repeat)
            n = res.motion.n_frames
            print(f"{label}: {n} frames, {len(res.fitter.marker_rms_)} markers, "
                  f"{len(res.fitter.free_coordinates_)} coordinates solved")
            print(f"  pinmsk IK:                    {1e3 * c_ours / n:7.3f} ms  [{1e3 * w_ours / n:7.3f} ms]  "
                  f"({res.fitter.iterations_.mean():.1f} iterations per frame)")
            if osim is None:
                print(f"  OpenSim: {why}; its IK is not timed")
                continue
            rep = min(args.repeat, 2)
            c_tool, w_tool, mot = _best(lambda: opensim_tool(osim, setup_path), rep)
            with harness.quiet(osim):
                c_sol, w_sol, n_sol = _best(lambda: opensim_solver(osim, setup_path), rep)
            print(f"  OpenSim InverseKinematicsTool: {1e3 * c_tool / n:7.3f} ms  [{1e3 * w_tool / n:7.3f} ms]  "
                  f"-> pinmsk {c_tool / c_ours:.1f}x faster [{w_tool / w_ours:.1f}x]")
            print(f"  OpenSim solver loop alone:     {1e3 * c_sol / n_sol:7.3f} ms  [{1e3 * w_sol / n_sol:7.3f} ms]  "
                  f"-> pinmsk {c_sol / n_sol / (c_ours / n):.1f}x faster")
            rot = set(rotational_coordinates(model))
            ref = read_trial(mot, angular=rot)
            e_ours = res.errors["total_squared_error"]
            e_os = read_trial(Path(mot).parent / f"{setup.name}_ik_marker_errors.sto")["total_squared_error"]
            d_rot = max((np.rad2deg(np.sqrt(np.mean((res.motion[c] - ref[c]) ** 2))), c) for c in ref.names if c in rot)
            d_tra = max((np.sqrt(np.mean((res.motion[c] - ref[c]) ** 2)), c) for c in ref.names if c not in rot)
            print(f"  largest RMS difference from OpenSim's motion: {d_rot[0]:.4f} deg ({d_rot[1]}), "
                  f"{1e3 * d_tra[0]:.4f} mm or mrad ({d_tra[1]}); total squared marker error, pinmsk / OpenSim: "
                  f"{np.min(e_ours / e_os):.4f} to {np.max(e_ours / e_os):.4f} over the frames")
    return 0


if __name__ == "__main__":
    from _record import run
    sys.exit(run(main))
