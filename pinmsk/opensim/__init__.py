"""OpenSim model layer: skeletons, functions, muscle paths and muscles built from an .osim document.

Below ``model.py`` (which builds the Model from these parts), above the reader :mod:`pinmsk.io.osim`:

* :mod:`.functions` -- OpenSim's Function types, evaluated exactly (value, first and second derivative);
* :mod:`.skeleton` -- the Pinocchio skeleton of an OpenSim model, OpenSim's exact kinematics, the
  measured error of whatever a Pinocchio joint cannot hold, and the map from OpenSim's coordinates;
* :mod:`.report` -- :class:`ImportReport`: what became what, and each approximation's error;
* :mod:`.importer` -- :func:`read_import` (the parts of an imported model) and :func:`write_import`
  (URDF + TOML sidecar); :func:`pinmsk.model.import_osim` and ``load_model("x.osim")`` use them;
* :mod:`.paths` -- geometric muscle paths and their polynomial surrogates;
* :mod:`.actuators` -- CoordinateActuator, PointActuator, TorqueActuator as pinmsk ideal actuators
  (the import hook, and OpenSim force set files such as ``*_Reserve_Actuators.xml``);
* :mod:`.contacts` -- :func:`contact_hook`: SmoothSphereHalfSpaceForce and HuntCrossleyForce as
  :mod:`pinmsk.contact` components (Simbody's laws), each sphere a frame on its body; a half space
  that moves and sphere-sphere contacts as :class:`pinmsk.effects.HuntCrossleyPair`.
* :mod:`.forces` -- :func:`force_hook`: CoordinateLimitForce, BushingForce, PointToPointSpring,
  SpringGeneralizedForce and ExpressionBasedCoordinateForce as effects.
* :mod:`.scaling` -- OpenSim's ScaleTool scaling: scale factors from marker measurements and manual
  scales, and the scaled ``.osim`` (bodies, joints, markers, paths, wrap objects, masses, muscles)
  with its scale set (the setup runner is :mod:`pinmsk.tools.scale`).

Reading needs no ``opensim`` package; it is an optional peer for the tests that compare with OpenSim.
"""
from __future__ import annotations

from .._lazy import lazy_attributes

_EXPORTS = {
    "read_import": "importer", "write_import": "importer", "ImportReport": "report", "ReportEntry": "report",
    "build_skeleton": "skeleton", "OsimKinematics": "skeleton", "CoordinateMap": "skeleton",
    "from_osim": "functions", "contact_hook": "contacts", "read_actuators": "actuators",
    "actuator_hook": "actuators", "force_hook": "forces",
}
__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_attributes(__name__, _EXPORTS, __all__)
