"""Interactive 3-D viewer: a model, its muscles and a trial in meshcat.

Built on Pinocchio's :class:`~pinocchio.visualize.MeshcatVisualizer` (which
places the skeleton's visual geometry) and meshcat's own server, which serves
the bundled JavaScript viewer on localhost, so no network is needed::

    viewer = pinmsk.presentation.viewer.Viewer(pinmsk.load_model("forearm"))   # prints the URL
    viewer.display(q)                                  # one configuration
    viewer.play(trial, results=so_results)             # animation + time slider
    viewer.jupyter_cell()                              # in a notebook cell

Scene (paths under meshcat's ``/meshcat``)::

    pinmsk                              model frame -> z-up world (y-up models stand up)
    pinmsk/ground                       the ground plane
    pinmsk/model/skeleton/visuals/<geometry>   bodies (Pinocchio's MeshcatVisualizer)
    pinmsk/model/skeleton/visuals/wrap_<name>  wrap objects of an imported OpenSim model
    pinmsk/model/muscles/<muscle>/seg<i>/c<k>  muscle polylines; colour level k of 0..levels-1
    pinmsk/model/muscles/<muscle>/seg<i>/red   ... in muscle red, shown while no activation is known
    pinmsk/model/contacts/<n>                  contact spheres
    pinmsk/model/residuals/<coord>/c<k>        joint residual markers, colour level k
    pinmsk/ghost/skeleton/visuals/<geometry>   second motion (translucent), optional offset
    pinmsk/grf/<side>/shaft, head              ground reaction force arrows

Colours: activation (or force / f_max, or |residual| / scale) in [0, 1] maps to
``levels`` discrete colours from blue (0) to red (1); a muscle without one is muscle red.  Each level is its own
mesh whose visibility is switched, so animated colours also reach a browser
that connects after the animation was sent (meshcat re-sends the scene to late
clients with the animation before the objects, which breaks material tracks).

Muscles are polylines drawn as one cylinder per segment (meshcat animates
transforms and properties, not vertex buffers, so a line strip could not follow
the motion in an animation or a saved page).  Their vertices come from the
model's path geometry (:func:`muscle_polylines`): the display points of a
built-in model or sidecar (fixed in bodies), or, for a model imported from an
OpenSim ``.osim``, its geometric paths (:meth:`pinmsk.opensim.paths.GeometricPaths.polylines`:
active points, tangent points and points along the wrapped arcs, OpenSim's
path algorithm) for all frames of a trial in one batch; for the sidecar ``pinmsk
import`` wrote, those of the ``.osim`` it names (``[model] osim``; a warning says so
if that file is gone or changed since).  Muscles whose paths
are only functions of the coordinates (no display points) are named in a
warning, not drawn.  An imported model's bodies are capsules between its joints
(OpenSim's ``.vtp`` meshes are not read) and its wrap objects translucent
cylinders, spheres and ellipsoids.

Channels used (see DESIGN.md): coordinates by name; ``<muscle>_activation``
or ``<muscle>_force``; ``<coord>_residual``; ``ground_force_v[xyz]`` and
``ground_force_p[xyz]`` with an optional side prefix.
"""
from __future__ import annotations

import base64
import contextlib
import difflib
import io
import os
import re
import signal
import sys
import threading
import time
import warnings
from collections import namedtuple
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pinocchio as pin

from ..errors import ModelError, TrialError
from ..io.tables import read_trial
from ..model import Model, load_model
from ..trial import Trial, parse_ground_reaction
from . import viewer_geometry as vg

__all__ = ["Viewer", "ViewerCommand", "view_cli", "default_ground_height", "muscle_polylines"]

#: One command sent to the meshcat server: ``kind`` (``set_object``, ``set_transform``,
#: ``set_property``, ``set_animation``, ``delete``), the node ``path`` and a detail
#: (the property name, or the animated paths of a ``set_animation``).
ViewerCommand = namedtuple("ViewerCommand", "kind path detail")

_KIND = {"SetObject": "set_object", "SetTransform": "set_transform", "SetProperty": "set_property",
         "SetAnimation": "set_animation", "Delete": "delete", "DaeMeshGeometry": "set_object"}

BONE = (0.89, 0.85, 0.79, 1.0)
GHOST = (0.45, 0.75, 1.0, 0.35)
GROUND = 0x7f8c99
CONTACT = 0xe0c020
GRF = 0x22bb44
MUSCLE_RED = 0xcc1a1a
WRAP = (0.35, 0.8, 0.95, 0.35)


