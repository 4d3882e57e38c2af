"""Where the built-in models live, and the URDF each sidecar points at.

The built-in models (``finger``, ``forearm``, ``gait2d``, ``human3d``) are a
URDF plus one TOML *sidecar* each, in the repository's ``urdf/`` folder.  A
wheel installs that folder as the data package ``pinmsk._urdf``; an editable
or source checkout reads it in place.  ``urdf/README.md`` documents the
sidecar format and the coordinate conventions.

``human3d`` ships no URDF of its own: its sidecar points at the 36-dof
``human.urdf`` of the ``example-robot-data`` distribution with the marker
``@example-robot-data:<path inside share/example-robot-data>``.

Turning a sidecar into a model (skeleton, gravity, muscles, effects, contacts) is
:func:`pinmsk.load_model`'s job, in one place (``pinmsk.model._load_sidecar``).

Functions
---------
builtin_dir, builtin_names, builtin_sidecar
    find the folder, list the models, get one sidecar's path.
read_sidecar
    parse a sidecar (TOML) into a dict, with errors that name the file.
resolve_urdf, example_robot_data_dir
    the URDF file a sidecar refers to and the package directories its meshes need.
"""

from __future__ import annotations

import difflib
import importlib.metadata
import importlib.resources
from pathlib import Path
from typing import NamedTuple

from pinmsk.errors import ModelError
from pinmsk.io.toml_files import read_toml

__all__ = [
    "EXAMPLE_ROBOT_DATA_MARKER",
    "UrdfSource",
    "builtin_dir",
    "builtin_names",
    "builtin_sidecar",
    "read_sidecar",
    "resolve_urdf",
    "example_robot_data_dir",
]

#: Prefix of a sidecar ``urdf`` value that lives in the example-robot-data distribution.
EXAMPLE_ROBOT_DATA_MARKER = "@example-robot-data:"
_ERD_DIST = "example-robot-data"
_ERD_DIR = "example-robot-data"  # folder name under <prefix>/share


# -----------------------------------------------------------------------------
# finding the built-in models
# -----------------------------------------------------------------------------


def builtin_dir() -> Path:
    """The folder holding the built-in URDFs and sidecars.

    Installed from a wheel, that is the data package ``pinmsk._urdf`` (setup
    maps the repository's ``urdf/`` onto it); from a source checkout or an
    editable install it is ``<repo>/urdf``.
    """
    # The checkout this module was imported from comes first: an editable install of another
    # checkout (a git worktree run with PYTHONPATH) maps ``pinmsk._urdf`` onto *that* checkout's urdf/.
    source = Path(__file__).resolve().parents[1] / "urdf"
    if source.is_dir() and any(source.glob("*.toml")):
        return source
    try:
        resource = importlib.resources.files("pinmsk._urdf")
    except ModuleNotFoundError:
        resource = None
    if resource is not None:
        path = Path(str(resource))
        if path.is_dir() and any(path.glob("*.toml")):
            return path
    raise ModelError(
        "cannot find pinmsk's built-in models: neither the package 'pinmsk._urdf' nor "
        f"{source} holds any *.toml sidecar; reinstall pinmsk (pip install .) or run from a source checkout"
    )


def builtin_names() -> tuple[str, ...]:
    """Names of the built-in models (one per sidecar ``<name>.toml`` whose ``[model]``
    table names a URDF; other TOML files there, such as marker sets, are not models), sorted."""
    return tuple(sorted(p.stem for p in builtin_dir().glob("*.toml") if _names_urdf(p)))


def _names_urdf(path: Path) -> bool:
    model = read_toml(path, what="built-in model sidecar").get("model", {})
    return isinstance(model, dict) and "urdf" in model


