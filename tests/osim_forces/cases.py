"""The cases of tests/test_osim_forces.py: zoo models, their states, and the forces compared.

Shared by the test and by ``make_references.py`` (which runs OpenSim on the same states and writes
``references.npz`` beside this file).  The states are sinusoids in OpenSim's coordinates reaching
60 % of each coordinate's range beyond its middle, so the CoordinateLimitForces press and the
contact spheres sink into their half spaces; a locked coordinate stays at its default value
(OpenSim does not change it) with zero speed, a clamped one is clamped to its range (as OpenSim clamps it); a FreeJoint's rotations get zero speed (OpenSim's
speeds there are angular velocities, pinmsk's the angles' rates, which differ elsewhere).
"""
from __future__ import annotations

import tarfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REFERENCES = HERE / "references.npz"
ZOO = "osim-zoo/zoo_models.tar.xz"

#: model -> the OpenSim force types whose generalized forces are compared, force by force
FORCES = {
    "Walker": ("CoordinateLimitForce", "HuntCrossleyForce"),
    "Jumper": ("CoordinateLimitForce", "HuntCrossleyForce"),
    "BouncingBlock": ("CoordinateLimitForce", "BushingForce", "PointToPointSpring", "HuntCrossleyForce"),
    "ToyLanding": ("CoordinateLimitForce", "BushingForce"),
}
#: models whose whole inverse dynamics (every force on) is compared with OpenSim's
ID_MODELS = ("Walker",)
N_FRAMES = 24


def extract(archive: Path, names, out: Path) -> dict[str, Path]:
    """``{model: path}`` of the zoo members ``<model>.osim`` extracted into ``out``."""
    paths = {}
    with tarfile.open(archive) as tar:
        for name in names:
            target = out / f"{name}.osim"
            if not target.is_file():
                target.write_bytes(tar.extractfile(f"{name}.osim").read())
            paths[name] = target
    return paths


def coordinate_table(path: Path):
    """``[(name, range_min, range_max, free_rotation, locked_at, clamped)]`` of a model's coordinates in
    OpenSim's order (pinmsk's reader; ``free_rotation``: a FreeJoint's rotation; ``locked_at``: a locked
    coordinate's default value, which OpenSim keeps when it is set, else None; ``clamped``: OpenSim
    clamps the values it is set to into the range)."""
    from pinmsk.io.osim import read_osim
    doc = read_osim(path)
    out = []
    for j in doc.joints:
        for i, c in enumerate(j.coordinates):
            out.append((c.name, c.range[0], c.range[1], j.type == "FreeJoint" and i < 3,
                        c.default_value if c.locked else None, c.clamped))
    return out


def states(path: Path, n: int = N_FRAMES, seed: int = 0):
    """``(names, t, Q, V, A)``: OpenSim coordinates' sinusoids (module docstring)."""
    table = coordinate_table(path)
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, n)
    Q, V, A = (np.zeros((n, len(table))) for _ in range(3))
    for j, (name, lo, hi, free_rot, locked_at, clamped) in enumerate(table):
        if locked_at is not None:
            Q[:, j] = locked_at
            continue
        lo, hi = max(lo, -1.5), min(hi, 1.5)
        mid, amp = 0.5 * (lo + hi), 0.6 * (hi - lo)
        w, ph = 2 * np.pi * rng.uniform(0.5, 2.0), rng.uniform(0.0, 2 * np.pi)
        Q[:, j] = mid + amp * np.sin(w * t + ph)
        if not free_rot:
            V[:, j] = amp * w * np.cos(w * t + ph)
        A[:, j] = -amp * w * w * np.sin(w * t + ph)
        if clamped:
            Q[:, j] = np.clip(Q[:, j], lo, hi)
    return [r[0] for r in table], t, Q, V, A
