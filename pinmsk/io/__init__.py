"""Readers and writers: every file pinmsk reads or writes goes through this package.

* :mod:`.tables` -- Trials as CSV and OpenSim ``.sto`` / ``.mot`` (and ``.c3d`` reading);
* :mod:`.c3d` -- C3D markers, analogs and force platforms (optional ``ezc3d``);
* :mod:`.cleveland_gait` -- the Cleveland State University 2-D gait text files;
* :mod:`.external_loads` -- OpenSim ExternalLoads XML;
* :mod:`.channel_map` -- renaming a lab's columns onto a model (``--map``);
* :mod:`.toml_files` -- reading TOML (sidecars, marker sets, batch and task files) with key checks;
* :mod:`.output_files` -- atomic writes, JSON, output checks and roll-back;
* :mod:`.shared_data` -- where the optional shared data folder is.
"""
from __future__ import annotations

from .._lazy import lazy_attributes

_EXPORTS = {
    "read_trial": "tables", "write_trial": "tables", "read_sto_header": "tables",
    "StoHeader": "tables", "FORMATS": "tables", "C3D_PARTS": "tables",
    "state_path_coordinate": "tables", "check_precision": "tables", "DEFAULT_PRECISION": "tables",
    "atomic_write": "output_files", "write_json": "output_files", "check_output_file": "output_files",
    "output_folder": "output_files", "output_transaction": "output_files",
    "read_c3d": "c3d", "read_csu": "cleveland_gait", "read_external_loads": "external_loads",
    "read_mapped": "channel_map", "load_channel_map": "channel_map",
    "read_toml": "toml_files", "shared_data_dir": "shared_data",
}
__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_attributes(__name__, _EXPORTS, __all__)