class Viewer:
    """A meshcat scene of one model. Starts (or connects to) a meshcat server.

    Parameters (keyword-only)
    -------------------------
    zmq_url : connect to a running ``meshcat-server`` instead of starting one.
    open_browser : open the URL in a browser; ignored on a machine without a
        display (no ``DISPLAY``/``WAYLAND_DISPLAY`` on Linux).
    ground : draw the ground plane (at :func:`default_ground_height` unless
        ``ground_height`` is given, in metres along the model's up axis).
    levels : number of discrete colours for activations/forces/residuals.
    skeleton_opacity : opacity of the bones (default 0.6 for models with muscles,
        whose display points often lie inside the bones' visuals, else 1).
    arc_points : segments drawn along each wrapped arc of an imported model's paths.
    wrap_objects : draw an imported model's wrap objects (tori are not drawn: named in a warning).
    quiet : do not print the URL.

    Attributes: ``url``, ``model``, ``visual_model`` (the Pinocchio
    GeometryModel shown), ``commands`` (a list of :data:`ViewerCommand`, every
    command sent, for tests and debugging), ``vis`` (the meshcat Visualizer)
    and ``viz`` (Pinocchio's MeshcatVisualizer).
    """

    def __init__(self, model, *, zmq_url: str | None = None, open_browser: bool = False,
                 ground: bool = True, ground_height: float | None = None, levels: int = 8,
                 skeleton_opacity: float | None = None, arc_points: int = 8, wrap_objects: bool = True,
                 quiet: bool = False):
        import meshcat

        self.model = model
        self.levels = int(levels)
        self._colors = vg.color_levels(self.levels)
        self.commands: list[ViewerCommand] = []
        self.up_axis = str(model.meta.get("up_axis", "z"))
        self._up = vg.up_index(self.up_axis)
        self._closed = False
        self._level_state: dict[str, int] = {}
        self._residual_built = False
        self._grf_sides: list[str] = []
        self._ghost_viz = None
        self._ghost_offset = np.zeros(3)

        self._polylines = muscle_polylines(model, arc_points=arc_points)
        self.visual_model = build_visual_model(model)
        if skeleton_opacity is None:
            # muscle display points lie inside the bones' visuals: let them show through
            drawn = getattr(model, "muscles", None) is not None or self._polylines is not None
            skeleton_opacity = 0.6 if drawn else 1.0
        for g in self.visual_model.geometryObjects:
            g.meshColor = np.concatenate([np.asarray(g.meshColor[:3]), [float(skeleton_opacity)]])
        if wrap_objects and getattr(self._polylines, "paths", None) is not None:
            add_wrap_objects(self.visual_model, model, self._polylines.paths)
        self.vis = meshcat.Visualizer(zmq_url=zmq_url) if zmq_url else _start_quietly(meshcat)
        self._record(self.vis.window)
        self.url = self.vis.url()
        try:
            self._setup(quiet=quiet, open_browser=open_browser, ground=ground, ground_height=ground_height)
        except BaseException:
            self.close()
            raise

    def _setup(self, *, quiet, open_browser, ground, ground_height) -> None:
        from pinocchio.visualize import MeshcatVisualizer

        model = self.model
        if not quiet:
            print(f"pinmsk viewer: {self.url}", flush=True)
        if open_browser:
            if _has_display():
                self.vis.open()
            elif not quiet:
                print("pinmsk viewer: no display found; open the URL above in a browser", flush=True)

        self.vis["/Grid"].set_property("visible", False)
        self.vis["/Axes"].set_property("visible", False)
        self._root = "pinmsk"
        self.vis[self._root].set_transform(vg.up_rotation(self.up_axis))

        self.viz = MeshcatVisualizer(model.pin, None, self.visual_model)
        self.viz.initViewer(viewer=self.vis[f"{self._root}/model"])
        self.viz.loadViewerModel(rootNodeName="skeleton")

        self._q0 = neutral_configuration(model.pin)
        self._build_muscles()
        self._contacts = self._build_contacts()
        self._joint_ids = {c: model.pin.getJointId(c) for c in model.coordinates}

        self.ground_height = (default_ground_height(model, self.visual_model, self._q0)
                              if ground_height is None else float(ground_height))
        self._ground = bool(ground)
        if ground:
            self._build_ground()
        self.display(self._q0)
        self.frame_camera([self._q0])

    # ------------------------------------------------------------------ setup
    def _record(self, window) -> None:
        send = window.send
        log = self.commands

        def recording_send(command):
            kind = _KIND.get(type(command).__name__, type(command).__name__)
            if kind == "set_animation":
                detail = tuple(p.lower() for p in command.animation.clips)
                log.append(ViewerCommand(kind, "", detail))
            else:
                path = getattr(command, "path", None)
                path = path.lower() if hasattr(path, "lower") and not isinstance(path, str) else path
                log.append(ViewerCommand(kind, path or "", getattr(command, "key", None)))
            return send(command)

        window.send = recording_send

    def _node(self, rel: str):
        return self.vis[f"{self._root}/{rel}"]

    def _build_muscles(self) -> None:
        """The segment table of every drawn muscle, with the segments the neutral pose needs."""
        self._muscle_segments: dict[str, tuple[float, list[str]]] = {}
        self._coloured: set[str] = set()
        src = self._polylines
        if src is None:
            return
        for name, radius in zip(src.names, src.radii):
            self._muscle_segments[name] = (float(radius), [])
            self._level_state[f"muscle:{name}"] = NO_LEVEL
        for name, pts in src(self._q0[None]).items():
            self._ensure_segments(name, pts.shape[1] - 1)

    def _ensure_segments(self, name: str, n: int) -> None:
        """Create segments of muscle ``name`` up to ``n`` (each with its muscle-red mesh, and its colour
        levels once the muscle has been coloured)."""
        _, segs = self._muscle_segments[name]
        levels = [*range(self.levels), NO_LEVEL] if name in self._coloured else [NO_LEVEL]
        for i in range(len(segs), n):
            path = f"model/muscles/{name}/seg{i}"
            self._level_meshes(name, path, levels)
            segs.append(path)

    def _ensure_levels(self, name: str) -> None:
        """The colour-level meshes of muscle ``name`` (made at its first colour: a muscle never coloured
        has only its muscle-red mesh, one meshcat object per segment instead of ``levels + 1``)."""
        if name in self._coloured:
            return
        self._coloured.add(name)
        for path in self._muscle_segments[name][1]:
            self._level_meshes(name, path, range(self.levels))

    def _level_meshes(self, name: str, path: str, levels) -> None:
        import meshcat.geometry as mg

        shown = self._level_state.get(f"muscle:{name}", NO_LEVEL)
        for k in levels:
            color = MUSCLE_RED if k == NO_LEVEL else vg.rgb_to_int(self._colors[k])
            node = self._node(f"{path}/{_level_node(k)}")
            node.set_object(mg.Cylinder(1.0, 1.0), mg.MeshLambertMaterial(color=color))
            if k != shown:
                node.set_property("visible", False)

    def muscle_polylines(self, q) -> dict[str, np.ndarray]:
        """``{muscle: (N, K, 3)}``: the vertices of each drawn muscle at configurations ``q`` (N, nq),
        in the model frame (fewer vertices in a frame repeat its last one)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        return {} if self._polylines is None else self._polylines(q)

    def _build_contacts(self):
        import meshcat.geometry as mg

        spheres = contact_spheres(self.model)
        for k, (label, fid, pos, radius) in enumerate(spheres):
            self._node(f"model/contacts/c{k}").set_object(
                mg.Sphere(radius), mg.MeshLambertMaterial(color=CONTACT, opacity=0.8, transparent=True))
        return spheres

    def _build_ground(self, qs: Sequence[np.ndarray] | None = None) -> None:
        """The ground plane: a thin box under the model at configurations ``qs``, 1 m margin."""
        import meshcat.geometry as mg

        qs = [self._q0] if qs is None else qs
        pts = np.concatenate([vg.geometry_points(self.model.pin, self.visual_model, q) for q in qs])
        span = np.ptp(pts, axis=0) + 2.0
        dims = [float(np.clip(x, 2.0, 50.0)) for x in span]
        dims[self._up] = 0.005
        T = np.eye(4)
        T[self._up, 3] = self.ground_height - 0.0025
        centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
        for ax in range(3):
            if ax != self._up:
                T[ax, 3] = centre[ax]
        node = self._node("ground")
        node.set_object(mg.Box(dims), mg.MeshLambertMaterial(color=GROUND, opacity=0.6, transparent=True))
        node.set_transform(T)

    def _build_residuals(self) -> None:
        import meshcat.geometry as mg

        if self._residual_built:
            return
        pts = vg.geometry_points(self.model.pin, self.visual_model, self._q0)
        r = float(np.clip(0.03 * np.ptp(pts, axis=0).max(), 0.012, 0.05))
        for c in self.model.coordinates:
            for k in range(self.levels):
                node = self._node(f"model/residuals/{c}/c{k}")
                node.set_object(mg.Sphere(r), mg.MeshLambertMaterial(color=vg.rgb_to_int(self._colors[k]),
                                                                     opacity=0.85, transparent=True))
                if k:
                    node.set_property("visible", False)
            self._level_state[f"residual:{c}"] = 0
        self._residual_built = True

    def _build_ghost(self, offset) -> None:
        from pinocchio.visualize import MeshcatVisualizer

        self._ghost_offset = self._offset_vector(offset)
        T = np.eye(4)
        T[:3, 3] = self._ghost_offset
        self._node("ghost").set_transform(T)
        if self._ghost_viz is None:
            self._ghost_viz = MeshcatVisualizer(self.model.pin, None, self.visual_model.copy())
            self._ghost_viz.initViewer(viewer=self.vis[f"{self._root}/ghost"])
            self._ghost_viz.loadViewerModel(rootNodeName="skeleton", visual_color=list(GHOST))

    def _offset_vector(self, offset) -> np.ndarray:
        if np.ndim(offset) == 0:
            return float(offset) * vg.left_vector(self.up_axis)
        v = np.asarray(offset, dtype=float)
        if v.shape != (3,):
            raise ValueError(f"ghost offset must be a number (lateral, m) or 3 numbers, got {offset!r}")
        return v

    def _build_grf(self, sides: Sequence[str]) -> None:
        import meshcat.geometry as mg

        for side in sides:
            if side in self._grf_sides:
                continue
            mat = mg.MeshLambertMaterial(color=GRF)
            self._node(f"grf/{_side_key(side)}/shaft").set_object(mg.Cylinder(1.0, 1.0), mat)
            self._node(f"grf/{_side_key(side)}/head").set_object(
                mg.Cylinder(self._grf_head, radiusTop=0.0, radiusBottom=2.2 * self._grf_radius), mat)
            self._grf_sides.append(side)

    _grf_radius = 0.012
    _grf_head = 0.06

    # ------------------------------------------------------------- display
    @property
    def muscle_paths(self) -> dict[str, list[str]]:
        """Scene paths (relative to ``pinmsk/``) of each muscle's segments."""
        return {n: list(segs) for n, (_, segs) in self._muscle_segments.items()}

    def display(self, q=None, *, activation=None, force=None, residual=None, residual_scale=None,
                ghost_q=None, ghost_offset=0.0, grf: Mapping | None = None):
        """Show configuration ``q``: ``(nq,)`` or ``{coordinate: value}`` (default: neutral,
        inside the joint limits; coordinates not named stay neutral).

        ``activation`` / ``force``: per-muscle values, an ``(n_muscles,)`` array or a
        ``{muscle: value}`` dict (force is shown as force / f_max).  ``residual``:
        ``(nv,)`` or ``{coord: value}``; coloured as ``|r| / residual_scale``
        (default: the largest |r|).  ``ghost_q``: a second configuration drawn
        translucent, shifted ``ghost_offset`` metres to the subject's left (away from
        the camera), or by a 3-vector in the model frame.
        ``grf``: ``{side: (force_xyz, point_xyz)}`` in the model frame.
        """
        if isinstance(q, Mapping):
            q = self._configuration_from(q)
        q = self._q0 if q is None else self._check_q(q, "q")
        self.viz.display(q)
        data = self.model.pin.createData()
        pin.framesForwardKinematics(self.model.pin, data, q)
        values = self._muscle_values(activation, force)
        for name, pts in self.muscle_polylines(q).items():
            self._ensure_segments(name, pts.shape[1] - 1)
            radius, segs = self._muscle_segments[name]
            pos, quat, size = segment_keys(_pad_vertices(pts, len(segs) + 1), radius)
            for i, path in enumerate(segs):
                self._node(path).set_transform(_scaled_matrix(pos[0, i], quat[0, i], size[0, i]))
            if values is not None:
                self._build_legend("force / max isometric force" if activation is None else "activation")
                self._ensure_levels(name)
                self._set_level(f"muscle:{name}", segs, values.get(name, 0.0))
        for k, (label, fid, pos, radius) in enumerate(self._contacts):
            T = np.eye(4)
            T[:3, 3] = data.oMf[fid].act(pos)
            self._node(f"model/contacts/c{k}").set_transform(T)
        if residual is not None:
            self._build_residuals()
            r = self._per_coordinate(residual, "residual")
            scale = residual_scale or (np.nanmax(np.abs(r)) if np.any(np.abs(r) > 0) else 1.0)
            for c, val in zip(self.model.coordinates, r):
                T = np.eye(4)
                T[:3, 3] = data.oMi[self._joint_ids[c]].translation
                self._node(f"model/residuals/{c}").set_transform(T)
                self._set_level(f"residual:{c}", [f"model/residuals/{c}"], abs(val) / scale)
        if ghost_q is not None:
            self._build_ghost(ghost_offset)
            self._ghost_viz.display(self._check_q(ghost_q, "ghost_q"))
        if grf:
            self._build_grf(list(grf))
            for side, (force_xyz, point_xyz) in grf.items():
                self._set_grf(side, force_xyz, point_xyz, self._grf_scale())
        return self

    def _set_level(self, key: str, paths: Sequence[str], value: float | None) -> None:
        """Show colour level ``value`` in [0, 1] (None: the muscle red of no value) of nodes ``paths``."""
        level = NO_LEVEL if value is None else int(vg.level_of([value], self.levels)[0])
        old = self._level_state.get(key, 0)
        if level == old:
            return
        for p in paths:
            self._node(f"{p}/{_level_node(old)}").set_property("visible", False)
            self._node(f"{p}/{_level_node(level)}").set_property("visible", True)
        self._level_state[key] = level

    def _set_grf(self, side, force_xyz, point_xyz, scale) -> None:
        shaft, head = vg.arrow_transforms(point_xyz, force_xyz, scale=scale, radius=self._grf_radius,
                                          head_length=self._grf_head)
        self._node(f"grf/{_side_key(side)}/shaft").set_transform(shaft)
        self._node(f"grf/{_side_key(side)}/head").set_transform(head)

    def _grf_scale(self) -> float:
        """Arrow length per newton: body weight -> 1 m."""
        mass = float(sum(i.mass for i in self.model.pin.inertias))
        g = float(np.linalg.norm(self.model.pin.gravity.linear)) or 9.81
        return 1.0 / (mass * g) if mass > 0 else 1e-3

    def _configuration_from(self, values: Mapping[str, float]) -> np.ndarray:
        """``{coordinate: value}`` -> q (unnamed coordinates at their neutral value)."""
        unknown = sorted(set(values) - set(self.model.coordinates))
        if unknown:
            raise ModelError(f"unknown coordinates {unknown} (coordinates: {', '.join(self.model.coordinates)})")
        q = self._q0.copy()
        for c, val in values.items():
            q[self.model.pin.joints[self._joint_ids[c]].idx_q] = float(val)
        return q

    def _check_q(self, q, what: str) -> np.ndarray:
        q = np.asarray(q, dtype=float).reshape(-1)
        if q.shape != (self.model.pin.nq,):
            raise ModelError(f"{what} has {q.size} values; model '{self.model.name}' has nq = "
                             f"{self.model.pin.nq} ({', '.join(self.model.coordinates)})")
        pm = self.model.pin
        return _require_finite(q, [pm.names[j] for j in range(1, pm.njoints) for _ in range(pm.joints[j].nq)],
                               what)

    def _muscle_values(self, activation, force):
        if activation is None and force is None:
            return None
        m = self.model.muscles
        if m is None and (force is not None or not self._muscle_segments):
            raise ModelError(f"model '{self.model.name}' has no muscles to colour"
                             + (" by force (no f_max without its muscle models)" if self._muscle_segments else ""))
        if activation is not None:
            vals = self._per_muscle(activation, "activation")
        else:
            vals = self._per_muscle(force, "force") / np.asarray(m.f_max, dtype=float)
        return dict(zip(self._colour_names, vals))

    @property
    def _colour_names(self) -> tuple[str, ...]:
        """The muscles activations name: the model's, or the drawn paths' of a model without muscle models."""
        m = self.model.muscles
        return tuple(m.names) if m is not None else tuple(self._muscle_segments)

    def _per_muscle(self, x, what) -> np.ndarray:
        return _per_name(x, self._colour_names, what, "muscles")

    def _per_coordinate(self, x, what) -> np.ndarray:
        return _per_name(x, self.model.coordinates, what, "coordinates")

    # ---------------------------------------------------------------- play
    def play(self, trial, *, results=None, ghost=None, ghost_offset=0.0, residual=None,
             residual_scale=None, fps: float = 60.0, speed: float = 1.0, play: bool = True,
             repetitions: int = 1):
        """Send ``trial`` as a meshcat animation (time slider in the viewer's controls).

        Key frames are at the trial's own times (resampled to at most ``fps``
        per second), in seconds, so the animation runs at real time (``speed``
        > 1 plays faster).  ``results`` is a second Trial (e.g. static
        optimisation output) with ``<muscle>_activation`` or ``<muscle>_force``
        channels, ``<coord>_residual`` and/or ground reaction channels; it is
        interpolated onto the trial's times.  ``ghost``: a second Trial of the
        same model (e.g. the simulated motion) drawn translucent, shifted
        ``ghost_offset`` metres to the subject's left (0: overlaid; a 3-vector: any shift).  ``residual``: an ``(N, nv)`` array
        on the trial's times, instead of ``<coord>_residual`` channels.
        Returns the ``meshcat.animation.Animation`` sent.
        """
        from meshcat.animation import Animation

        model = self.model
        t_src = np.asarray(trial.time, dtype=float)
        if t_src.size < 2:
            raise TrialError("play: the trial needs at least 2 frames")
        t = _playback_times(t_src, fps)
        q = _interp_columns(t, t_src, _coordinates_of(trial, model, "trial"))
        sources = [s for s in (results, trial) if s is not None]
        values = self._muscle_channels(sources, t)
        res = None
        if residual is not None:
            arr = np.asarray(residual, dtype=float)
            if arr.shape != (t_src.size, model.nv):
                raise TrialError(f"residual must be (N, nv) = ({t_src.size}, {model.nv}), got {arr.shape}")
            bad = np.argwhere(~np.isfinite(arr))
            if bad.size:
                i, j = bad[0]
                raise TrialError(f"residual of coordinate {model.coordinates[j]!r} is {float(arr[i, j])!r} at "
                                 f"frame {i} (time {t_src[i]:.6g} s); {_NO_NAN}")
            res = _interp_columns(t, t_src, arr)
        else:
            res = _channels_on(sources, [f"{c}_residual" for c in model.coordinates], t)
        grf = _grf_on(sources, t)
        gq = None
        if ghost is not None:
            gq = _interp_columns(t, np.asarray(ghost.time, dtype=float), _coordinates_of(ghost, model, "ghost"))
            self._build_ghost(ghost_offset)
        if res is not None:
            self._build_residuals()
            scale = residual_scale or (np.nanmax(np.abs(res)) if np.any(np.abs(res) > 0) else 1.0)
            res_levels = vg.level_of(np.abs(res) / scale, self.levels)
        if grf:
            self._build_grf(list(grf))

        lines = self.muscle_polylines(q)         # every frame's muscle vertices in one batch
        for name, pts in lines.items():
            if name in values:
                self._ensure_levels(name)
            self._ensure_segments(name, pts.shape[1] - 1)
        anim = Animation(default_framerate=1)  # key times in seconds
        key_t = (t - t[0]) / float(speed)
        data = model.pin.createData()
        gm = self.visual_model
        gdata = gm.createData()
        gnames = [self.viz.getViewerNodeName(g, pin.GeometryType.VISUAL) for g in gm.geometryObjects]
        ghost_names = ([self._ghost_viz.getViewerNodeName(g, pin.GeometryType.VISUAL)
                        for g in self._ghost_viz.visual_model.geometryObjects] if gq is not None else [])
        scales = [g.meshScale for g in gm.geometryObjects]
        moving = [g.parentJoint != 0 for g in gm.geometryObjects]
        gscale = self._grf_scale()
        from pinocchio.visualize.meshcat_visualizer import applyScalingOnHomegeneousTransform as scaled
        for i, tk in enumerate(key_t):
            frame = anim.at_frame(self.vis, float(tk))
            pin.framesForwardKinematics(model.pin, data, q[i])
            pin.updateGeometryPlacements(model.pin, data, gm, gdata)
            for name, M, s, mov in zip(gnames, gdata.oMg, scales, moving):
                if mov:
                    frame[f"{self._root}/model/{name}"].set_transform(scaled(M.homogeneous, s))
            for k, (label, fid, pos, radius) in enumerate(self._contacts):
                T = np.eye(4)
                T[:3, 3] = data.oMf[fid].act(pos)
                frame[f"{self._root}/model/contacts/c{k}"].set_transform(T)
            if res is not None:
                for c in model.coordinates:
                    T = np.eye(4)
                    T[:3, 3] = data.oMi[self._joint_ids[c]].translation
                    frame[f"{self._root}/model/residuals/{c}"].set_transform(T)
            if gq is not None:
                pin.framesForwardKinematics(model.pin, data, gq[i])
                pin.updateGeometryPlacements(model.pin, data, gm, gdata)
                for name, M, s, mov in zip(ghost_names, gdata.oMg, scales, moving):
                    if mov:
                        frame[f"{self._root}/ghost/{name}"].set_transform(scaled(M.homogeneous, s))
            for side, (F, P) in grf.items():
                shaft, head = vg.arrow_transforms(P[i], F[i], scale=gscale, radius=self._grf_radius,
                                                  head_length=self._grf_head)
                _set_scaled(frame[f"{self._root}/grf/{_side_key(side)}/shaft"], shaft)
                _set_scaled(frame[f"{self._root}/grf/{_side_key(side)}/head"], head)
        for name, pts in lines.items():
            radius, segs = self._muscle_segments[name]
            pos, quat, size = segment_keys(_pad_vertices(pts, len(segs) + 1), radius)
            for i, path in enumerate(segs):
                _set_tracks(anim, self.vis, f"{self._root}/{path}", key_t, position=pos[:, i], quaternion=quat[:, i],
                            scale=size[:, i])
        self.played_polylines = lines
        # colours: visibility of the level meshes, keyed only where the level changes
        for mname, (radius, segs) in self._muscle_segments.items():
            if mname in values:
                lv = vg.level_of(values[mname], self.levels)
                for path in segs:
                    self._visibility_tracks(anim, key_t, lv, path, hide=(_level_node(NO_LEVEL),))
        if res is not None:
            for j, c in enumerate(model.coordinates):
                self._visibility_tracks(anim, key_t, res_levels[:, j], f"model/residuals/{c}")
        # the static scene shows the first frame (what a paused animation and late clients see)
        self.display(q[0], activation={n: v[0] for n, v in values.items()} if values else None,
                     residual=None if res is None else np.abs(res[0]), residual_scale=scale if res is not None else None,
                     ghost_q=None if gq is None else gq[0], ghost_offset=ghost_offset,
                     grf={side: (F[0], P[0]) for side, (F, P) in grf.items()} or None)
        if values:
            forces_only = not any(n.endswith("_activation") for s in sources for n in s.names)
            self._build_legend("force / max isometric force" if forces_only else "activation")
        for mname, (radius, segs) in self._muscle_segments.items():
            if mname not in values:
                self._set_level(f"muscle:{mname}", segs, None)
        self.vis.set_animation(anim, play=play, repetitions=repetitions)
        samples = q[:: max(1, len(q) // 10)]
        if self._ground:
            self._build_ground(samples)
        self.frame_camera(samples)
        return anim

    def _visibility_tracks(self, anim, key_t, lv, path, hide: Sequence[str] = ()) -> None:
        """Level k of ``path`` visible where ``lv`` is k (keys where it changes); the ``hide`` children hidden."""
        changes = np.flatnonzero(np.diff(lv)) + 1
        idx = np.concatenate([[0], changes, [len(lv) - 1]])
        for k in range(self.levels):
            node = f"{self._root}/{path}/c{k}"
            for i in idx:
                anim.at_frame(self.vis, float(key_t[i]))[node].set_property("visible", "boolean",
                                                                           bool(lv[i] == k))
        for child in hide:
            for i in (0, len(lv) - 1):
                anim.at_frame(self.vis, float(key_t[i]))[f"{self._root}/{path}/{child}"].set_property(
                    "visible", "boolean", False)

    def _muscle_channels(self, sources, t) -> dict[str, np.ndarray]:
        m = self.model.muscles
        f_max = {} if m is None else dict(zip(m.names, np.asarray(m.f_max, dtype=float)))
        out = {}
        for n in self._colour_names:
            act = _channels_on(sources, [f"{n}_activation"], t)
            if act is not None:
                out[n] = act[:, 0]
                continue
            force = _channels_on(sources, [f"{n}_force"], t) if n in f_max else None
            if force is not None:
                out[n] = force[:, 0] / f_max[n]
        return out

    # -------------------------------------------------------------- camera
    def _build_legend(self, label: str) -> None:
        """A colour bar of the muscle colour levels (0 at the bottom, 1 at the top) with ``label``,
        standing beside the model and facing the camera (node ``/legend``; drawn once)."""
        if getattr(self, "_legend", None) == label:
            return
        import meshcat.geometry as mg

        cache = self.__dict__.setdefault("_legend_pngs", {})
        if label not in cache:
            cache[label] = legend_png(self._colors, label)
        self._legend_png = cache[label]
        self._legend = label
        self._place_legend()

    def _place_legend(self) -> None:
        """Stand the legend beside the model (to its left on the screen), its face towards the camera."""
        if getattr(self, "_legend", None) is None:
            return
        import meshcat.geometry as mg

        extent = getattr(self, "_extent", 1.0)
        h = 0.5 * extent                       # half the model's size
        self.vis["legend"].set_object(
            mg.Box([h * LEGEND_ASPECT, h, 0.001]),
            mg.MeshBasicMaterial(map=mg.ImageTexture(mg.PngImage(self._legend_png)), transparent=True))
        view = getattr(self, "_view", np.array([0.7, -1.0, 0.35]))
        extent = getattr(self, "_extent", 1.0)
        yaw = np.arctan2(view[1], view[0])
        right = np.array([np.sin(yaw), -np.cos(yaw), 0.0])
        # the box's face (+z) turned towards the camera, its image upright along world z
        face = np.array([np.cos(yaw), np.sin(yaw), 0.0])
        R = np.column_stack([-right, [0.0, 0.0, 1.0], face])
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = 0.55 * extent * right        # 'right' of the view direction: the screen's left
        self.vis["legend"].set_transform(T)

    def frame_camera(self, qs: Sequence[np.ndarray] | None = None, *, distance: float | None = None) -> None:
        """Point the camera at the model (at configurations ``qs``), seen from its right side.

        The scene root is translated so that the model's centre is at meshcat's
        origin, which the orbit camera looks at (``self.centre`` is that centre in
        the z-up world before the shift).
        """
        qs = [self._q0] if qs is None else qs
        pts = np.concatenate([vg.geometry_points(self.model.pin, self.visual_model, q) for q in qs])
        if self._ghost_viz is not None:
            pts = np.concatenate([pts, pts + self._ghost_offset])
        R = vg.up_rotation(self.up_axis)[:3, :3]
        w = pts @ R.T
        lo, hi = w.min(axis=0), w.max(axis=0)
        centre = 0.5 * (lo + hi)
        extent = max(float(np.max(hi - lo)), 0.3)
        d = distance or (0.9 * extent + 0.15)
        direction = np.array([0.7, -1.0, 0.35])
        offset = d * direction / np.linalg.norm(direction)
        # meshcat's orbit camera looks at the world origin: move the scene there instead
        T = vg.up_rotation(self.up_axis)
        T[:3, 3] = -centre
        self.vis[self._root].set_transform(T)
        self.centre = centre
        self._extent, self._view = extent, direction
        self._place_legend()
        # the camera object lives in three.js's y-up frame: (x, y, z)_world -> (x, z, -y)
        self.vis["/Cameras/default/rotated/<object>"].set_property(
            "position", [float(offset[0]), float(offset[2]), float(-offset[1])])

    # --------------------------------------------------------------- misc
    def jupyter_cell(self, height: int = 400):
        """An IPython HTML object embedding the viewer (put it last in a notebook cell)."""
        return self.vis.jupyter_cell(height=height)

    def _repr_html_(self) -> str:
        # a bare ``viewer`` at the end of a notebook cell shows the scene
        return self.jupyter_cell().data

    def static_html(self) -> str:
        """The whole current scene as one self-contained HTML page (from the server)."""
        return self.vis.static_html()

    def scene(self) -> dict[str, set[str]]:
        """The server's scene tree: ``{path: {"object", "transform", "animation", "property"}}``.

        Read back from the meshcat server (its ``get_scene`` reply), not from
        what this object remembers sending.
        """
        return parse_static_scene(self.static_html())

    def serve(self, *, timeout: float | None = None) -> None:
        """Keep the server up until Ctrl-C (or ``timeout`` seconds), then stop it."""
        print(f"pinmsk viewer: serving {self.url}; press Ctrl-C to stop", flush=True)
        t_end = None if timeout is None else time.monotonic() + timeout
        try:
            while t_end is None or time.monotonic() < t_end:
                time.sleep(0.1)
        except KeyboardInterrupt:
            pass
        finally:
            self.close()

    def wait(self) -> None:
        """Block until a browser has connected."""
        self.vis.wait()

    def close(self) -> None:
        """Stop the meshcat server this viewer started (no-op when connected to another one)."""
        if self._closed:
            return
        self._closed = True
        window = self.vis.window
        proc = getattr(window, "server_proc", None)
        try:
            window.zmq_socket.close(linger=0)
        except Exception:  # pragma: no cover
            pass
        if proc is not None and proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=5)
            except Exception:  # pragma: no cover
                proc.kill()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self) -> str:
        return f"<pinmsk.Viewer {self.model.name} at {self.url}>"


