"""The cases of tests/test_osim_forces.py: zoo models, their states, and the forces compared.

Shared by the test and by ``make_references.py`` (which runs OpenSim on the same states and writes
``references.npz`` beside this file).  The states are sinusoids in OpenSim's coordinates reaching
60 % of each coordinate's range beyond its middle, so the CoordinateLimitForces press and the
contact spheres sink into their half spaces; a locked coordinate stays at its default value
(OpenSim does not change it) with zero speed, a free ball is moved onto a sphere it touches,, a clamped one is clamped to its range (as OpenSim clamps it); a FreeJoint's rotations get zero speed (OpenSim's
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
    "ToyLanding": ("CoordinateLimitForce", "BushingForce", "HuntCrossleyForce"),
    "SoccerKick": ("CoordinateLimitForce", "HuntCrossleyForce"),
    "WalkerExpression": ("ExpressionBasedCoordinateForce", "SpringGeneralizedForce"),
    "WalkerElasticFoundation": ("ElasticFoundationForce",),
}
#: models made here from a zoo model: name -> (zoo model, forces added to its ForceSet)
DERIVED = {"WalkerExpression": ("Walker", """
				<ExpressionBasedCoordinateForce name="knee_expression">
					<coordinate>LKnee_rz</coordinate>
					<expression>-2*q - 0.5*qdot + 0.3*sin(q)^2 + step(q + 1)*exp(-qdot^2) - max(q, 0.2)*atan(qdot)</expression>
				</ExpressionBasedCoordinateForce>
				<SpringGeneralizedForce name="hip_spring">
					<coordinate>RHip_rz</coordinate>
					<stiffness>3.5</stiffness>
					<rest_length>0.3</rest_length>
					<viscosity>0.2</viscosity>
				</SpringGeneralizedForce>
				<ExpressionBasedCoordinateForce name="pelvis_expression">
					<coordinate>Pelvis_ty</coordinate>
					<expression>-100*(q - 0.5)*abs(q - 0.5) - 3*qdot + square(tanh(q))/recip(2) - cube(cos(q))</expression>
				</ExpressionBasedCoordinateForce>"""),
           "WalkerElasticFoundation": ("Walker", """
				<ElasticFoundationForce name="foot_foundation">
					<ElasticFoundationForce::ContactParametersSet name="contact_parameters">
						<objects>
							<ElasticFoundationForce::ContactParameters>
								<geometry>LFootContact RFootContact PlatformContact</geometry>
								<stiffness>1000000</stiffness>
								<dissipation>1</dissipation>
								<static_friction>0.8</static_friction>
								<dynamic_friction>0.4</dynamic_friction>
								<viscous_friction>0.4</viscous_friction>
							</ElasticFoundationForce::ContactParameters>
						</objects>
						<groups />
					</ElasticFoundationForce::ContactParametersSet>
					<transition_velocity>0.2</transition_velocity>
				</ElasticFoundationForce>""")}
#: models whose free ball (its FreeJoint's translations) is moved onto a contact sphere at every frame, so
#: that the sphere-sphere contacts press: model -> the ball's translation coordinates
BALLS = {"SoccerKick": ("ball_tx", "ball_ty", "ball_tz")}
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
                source, added = DERIVED.get(name, (name, None))
                data = tar.extractfile(f"{source}.osim").read()
                if added is not None:      # the forces go first in the ForceSet's objects
                    text = data.decode("utf-8")
                    at = text.index("<objects>", text.index("<ForceSet")) + len("<objects>")
                    data = (text[:at] + added + text[at:]).encode("utf-8")
                target.write_bytes(data)
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
    names = [r[0] for r in table]
    if path.stem in BALLS:
        _onto_ball(path, names, Q, V, BALLS[path.stem], rng)
    return names, t, Q, V, A


def _onto_ball(path, names, Q, V, ball, rng):
    """Move the ball (its translation coordinates ``ball``) so that at frame k it overlaps by 1-8 mm,
    in a random direction, the k-th (cyclically) sphere that has a sphere-sphere contact with it, and
    give it a random velocity (pinmsk's import finds the spheres and their frames)."""
    import warnings

    import pinocchio as pin

    from pinmsk.model import import_osim
    from pinmsk.opensim.contacts import contact_hook
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model, _ = import_osim(path, hooks=(contact_hook,))
    pairs = [c for c in model.components if c.family == "hunt_crossley_pair" and c.other == "sphere"]
    cmap = model.meta["coordinate_map"]
    order = list(cmap.osim_coordinates) if cmap is not None else list(model.coordinates)
    cols = [names.index(c) for c in order]
    tcols = [names.index(c) for c in ball]
    pm, pd = model.pin, model.pin.createData()

    def centre(q_osim, frame):
        q = cmap.expand(q_osim[None, cols], couplers=False)[0][0] if cmap is not None else q_osim[cols]
        pin.framesForwardKinematics(pm, pd, q)
        return pd.oMf[pm.getFrameId(frame)].translation.copy()

    for k in range(Q.shape[0]):
        c = pairs[k % len(pairs)]
        base = centre(Q[k], c.frame2)
        B = np.column_stack([centre(Q[k] + np.eye(Q.shape[1])[j] * 1.0, c.frame2) - base for j in tcols])
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        goal = centre(Q[k], c.target) + d * (c.values["radius"] + c.other_radius - rng.uniform(0.001, 0.008))
        Q[k, tcols] += np.linalg.solve(B, goal - base)
        V[k, tcols] = rng.normal(0.0, 0.3, 3)
