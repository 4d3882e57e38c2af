"""OpenSim's tools run from their setup files: ``pinmsk run SETUP.xml``.

:func:`run_setup` reads a setup (:func:`pinmsk.io.opensim_setup.read_setup`),
finds the runner of its tool (the root's first element) and runs it; each
runner is a module of this package with ``run(setup, *, results_dir=None) ->
list[Path]`` that reads every property it honours, refuses the others by
name (:meth:`~pinmsk.io.opensim_setup.SetupNode.finish`) and writes its
results as OpenSim's tool names and lays them out.

=======================  =====================================================
tool                     runner
=======================  =====================================================
InverseDynamicsTool      :mod:`pinmsk.tools.inverse_dynamics`
AnalyzeTool              :mod:`pinmsk.tools.analyze` (StaticOptimization, MuscleAnalysis)
InverseKinematicsTool    :mod:`pinmsk.tools.inverse_kinematics`
ScaleTool                :mod:`pinmsk.tools.scale`
=======================  =====================================================

Paths in a setup resolve against the setup file's folder, as OpenSim's tools
resolve them; ``results_dir`` replaces the setup's ``<results_directory>``.
"""
from __future__ import annotations

import importlib
from pathlib import Path

from ..io.opensim_setup import SetupError, read_setup

__all__ = ["run_setup", "RUNNERS"]

#: OpenSim tool tag -> module of this package that runs it.
RUNNERS = {
    "InverseDynamicsTool": "inverse_dynamics",
    "AnalyzeTool": "analyze",
    "InverseKinematicsTool": "inverse_kinematics",
    "ScaleTool": "scale",
}


def _runner(setup):
    module = RUNNERS.get(setup.tool)
    if module is None:
        raise SetupError(f"{setup.path}: <{setup.tool}> is not a tool pinmsk runs "
                         f"(it runs {', '.join('<' + t + '>' for t in RUNNERS)})")
    name = f"{__name__}.{module}"
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as exc:
        if exc.name != name:
            raise
        raise SetupError(f"{setup.path}: <{setup.tool}> has no runner in this pinmsk "
                         f"(the module {name} is absent)") from None


def run_setup(path, *, results_dir=None) -> list[Path]:
    """Run the OpenSim setup file ``path``; the files written, in order.

    ``results_dir`` (optional) is the folder the results go to instead of the setup's
    ``<results_directory>``.  A setup that cannot be run as written (an unknown tool, a
    property pinmsk does not honour, a missing file) raises
    :class:`~pinmsk.io.opensim_setup.SetupError` naming it, before anything is written.
    """
    setup = read_setup(path)
    return list(_runner(setup).run(setup, results_dir=results_dir))