# ------------------------------------------------------------------ helpers

def _start_quietly(meshcat):
    """Start a meshcat server subprocess; its banner goes to stderr, we print the URL ourselves."""
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        vis = meshcat.Visualizer()
    return vis


#: Width / height of the legend image.
LEGEND_ASPECT = 0.45


def legend_png(colors: np.ndarray, label: str) -> bytes:
    """PNG of a vertical colour bar: the ``colors`` levels from 0 (bottom) to 1 (top), ticks 0, 0.5, 1
    and ``label`` along its side, on a white card (matplotlib's Agg canvas)."""
    from matplotlib.colors import ListedColormap, BoundaryNorm
    from matplotlib.figure import Figure
    from matplotlib.colorbar import ColorbarBase

    n = len(colors)
    fig = Figure(figsize=(2.0 * LEGEND_ASPECT * 2, 4.0), dpi=100)
    fig.patch.set_facecolor("white")
    ax = fig.add_axes([0.08, 0.05, 0.25, 0.9])
    ColorbarBase(ax, cmap=ListedColormap(colors), norm=BoundaryNorm(np.linspace(0, 1, n + 1), n),
                 ticks=[0.0, 0.5, 1.0], orientation="vertical")
    ax.tick_params(labelsize=16)
    ax.set_ylabel(label, fontsize=16 if len(label) < 20 else 12, labelpad=4)
    ax.yaxis.set_label_position("right")
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def _has_display() -> bool:
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