def builtin_sidecar(name: str) -> Path:
    """Path of the sidecar of built-in model ``name`` (e.g. ``"forearm"``)."""
    names = builtin_names()
    if name not in names:
        close = difflib.get_close_matches(str(name), names, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else "."
        raise ModelError(f"no built-in model {name!r}{hint} The built-in models are: {', '.join(names)}")
    return builtin_dir() / f"{name}.toml"


# -----------------------------------------------------------------------------
# sidecars and the URDFs they point at
# -----------------------------------------------------------------------------


def _sidecar_path(sidecar) -> Path:
    """A sidecar given as a path or as the name of a built-in model."""
    if isinstance(sidecar, Path) or (isinstance(sidecar, str) and (sidecar.endswith(".toml") or "/" in sidecar)):
        return Path(sidecar)
    return builtin_sidecar(str(sidecar))


def read_sidecar(path) -> dict:
    """Parse a sidecar TOML file (a path, or a built-in model's name) into a dict.

    Checks only what every reader needs: the file parses and has a ``[model]``
    table with a ``urdf`` string.  Muscles and effects are checked by the
    classes that read them.
    """
    path = _sidecar_path(path)
    data = read_toml(path, what="sidecar file")
    model = data.get("model")
    if not isinstance(model, dict) or not isinstance(model.get("urdf"), str):
        raise ModelError(
            f"sidecar {path} needs a [model] table with a urdf = \"...\" entry (path relative to the sidecar); "
            "see urdf/README.md"
        )
    return data


class UrdfSource(NamedTuple):
    """A URDF file and the package directories that resolve its ``package://`` meshes.

    A named tuple, so ``urdf, package_dirs = resolve_urdf(...)`` works.
    """

    path: Path
    package_dirs: tuple[Path, ...] = ()


def example_robot_data_dir() -> Path:
    """``<prefix>/share/example-robot-data`` of the installed example-robot-data.

    Version 6 ships its files under a cmeel prefix without a Python loader, so
    the folder is found from the distribution's file list.
    """
    try:
        dist = importlib.metadata.distribution(_ERD_DIST)
    except importlib.metadata.PackageNotFoundError:
        raise ModelError(
            "the built-in model 'human3d' uses human.urdf from the example-robot-data package, "
            "which is not installed; install it with `pip install example-robot-data`"
        ) from None
    for f in dist.files or ():
        parts = f.parts
        if _ERD_DIR in parts and "robots" in parts:
            i = parts.index(_ERD_DIR)
            root = Path(dist.locate_file(Path(*parts[: i + 1])))
            if root.is_dir():
                return root.resolve()
    raise ModelError(
        f"example-robot-data {dist.version} is installed but its file list has no "
        f"'{_ERD_DIR}/robots/...' entry; reinstall it (pip install --force-reinstall example-robot-data)"
    )


def resolve_urdf(sidecar, reference: str | None = None) -> UrdfSource:
    """The URDF that ``sidecar``'s ``[model] urdf`` (or ``reference``) points at.

    A plain value is a path relative to the sidecar's folder.  A value
    ``@example-robot-data:<relative path>`` is looked up inside the installed
    example-robot-data (``<prefix>/share/example-robot-data/<relative path>``)
    and comes with the package directory that resolves its meshes.
    """
    path = _sidecar_path(sidecar)
    if reference is None:
        reference = read_sidecar(path)["model"]["urdf"]
    if reference.startswith(EXAMPLE_ROBOT_DATA_MARKER):
        rel = reference[len(EXAMPLE_ROBOT_DATA_MARKER):].lstrip("/")
        root = example_robot_data_dir()
        urdf = root / rel
        if not urdf.is_file():
            raise ModelError(
                f"sidecar {path}: urdf = {reference!r} names {urdf}, which example-robot-data does not ship; "
                f"look in {root} for the right relative path"
            )
        # meshes are "package://example-robot-data/robots/...": the package dir is <prefix>/share
        return UrdfSource(urdf, (root.parent,))
    urdf = (path.parent / reference).resolve()
    if not urdf.is_file():
        raise ModelError(f"sidecar {path}: urdf = {reference!r} does not exist (looked for {urdf})")
    return UrdfSource(urdf, (urdf.parent,))


# -----------------------------------------------------------------------------
# Pinocchio models
# -----------------------------------------------------------------------------


