"""OpenSim models in pinmsk: the model layer over the parsed ``.osim`` (:mod:`pinmsk.io.osim`).

* :mod:`.functions` -- OpenSim's Function types, evaluated exactly (value, first and second derivative);
* :mod:`.skeleton` -- the Pinocchio skeleton of an OpenSim model, its exact OpenSim kinematics, and
  the measured error of whatever a Pinocchio joint cannot hold exactly;
* :mod:`.report` -- :class:`ImportReport`, what became what and each approximation's error;
* :mod:`.importer` -- :func:`import_osim` (model + report) and :func:`write_import` (URDF + TOML sidecar).

Reading needs no ``opensim`` package; it is an optional peer for the tests that compare with OpenSim.
"""
from __future__ import annotations

from .._lazy import lazy_attributes

_EXPORTS = {
    "import_osim": "importer", "write_import": "importer", "ImportReport": "report",
    "ReportEntry": "report", "build_skeleton": "skeleton", "OsimKinematics": "skeleton",
    "from_osim": "functions",
}
__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_attributes(__name__, _EXPORTS, __all__)