#: The colour "level" of a muscle without an activation: its ``red`` mesh.
NO_LEVEL = -1


def _level_node(level: int) -> str:
    return "red" if level == NO_LEVEL else f"c{level}"


def _side_key(side) -> str:
    return side if side else "grf"


def _set_scaled(frame, T: np.ndarray) -> None:
    """Animation keys for a transform with scale (meshcat's helper drops the scale)."""
    from meshcat.animation import js_position, js_quaternion

    S = np.linalg.norm(T[:3, :3], axis=0)
    R = T[:3, :3] / np.where(S > 0, S, 1.0)
    M = np.eye(4)
    M[:3, :3] = R
    M[:3, 3] = T[:3, 3]
    frame.set_property("position", "vector3", js_position(M))
    frame.set_property("quaternion", "quaternion", js_quaternion(M))
    frame.set_property("scale", "vector3", [float(x) for x in S])


def _playback_times(t: np.ndarray, fps: float) -> np.ndarray:
    """The trial's own times, or a uniform grid at ``fps`` when the trial is denser."""
    duration = float(t[-1] - t[0])
    if fps <= 0 or t.size <= duration * fps + 1:
        return t
    n = int(np.ceil(duration * fps)) + 1
    return np.linspace(t[0], t[-1], n)


def _interp_columns(t, t_src, values) -> np.ndarray:
    values = np.asarray(values, dtype=float)
    if values.ndim == 1:
        values = values[:, None]
    if len(t) == len(t_src) and np.array_equal(t, t_src):
        return values.copy()
    return np.stack([np.interp(t, t_src, values[:, k]) for k in range(values.shape[1])], axis=1)


