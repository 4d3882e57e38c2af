"""OpenSim's InverseDynamicsTool from its setup file.

The properties read (opensim-core ``OpenSim/Tools/InverseDynamicsTool.cpp``, ``DynamicsTool.cpp``):

==============================================  ==========================================================
property                                        honoured as
==============================================  ==========================================================
``model_file``                                  the ``.osim``, imported (:func:`pinmsk.model.load_model`)
``results_directory``, ``input_directory``      where results go / inputs resolve (the setup's folder)
``time_range``                                  the frames reported (OpenSim's ``findIndex`` rule)
``forces_to_exclude``                           ``All``, ``actuators``, ``Muscles`` or a force's name;
                                                a muscle left applying is refused (pinmsk applies none)
``external_loads_file``                         an ExternalLoads ``.xml``, its loads unfiltered, as
                                                OpenSim's tool applies them
``coordinates_file``                            ``.mot`` / ``.sto``, degrees as its header says
``coordinates_in_degrees``                      checked against the file's ``inDegrees``
``lowpass_cutoff_frequency_for_coordinates``    OpenSim's pad + IIR filter; negative = none
``output_gen_force_file``                       the result's name (``.sto`` added without extension)
``joints_to_report_body_forces``                refused when it names joints (not computed)
==============================================  ==========================================================

The result is OpenSim's: a storage ``Inverse Dynamics Generalized Forces`` with ``time`` and
each coordinate's generalized force, ``<coord>_moment`` for a rotation and ``<coord>_force``
for a translation, in OpenSim's coordinate order, computed by
:func:`pinmsk.dynamics.inverse_dynamics_result` on the coordinates as OpenSim filters them
(:func:`pinmsk.tools._common.opensim_filtered`; the padded frames give the splines their
ends), a coordinate the file lacks held at its default value, as OpenSim holds it.
"""
from __future__ import annotations

from pathlib import Path

from . import _common, layout

__all__ = ["run"]


def run(setup, *, results_dir=None) -> list[Path]:
    """Run an InverseDynamicsTool setup (see the module docstring); the file written, as a list."""
    from ..dynamics import inverse_dynamics_result

    node = setup.node
    folder = _common.input_folder(node)
    model_path = _common.model_file(node, folder=folder)
    start, end = _common.time_range(node)
    loads_path = node.file("external_loads_file", folder=folder)
    coords_path, declared = _common.coordinates_file(node, "coordinates_file", folder=folder,
                                                     degrees_prop="coordinates_in_degrees")
    cutoff = _common.lowpass_cutoff(node, "lowpass_cutoff_frequency_for_coordinates")
    name = _common.output_name(node, "output_gen_force_file", "inverse_dynamics.sto")
    out_dir = _common.results_folder(node, results_dir)
    if node.words("joints_to_report_body_forces"):
        raise node.error("joints_to_report_body_forces", "joints' equivalent body forces are not computed by "
                                                         "pinmsk; leave it empty")
    node.ignore("output_body_forces_file")      # written only for joints_to_report_body_forces
    exclude = node.words("forces_to_exclude")
    node.finish()

    # the muscles apply no force here (exclude_forces refuses a setup where they would): not imported
    model = _common.load_setup_model(node, model_path, muscles=False)
    choice = _common.exclude_forces(node, "forces_to_exclude", exclude, model, model_path)
    coords = _common.read_coordinates(node, "coordinates_file", coords_path, model, declared=declared,
                                      degrees_prop="coordinates_in_degrees")
    _common.check_range(node, "time_range", coords.time, start, end)
    trial = _common.opensim_filtered(coords, cutoff, str(coords_path))
    cut, keep, rows, kw = _common.loads_and_frames(node, loads_path, trial, start, end, "time_range")
    res = inverse_dynamics_result(choice.model, cut, cutoff=0, components=choice.components,
                                  missing_coordinates="default", **kw)
    table = layout.id_table(model, res.trial, rows=rows - keep[0])
    folder_out = _common.make_results_folder(out_dir)
    return [_common.write_storage(table, folder_out / name)]