_NO_DRAW = "meshcat cannot draw NaN or infinite values"
_NO_NAN = f"{_NO_DRAW}: fill or cut the gaps first"


def _per_name(x, names, what: str, kind: str) -> np.ndarray:
    """One value per name from a mapping (missing names 0) or a sequence; unknown names, a wrong
    length or a non-finite value are ModelErrors naming ``what`` and ``kind``."""
    if isinstance(x, Mapping):
        unknown = sorted(set(x) - set(names))
        if unknown:
            raise ModelError(f"{what}: unknown {kind} {unknown} ({kind}: {', '.join(names)})")
        x = np.array([float(x.get(n, 0.0)) for n in names])
    else:
        x = np.asarray(x, dtype=float).reshape(-1)
    if x.shape != (len(names),):
        raise ModelError(f"{what} has {x.size} values; the model has {len(names)} {kind}")
    return _require_finite(x, names, what)


def _require_finite(x: np.ndarray, labels, what: str) -> np.ndarray:
    """``x`` (one value per label) if all finite, else TrialError naming the first bad label."""
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        raise TrialError(f"{what}: {labels[bad[0]]!r} is {float(x[bad[0]])!r}; {_NO_NAN}")
    return x


def _coordinates_of(trial, model, what: str) -> np.ndarray:
    """``(N, nq)`` configuration of ``model`` from a trial's coordinate channels (finite); a model with
    dependent joints (an exact OpenSim import) takes OpenSim's coordinates, mapped to its joints."""
    from ..kinematics import coordinate_map, trial_coordinates
    cmap = coordinate_map(model)
    if cmap is not None:
        given = trial_coordinates(model)
        trial.require(given)
        trial.check_finite(given, what=f"in the {what} before viewing ({_NO_DRAW})")
        return cmap.expand({c: np.asarray(trial[c], dtype=float) for c in given})[0]
    names = set(trial.names)
    missing = [c for c in model.coordinates if c not in names]
    if missing:
        hints = [f"{c} (did you mean {difflib.get_close_matches(c, trial.names, n=1)[0]!r}?)"
                 if difflib.get_close_matches(c, trial.names, n=1) else c for c in missing]
        raise TrialError(
            f"{what} has no channel for coordinate(s) {', '.join(hints)} of model "
            f"'{model.name}'; a motion to view needs all of: {', '.join(model.coordinates)}")
    trial.check_finite(model.coordinates, what=f"in the {what} before viewing ({_NO_DRAW})")
    q = np.zeros((len(trial.time), model.pin.nq))
    for c in model.coordinates:
        q[:, model.pin.joints[model.pin.getJointId(c)].idx_q] = np.asarray(trial[c], dtype=float)
    return q


def _channels_on(sources, names, t) -> np.ndarray | None:
    """Channels ``names`` from the first source holding all of them, on times ``t``; else None."""
    for s in sources:
        if all(n in s.names for n in names):
            s.check_finite(names, what=f"before viewing ({_NO_DRAW})")
            vals = np.stack([np.asarray(s[n], dtype=float) for n in names], axis=1)
            return _interp_columns(t, np.asarray(s.time, dtype=float), vals)
    return None


def _grf_on(sources, t) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``{side: (F (N, 3), P (N, 3))}`` from ground reaction channels (missing axes are 0)."""
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for s in sources:
        found: dict[str, dict[tuple[str, str], str]] = {}
        for n in s.names:
            g = parse_ground_reaction(n)
            if g is not None and g.quantity in ("force", "point"):
                found.setdefault(g.side or "", {})[(g.quantity, g.axis)] = n
        for side, chans in found.items():
            if side in out or not any(k[0] == "force" for k in chans):
                continue
            s.check_finite(list(chans.values()), what=f"before viewing ({_NO_DRAW})")
            arrays = []
            for quantity in ("force", "point"):
                cols = [np.asarray(s[chans[(quantity, ax)]], dtype=float) if (quantity, ax) in chans
                        else np.zeros(len(s.time)) for ax in "xyz"]
                arrays.append(_interp_columns(t, np.asarray(s.time, dtype=float), np.stack(cols, axis=1)))
            out[side] = (arrays[0], arrays[1])
    return out


def segment_keys(pts: np.ndarray, radius: float):
    """Placements of the unit cylinders (axis y, spanning y = -0.5 .. 0.5) that draw the segments of
    polylines ``pts`` (N, K, 3): positions (N, K-1, 3), quaternions (N, K-1, 4) as ``x, y, z, w`` (three.js's
    order) and scales (N, K-1, 3) (``radius``, length, ``radius``); a zero-length segment is scaled to
    nothing (not a disc)."""
    a, b = pts[:, :-1], pts[:, 1:]
    d = b - a
    length = np.linalg.norm(d, axis=-1)
    u = d / np.where(length > 1e-12, length, 1.0)[..., None]
    # the rotation taking y onto u: about y x u = (u_z, 0, -u_x) by acos(u_y), as a half-angle quaternion
    w = np.sqrt(np.maximum(0.5 * (1.0 + u[..., 1]), 0.0))
    flip = w < 1e-6                                   # u = -y: half a turn about x
    w2 = np.where(flip, 1.0, 2.0 * w)
    quat = np.stack([np.where(flip, 1.0, u[..., 2] / w2), np.zeros_like(w), np.where(flip, 0.0, -u[..., 0] / w2),
                     np.where(flip, 0.0, w)], axis=-1)
    quat /= np.linalg.norm(quat, axis=-1, keepdims=True)
    zero = length <= 1e-12
    scale = np.stack([np.where(zero, 1e-9, radius), np.where(zero, 1e-9, length), np.where(zero, 1e-9, radius)],
                     axis=-1)
    return 0.5 * (a + b), quat, scale


def _scaled_matrix(position, quat, scale) -> np.ndarray:
    """The 4x4 matrix of a placement with a scale (as three.js composes position, quaternion, scale)."""
    x, y, z, w = quat
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    T = np.eye(4)
    T[:3, :3] = R * np.asarray(scale)[None, :]
    T[:3, 3] = position
    return T


def _pad_vertices(pts: np.ndarray, k: int) -> np.ndarray:
    """``pts`` (N, K, 3) with its last vertex repeated up to k vertices."""
    if pts.shape[1] >= k:
        return pts
    return np.concatenate([pts, np.repeat(pts[:, -1:], k - pts.shape[1], axis=1)], axis=1)


def _set_tracks(anim, vis, path: str, times, **tracks) -> None:
    """Whole animation tracks of node ``path`` at once (``position``/``scale`` (N, 3), ``quaternion``
    (N, 4)), instead of one key per frame and call."""
    from meshcat.animation import AnimationTrack

    clip = anim.at_frame(vis, 0.0)[path].get_clip()
    frames = [float(x) for x in times]
    for name, values in tracks.items():
        kind = "quaternion" if name == "quaternion" else "vector3"
        clip.tracks[name] = AnimationTrack(name, kind, list(frames), np.asarray(values, dtype=float).tolist())


class _DisplayPointLines:
    """Polylines through a model's display points (fixed in bodies: built-in models and sidecars)."""

    paths = None

    def __init__(self, model, names, frames, points, radii):
        self.model, self.names, self.radii = model, tuple(names), tuple(radii)
        self._frames = frames              # per muscle: frame ids (P,)
        self._points = points              # per muscle: (P, 3) in those frames
        self._ids = sorted({f for fr in frames for f in fr})

    def __call__(self, Q) -> dict[str, np.ndarray]:
        pm = self.model.pin
        data = pm.createData()
        col = {f: k for k, f in enumerate(self._ids)}
        R = np.empty((len(Q), len(self._ids), 3, 3))
        p = np.empty((len(Q), len(self._ids), 3))
        for n, q in enumerate(Q):
            pin.framesForwardKinematics(pm, data, q)
            for k, f in enumerate(self._ids):
                R[n, k], p[n, k] = data.oMf[f].rotation, data.oMf[f].translation
        out = {}
        for name, fr, pts in zip(self.names, self._frames, self._points):
            cols = [col[f] for f in fr]
            out[name] = np.einsum("npij,pj->npi", R[:, cols], pts) + p[:, cols]
        return out


class _GeometricLines:
    """Polylines of an imported OpenSim model's geometric paths (:meth:`GeometricPaths.polylines`) at
    the model's configurations: its joints that are OpenSim coordinates give the paths' coordinates,
    the others keep their default values."""

    def __init__(self, model, paths, radii, *, arc_points: int):
        self.model, self.paths, self.names, self.radii = model, paths, tuple(paths.muscles), tuple(radii)
        self.arc_points = int(arc_points)
        cmap = model.meta.get("coordinate_map")
        defaults = dict(getattr(cmap, "defaults", {}) or {})
        defaults.update(getattr(cmap, "welded", {}) or {})
        pm = model.pin
        self._cols = []
        self._defaults = np.zeros(len(paths.coordinates))
        for j, c in enumerate(paths.coordinates):
            if pm.existJointName(c) and pm.joints[pm.getJointId(c)].nq == 1:
                self._cols.append((j, pm.joints[pm.getJointId(c)].idx_q))
            self._defaults[j] = float(defaults.get(c, 0.0))

    def __call__(self, Q) -> dict[str, np.ndarray]:
        qg = np.repeat(self._defaults[None], len(Q), axis=0)
        for j, iq in self._cols:
            qg[:, j] = Q[:, iq]
        pl = self.paths.polylines(qg, arc_points=self.arc_points)
        k = np.maximum(pl.counts.max(axis=0), 2)
        return {name: pl.points[:, i, :k[i]] for i, name in enumerate(pl.muscles)}


def muscle_polylines(model, *, arc_points: int = 8):
    """What draws ``model``'s muscles: ``None`` or a callable ``(Q (N, nq)) -> {muscle: (N, K, 3)}`` with
    ``names`` and ``radii``.  An imported OpenSim model draws its geometric paths (the import's, or
    read again from its ``.osim`` when the import kept none); other models their display points.
    Muscles with neither (paths that are only functions of the coordinates) are named in a warning."""
    muscles = getattr(model, "muscles", None)
    names = tuple(muscles.names) if muscles is not None else ()
    radii = dict(zip(names, _muscle_radii(muscles))) if muscles is not None else {}
    source, said = None, False
    if model.meta.get("osim") or model.meta.get("source_osim"):
        from ..opensim.muscle_import import geometric_paths, osim_geometric_paths
        if model.meta.get("osim"):
            gp = geometric_paths(model.meta.get("import_report")) or osim_geometric_paths(model.meta["osim"])
        else:
            gp, said = _sidecar_osim_paths(model, osim_geometric_paths)
        if gp is not None:
            source = _GeometricLines(model, gp, [radii.get(n, 0.006) for n in gp.muscles], arc_points=arc_points)
    elif muscles is not None and getattr(muscles, "display_points", None):
        frames = {f.name for f in model.pin.frames}
        drawn, fids, pts = [], [], []
        for name in names:
            resolved = []
            for p in muscles.display_points.get(name) or []:
                if p[0] not in frames:
                    warnings.warn(f"muscle '{name}': display point on unknown body '{p[0]}'; skipped", stacklevel=3)
                    continue
                resolved.append((model.pin.getFrameId(p[0]), np.asarray(p[1:4], dtype=float)))
            if len(resolved) >= 2:
                drawn.append(name)
                fids.append([r[0] for r in resolved])
                pts.append(np.array([r[1] for r in resolved]))
        if drawn:
            source = _DisplayPointLines(model, drawn, fids, pts, [radii[n] for n in drawn])
    missing = [n for n in names if source is None or n not in source.names]
    if missing and not said:
        warnings.warn(f"model '{model.name}': {len(missing)} muscle(s) have no path geometry to draw (their paths "
                      f"are functions of the coordinates only, {type(muscles.path).__name__}; give [[muscles]] "
                      f"display 'points' to draw them): {', '.join(missing)}", stacklevel=3)
    return source


def _sidecar_osim_paths(model, read_paths):
    """``(geometric paths or None, warned)`` of the .osim a sidecar written by ``pinmsk import`` names
    (``[model] osim``, ``meta['source_osim']``): a warning says why none are drawn (the file is gone or
    unreadable), or that the file changed since the sidecar was written (its digest differs)."""
    from ..errors import PinmskError
    from ..opensim.importer import osim_digest
    src = Path(model.meta["source_osim"])
    where = f"model '{model.name}' ({model.meta.get('sidecar', 'its sidecar')}, [model] osim)"
    if not src.is_file():
        warnings.warn(f"{where}: the OpenSim model it was imported from, {src}, is not found, so no muscle paths "
                      "are drawn (the sidecar's paths are polynomials of the coordinates); put the .osim there or "
                      "correct [model] osim", stacklevel=4)
        return None, True
    digest = model.meta.get("source_osim_digest")
    if digest and osim_digest(src) != digest:
        warnings.warn(f"{where}: {src} changed since the sidecar was written; the muscle paths drawn are the "
                      "file's as it is now", stacklevel=4)
    try:
        return read_paths(src), False
    except PinmskError as exc:
        warnings.warn(f"{where}: no muscle paths drawn: {exc}", stacklevel=4)
        return None, True


def add_wrap_objects(geom_model: pin.GeometryModel, model, paths) -> list[str]:
    """Add the wrap objects the ``paths`` use (cylinders, spheres, ellipsoids) to ``geom_model`` as
    translucent ``wrap_<name>`` geometries on their bodies' frames; returns the names added.  Tori
    (no such primitive in meshcat) and wraps on bodies the model lacks are named in a warning."""
    import coal

    from ..opensim.paths import body_fixed_xyz

    wraps = {}
    for spec in paths.specs:
        for pw in spec.wraps:
            wraps.setdefault(pw.wrap.name, pw.wrap)
    added, skipped = [], []
    pm = model.pin
    for name, w in wraps.items():
        if not w.active:
            continue
        if w.kind == "torus" or not pm.existFrame(w.body):
            skipped.append(f"{name} ({'a torus' if w.kind == 'torus' else f'on body {w.body!r}, not in the model'})")
            continue
        geom = {"cylinder": lambda: coal.Cylinder(w.radius, w.length), "sphere": lambda: coal.Sphere(w.radius),
                "ellipsoid": lambda: coal.Ellipsoid(*w.dimensions)}[w.kind]()
        frame = pm.frames[pm.getFrameId(w.body)]
        placement = frame.placement * pin.SE3(body_fixed_xyz(w.rotation), np.asarray(w.translation))
        obj = pin.GeometryObject(f"wrap_{name}", frame.parentJoint, placement, geom)
        obj.meshColor = np.asarray(WRAP, dtype=float)
        geom_model.addGeometryObject(obj)
        added.append(name)
    if skipped:
        warnings.warn(f"model '{model.name}': wrap object(s) not drawn: {', '.join(skipped)}", stacklevel=3)
    return added


def _muscle_radii(muscles) -> np.ndarray:
    """Display radius of each muscle from its PCSA (volume / l_opt), 4 .. 15 mm."""
    try:
        pcsa = np.asarray(muscles.volume, dtype=float) / np.asarray(muscles.l_opt, dtype=float)
        r = np.sqrt(pcsa / np.pi)
    except Exception:
        r = np.full(len(muscles.names), 0.006)
    return np.clip(np.nan_to_num(r, nan=0.006), 0.004, 0.015)


def build_visual_model(model) -> pin.GeometryModel:
    """The visual GeometryModel of ``model``: its URDF visuals (meshes resolved with
    ``meta['package_dirs']``) plus capsules for massive bodies without a visual."""
    urdf = model.meta.get("urdf")
    gm = pin.GeometryModel()
    if urdf:
        dirs = [str(d) for d in model.meta.get("package_dirs", [])]
        try:
            gm = pin.buildGeomFromUrdf(model.pin, str(urdf), pin.GeometryType.VISUAL, package_dirs=dirs)
        except Exception as exc:
            warnings.warn(f"model '{model.name}': could not load visual geometry from {urdf} ({exc}); "
                          "showing capsules instead", stacklevel=2)
            gm = pin.GeometryModel()
    return vg.fallback_geometry(model.pin, gm, color=BONE)


def neutral_configuration(pin_model: pin.Model) -> np.ndarray:
    """Pinocchio's neutral configuration moved inside finite joint limits."""
    q = pin.neutral(pin_model)
    lo, hi = pin_model.lowerPositionLimit, pin_model.upperPositionLimit
    ok = np.isfinite(lo) & np.isfinite(hi) & (lo <= hi)
    q[ok] = np.clip(q[ok], lo[ok], hi[ok])
    return q


def default_ground_height(model, visual_model: pin.GeometryModel, q0) -> float:
    """Ground height along the up axis: ``meta['ground_height']`` if set; 0 for models
    with a translational (prismatic) joint (the ground is the world's y = 0 or z = 0);
    otherwise just below the lowest point of the model at ``q0``."""
    if "ground_height" in model.meta:
        return float(model.meta["ground_height"])
    pm = model.pin
    if any(pm.joints[j].shortname().startswith(("JointModelP", "JointModelFreeFlyer", "JointModelPlanar"))
           for j in range(1, pm.njoints)):
        return 0.0
    up = vg.up_index(model.meta.get("up_axis", "z"))
    pts = vg.geometry_points(pm, visual_model, q0)
    return float(pts[:, up].min()) - 0.02


def contact_spheres(model) -> list[tuple[str, int, np.ndarray, float]]:
    """``(label, frame id, position in the frame, radius)`` of the model's contact spheres.

    Reads each contact component's frame (``frame``, ``body`` or ``target``),
    position (``position``, ``point``, ``offset`` or ``location``, else the
    frame origin) and ``radius`` (attribute or parameter, else 2 cm).
    """
    out = []
    for c in getattr(model, "contacts", ()):
        frame = getattr(c, "frame", None) or getattr(c, "body", None) or getattr(c, "target", None)
        if not isinstance(frame, str) or not model.pin.existFrame(frame):
            warnings.warn(f"contact {getattr(c, 'label', c)!r}: no frame found to draw it on", stacklevel=2)
            continue
        pos = None
        for attr in ("position", "point", "offset", "location"):
            if getattr(c, attr, None) is not None:
                pos = np.asarray(getattr(c, attr), dtype=float).reshape(-1)[:3]
                break
        if pos is None or pos.shape != (3,):
            pos = np.zeros(3)
        radius = getattr(c, "radius", None)
        if radius is None:
            radius = getattr(c, "values", {}).get("radius", 0.02) if hasattr(c, "values") else 0.02
        out.append((str(getattr(c, "label", frame)), model.pin.getFrameId(frame), pos, float(radius)))
    return out


def parse_static_scene(html: str) -> dict[str, set[str]]:
    """Decode the commands embedded in meshcat's static HTML into ``{path: kinds}``.

    ``kinds`` holds ``object``, ``transform``, ``property`` and ``animation``;
    a ``set_animation`` adds ``animation`` to every animated path.
    """
    import umsgpack

    out: dict[str, set[str]] = {}
    for b64 in re.findall(r'data:application/octet-binary;base64,([A-Za-z0-9+/=]+)', html):
        cmd = umsgpack.unpackb(base64.b64decode(b64))
        kind = cmd.get("type")
        if kind == "set_animation":
            for a in cmd.get("animations", []):
                out.setdefault(a["path"], set()).add("animation")
            continue
        label = {"set_object": "object", "set_transform": "transform",
                 "set_property": "property"}.get(kind, kind)
        out.setdefault(cmd.get("path", ""), set()).add(label)
    return out


def view_cli(model_name, trial_path=None, results_path=None, *, open_browser: bool = False,
             block: bool = True, timeout: float | None = None) -> Viewer:
    """``pinmsk view MODEL [TRIAL] [--results RESULTS]``: start the viewer and print its URL.

    ``model_name`` is a name or file for :func:`~pinmsk.model.load_model`, or a Model already loaded;
    ``trial_path`` is a file or a :class:`~pinmsk.trial.Trial` already read.

    Loads the model (built-in name or file), shows the neutral pose, or plays
    the trial with the results' activations/forces/residuals/GRF.  With
    ``block`` it then waits (Ctrl-C, or ``timeout`` seconds) and stops the
    server; otherwise it returns the running :class:`Viewer`.
    """
    if results_path and trial_path is None:
        raise TrialError("--results needs a TRIAL with the motion to show them on")
    model = model_name if isinstance(model_name, Model) else load_model(model_name)
    trial = trial_path if isinstance(trial_path, Trial) else (read_trial(trial_path) if trial_path else None)
    results = read_trial(results_path) if results_path else None
    if trial is not None:
        _coordinates_of(trial, model, "trial")       # refuse a bad motion before starting a server
    # blocking: the server stops on every way out; returning: the caller owns it
    with signals_raise_exit() if block else contextlib.nullcontext():
        viewer = Viewer(model, open_browser=open_browser)     # stops its server if its setup fails
        with _closing(viewer) if block else _closing_on_error(viewer):
            if trial is not None:
                viewer.play(trial, results=results)
                print(f"pinmsk viewer: playing {trial.meta.get('source') or 'the trial'} "
                      f"({trial.time[-1] - trial.time[0]:.2f} s); "
                      "open 'Open Controls' > Animations for the time slider", flush=True)
            if block:
                viewer.serve(timeout=timeout)
    return viewer


#: Signals that end a blocking viewer: a service manager's stop, a closed terminal.
END_SIGNALS = tuple(getattr(signal, n) for n in ("SIGTERM", "SIGHUP") if hasattr(signal, n))


@contextlib.contextmanager
def signals_raise_exit(signals: Sequence[int] = END_SIGNALS):
    """Within the block, SIGTERM and SIGHUP raise ``SystemExit(128 + signum)`` (the shell's code).

    meshcat starts its server in a session of its own (so a closed terminal's
    SIGHUP does not reach it) and stops it from ``atexit``, which Python skips
    when a signal's default action ends the process.  Raising instead lets
    ``finally`` clauses and :meth:`Viewer.close` run.  The previous handlers
    are restored on leaving; outside the main thread (where Python cannot set
    handlers) the block runs unchanged.
    """
    def end(signum, frame):
        raise SystemExit(128 + signum)

    previous = {}
    if threading.current_thread() is threading.main_thread():
        for sig in signals:
            previous[sig] = signal.signal(sig, end)
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


@contextlib.contextmanager
def closing_on_signals(viewer: "Viewer"):
    """Stop ``viewer``'s meshcat server when the block ends by any way: normally,
    Ctrl-C, an exception, SIGTERM or SIGHUP (see :func:`signals_raise_exit`)."""
    with signals_raise_exit(), _closing(viewer):
        yield viewer


@contextlib.contextmanager
def _closing(viewer: "Viewer"):
    try:
        yield viewer
    finally:
        viewer.close()


@contextlib.contextmanager
def _closing_on_error(viewer: "Viewer"):
    """Stop ``viewer``'s server if the block raises; leave it running otherwise."""
    try:
        yield viewer
    except BaseException:
        viewer.close()
        raise
