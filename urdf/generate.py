#!/usr/bin/env python3
"""Generate pinmsk's built-in models (URDF + TOML sidecar) from their anthropometry.

Run from anywhere::

    python urdf/generate.py           # rewrite finger/forearm/gait2d .urdf and .toml
    python urdf/generate.py --check   # exit 1 if a committed file differs from what this script writes

The script is also importable (``render_all()`` returns ``{file name: text}``) so
the test suite can check that the committed files are exactly its output.

All anthropometry is carried as exact fractions (``fractions.Fraction``) and only
converted to ``float`` when a number is written, so every mass, length and
inertia in the URDFs can be recomputed by hand from the tables quoted below.
Only three things need transcendental functions and are done in floating
point: the foot geometry (Table 4.1 angle beta), ``cos(pennation)`` in the
forearm reference lengths, and degree-to-radian conversions.

Conventions (all sagittal models; the same as OpenSim):
    world x forward, y up, z to the subject's right; gravity (0, -9.81, 0);
    every body rotates about z; a body's frame origin is its proximal joint
    centre (the HAT frame origin is the HAT centre of mass, Eq. 5.1).

Thesis references (Eq./Table/Sec. numbers) are to Sharif Shourijeh's thesis
(seed/thesis.txt).  ``urdf/README.md`` explains the sidecar format.

Standard library only: the generator must run without numpy or Pinocchio.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

HERE = Path(__file__).resolve().parent


def F(x) -> Fraction:
    """Exact rational from an int, a Fraction or a decimal *string* ("0.0465")."""
    if isinstance(x, float):
        raise TypeError("pass decimals as strings so they stay exact: F('0.0465')")
    return Fraction(x)


def fnum(x) -> str:
    """Shortest float repr of a number (exact Fraction or float); never '-0.0'."""
    v = float(x)
    if v == 0.0:
        v = 0.0
    return repr(v)


# =============================================================================
# Small URDF writer
# =============================================================================


@dataclass(frozen=True)
class Inertial:
    """Mass, centre of mass (in the link frame) and principal inertia about the COM."""

    mass: object
    com: tuple
    ixx: object
    iyy: object
    izz: object


@dataclass(frozen=True)
class Visual:
    kind: str  # "cylinder" (radius, length) | "box" (sx, sy, sz) | "sphere" (radius,)
    size: tuple
    xyz: tuple = (0, 0, 0)
    rpy: tuple = (0, 0, 0)
    material: str = "bone"


@dataclass(frozen=True)
class Link:
    name: str
    inertial: Inertial | None = None
    visuals: tuple = ()
    comment: str = ""


@dataclass(frozen=True)
class Joint:
    name: str
    type: str  # revolute | prismatic | fixed
    parent: str
    child: str
    xyz: tuple = (0, 0, 0)
    axis: tuple | None = None
    lower: object = None
    upper: object = None
    comment: str = ""


# cylinder axis is the local z axis: this rpy turns it onto the link's y axis
CYL_ALONG_Y = (math.pi / 2, 0, 0)
CYL_ALONG_X = (0, math.pi / 2, 0)

MATERIALS = {
    "bone": (0.89, 0.85, 0.79, 1.0),
    "right": (0.80, 0.35, 0.30, 1.0),
    "left": (0.30, 0.45, 0.80, 1.0),
    "trunk": (0.60, 0.60, 0.60, 1.0),
    "fixed": (0.40, 0.40, 0.40, 1.0),
}


def _xyz(v) -> str:
    return " ".join(fnum(c) for c in v)


def _comment(text: str, indent: str) -> list[str]:
    if not text:
        return []
    body = text.replace("--", "- -")  # "--" is not allowed inside XML comments
    lines = body.splitlines()
    if len(lines) == 1:
        return [f"{indent}<!-- {lines[0]} -->"]
    return [f"{indent}<!--"] + [f"{indent}  {ln}".rstrip() for ln in lines] + [f"{indent}-->"]


def _link_xml(link: Link) -> list[str]:
    out = _comment(link.comment, "  ")
    if link.inertial is None and not link.visuals:
        return out + [f'  <link name="{link.name}"/>']
    out.append(f'  <link name="{link.name}">')
    if link.inertial is not None:
        i = link.inertial
        out += [
            "    <inertial>",
            f'      <origin xyz="{_xyz(i.com)}" rpy="0 0 0"/>',
            f'      <mass value="{fnum(i.mass)}"/>',
            f'      <inertia ixx="{fnum(i.ixx)}" ixy="0" ixz="0" iyy="{fnum(i.iyy)}" iyz="0" izz="{fnum(i.izz)}"/>',
            "    </inertial>",
        ]
    for v in link.visuals:
        if v.kind == "cylinder":
            geom = f'<cylinder radius="{fnum(v.size[0])}" length="{fnum(v.size[1])}"/>'
        elif v.kind == "box":
            geom = f'<box size="{_xyz(v.size)}"/>'
        elif v.kind == "sphere":
            geom = f'<sphere radius="{fnum(v.size[0])}"/>'
        else:  # pragma: no cover - generator bug
            raise ValueError(v.kind)
        out += [
            "    <visual>",
            f'      <origin xyz="{_xyz(v.xyz)}" rpy="{_xyz(v.rpy)}"/>',
            f"      <geometry>{geom}</geometry>",
            f'      <material name="{v.material}"/>',
            "    </visual>",
        ]
    out.append("  </link>")
    return out


def _joint_xml(j: Joint) -> list[str]:
    out = _comment(j.comment, "  ")
    out.append(f'  <joint name="{j.name}" type="{j.type}">')
    out.append(f'    <parent link="{j.parent}"/>')
    out.append(f'    <child link="{j.child}"/>')
    out.append(f'    <origin xyz="{_xyz(j.xyz)}" rpy="0 0 0"/>')
    if j.type != "fixed":
        out.append(f'    <axis xyz="{_xyz(j.axis)}"/>')
        # effort/velocity are required by the URDF format; pinmsk does not use them.
        out.append(f'    <limit lower="{fnum(j.lower)}" upper="{fnum(j.upper)}" effort="1000" velocity="50"/>')
    out.append("  </joint>")
    return out


def render_urdf(robot: str, header: str, items: list) -> str:
    """URDF text; ``items`` is a list of Link/Joint in reading order."""
    out = ['<?xml version="1.0"?>']
    out += _comment(header, "")
    out.append(f'<robot name="{robot}">')
    for name, rgba in MATERIALS.items():
        out.append(f'  <material name="{name}"><color rgba="{_xyz(rgba)}"/></material>')
    for item in items:
        out.append("")
        out += _link_xml(item) if isinstance(item, Link) else _joint_xml(item)
    out.append("</robot>")
    return "\n".join(out) + "\n"


GENERATED_NOTE = (
    "GENERATED by urdf/generate.py - do not edit by hand; change the generator and rerun it.\n"
    "Conventions: world x forward, y up, z to the subject's right (as OpenSim);\n"
    "gravity (0, -9.81, 0) is declared in the sidecar TOML next to this file."
)

# =============================================================================
# Small TOML helpers (the sidecars are written as text so they keep comments)
# =============================================================================


def toml_str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def toml_list(values) -> str:
    return "[" + ", ".join(fnum(v) for v in values) + "]"


def toml_points(points) -> str:
    rows = [f"[{toml_str(b)}, {fnum(x)}, {fnum(y)}, {fnum(z)}]" for b, x, y, z in points]
    return "[\n    " + ",\n    ".join(rows) + ",\n]"


def toml_path(l0, arms: dict) -> str:
    inner = ", ".join(f"{k} = {toml_list(v)}" for k, v in arms.items())
    return f"{{ l0 = {fnum(l0)}, moment_arms = {{ {inner} }} }}"


def comment_block(text: str) -> str:
    return "\n".join(("# " + ln).rstrip() for ln in text.strip("\n").splitlines()) + "\n"


SCHEMA_NOTE = """\
Sidecar format: see urdf/README.md.  Units are SI (m, kg, N, rad, m^3).
Path variants: l_mt(q) = l0 - sum_j integral_0^{q_j} r_j(s) ds with the moment arm
r_j(s) = c0 + c1 s + c2 s^2 + ... given as [c0, c1, ...] per coordinate, so
r_j = -d l_mt / d q_j (positive = the muscle shortens when q_j increases).
`points` are for display only: a polyline through points fixed in bodies
([body, x, y, z] in the body frame); they do not define the path."""

# =============================================================================
# finger: 1-dof index finger at the MCP joint (Sec. 3.2.2)
# =============================================================================

# Segment lengths: Buchholz, Armstrong & Goldstein (1992), J. Biomech. 25:149,
# index-finger phalanx lengths as fractions of hand length, for a hand length of
# 0.19 m (adult male average).  The thesis takes its finger data from Buchner,
# Hines & Hemami (1988) [79]; those tables were not available here, so the
# numbers below are our own plausible composite, not the thesis's.
HAND_LENGTH = F("0.19")
PHALANGES = (
    # name, length ratio to hand length, mass (kg), radius (m)
    ("proximal", F("0.245"), F("0.013"), F("0.009")),
    ("middle", F("0.143"), F("0.006"), F("0.008")),
    ("distal", F("0.097"), F("0.003"), F("0.007")),
)
# Masses: each phalanx (with its soft tissue) as a uniform solid cylinder of
# density 1100 kg/m^3 and the radius above, rho*pi*R^2*L = 13.0, 6.0, 3.1 g,
# rounded to whole grams (the rounded value is what the model uses).
FINGER_F_MAX = F(100)  # N, Sec. 3.2.2 assumption 1
FINGER_MOMENT_ARM = F("0.010")  # m, Sec. 3.2.2 assumption 3
FINGER_MUSCLES = (
    # name, sign of moment arm, l_opt, l_slack.  Chosen: of the order of the
    # extrinsic index-finger muscles (FDP/FDS index, EDC index) in published
    # upper-limb models (optimal fiber length 6-9 cm, tendon slack 25-32 cm);
    # not copied from one table.  Pennation 0 (assumed).
    ("flexor", +1, F("0.075"), F("0.28")),
    ("extensor", -1, F("0.070"), F("0.32")),
)
SPECIFIC_TENSION = F(250000)  # Pa, thesis Eq. B.3 (sigma_m = 0.25 MPa)


def finger_body():
    """Composite of the three phalanges about the MCP joint, finger along +x."""
    parts = []
    x0 = F(0)
    for name, ratio, m, r in PHALANGES:
        length = ratio * HAND_LENGTH
        # uniform cylinder along x: COM at mid-length,
        # I_transverse = m (3 R^2 + L^2) / 12, I_axial = m R^2 / 2
        parts.append(
            dict(
                name=name,
                length=length,
                mass=m,
                radius=r,
                com=x0 + length / 2,
                i_trans=m * (3 * r * r + length * length) / 12,
                i_axial=m * r * r / 2,
            )
        )
        x0 += length
    mass = sum(p["mass"] for p in parts)
    com = sum(p["mass"] * p["com"] for p in parts) / mass
    # parallel-axis theorem; all COMs lie on the x axis, so only the transverse
    # moments (about y and z) get the m d^2 term.
    i_trans = sum(p["i_trans"] + p["mass"] * (p["com"] - com) ** 2 for p in parts)
    i_axial = sum(p["i_axial"] for p in parts)
    return dict(parts=parts, length=x0, mass=mass, com=com, izz=i_trans, iyy=i_trans, ixx=i_axial)


def finger_urdf(b) -> str:
    L = b["length"]
    arith = "\n".join(
        f"  {p['name']:8s} L = {fnum(p['length'])} m, m = {fnum(p['mass'])} kg, "
        f"R = {fnum(p['radius'])} m, COM x = {fnum(p['com'])} m"
        for p in b["parts"]
    )
    header = (
        f"{GENERATED_NOTE}\n\n"
        "finger: 1-dof index finger at the metacarpophalangeal (MCP) joint, thesis Sec. 3.2.2.\n"
        "The hand (palm) is fixed to the world; the finger points along +x at q = 0 (horizontal),\n"
        "mcp_flexion rotates about -z so q > 0 is flexion (the tip moves down): gravity flexes it.\n"
        "Composite of three phalanges (uniform cylinders, Buchholz et al. 1992 length ratios,\n"
        f"hand length {fnum(HAND_LENGTH)} m):\n{arith}\n"
        f"  total m = {fnum(b['mass'])} kg, length = {fnum(L)} m, COM x = {fnum(b['com'])} m,\n"
        f"  Izz = Iyy = {fnum(b['izz'])} kg m^2 about the COM (parallel-axis), Ixx = {fnum(b['ixx'])}."
    )
    items = [
        Link(
            "palm",
            visuals=(Visual("box", (F("0.09"), F("0.025"), F("0.08")), xyz=(F("-0.045"), 0, 0), material="fixed"),),
            comment="Metacarpals/palm, fixed to the world (massless here: it never moves). Origin = MCP joint centre.",
        ),
        Joint(
            "mcp_flexion",
            "revolute",
            "palm",
            "finger",
            axis=(0, 0, -1),
            lower=F("-0.5"),
            upper=F("1.6"),
            comment="MCP flexion, + = flexion (tip down). Limits are advisory.",
        ),
        Link(
            "finger",
            Inertial(b["mass"], (b["com"], 0, 0), b["ixx"], b["iyy"], b["izz"]),
            visuals=tuple(
                Visual("cylinder", (p["radius"], p["length"]), xyz=(p["com"], 0, 0), rpy=CYL_ALONG_X)
                for p in b["parts"]
            ),
            comment="Proximal + middle + distal phalanx as one rigid body (fixed PIP/DIP). Origin = MCP joint.",
        ),
        Joint("fingertip_joint", "fixed", "finger", "fingertip", xyz=(L, 0, 0)),
        Link("fingertip", comment="Frame at the tip of the distal phalanx."),
    ]
    return render_urdf("finger", header, items)


def model_table(name: str, description: str) -> list[str]:
    """The ``[model]`` table of a built-in model's TOML (``<name>.urdf``, y up, constant paths by default)."""
    return [
        "[model]",
        f"name = {toml_str(name)}",
        f"urdf = {toml_str(name + '.urdf')}",
        "gravity = [0.0, -9.81, 0.0]",
        'up_axis = "y"',
        f"description = {toml_str(description)}",
        'default_paths = "constant"',
    ]


def finger_toml(b) -> str:
    out = [
        comment_block(
            f"""
finger - 1-dof index finger at the metacarpophalangeal joint (thesis Sec. 3.2.2).
GENERATED by urdf/generate.py from the numbers quoted there; rerun it instead of editing.

Skeleton (finger.urdf): palm fixed to the world, finger horizontal along +x at q = 0,
joint `mcp_flexion` about -z: q > 0 = flexion (tip moves down), so gravity flexes the
finger, as in the thesis's horizontal pendulum with gravity.
Finger body (our composite, NOT the thesis's [79] values, which were unavailable):
three phalanges as uniform cylinders of density ~1100 kg/m^3; lengths from
Buchholz, Armstrong & Goldstein (1992) ratios x hand length {fnum(HAND_LENGTH)} m:
  mass {fnum(b['mass'])} kg, length {fnum(b['length'])} m, COM {fnum(b['com'])} m from the MCP,
  Izz about the COM {fnum(b['izz'])} kg m^2.

Muscles (Sec. 3.2.2): F_max = 100 N both (assumption 1); constant moment arms 10 mm
(assumption 3), flexor +, extensor - (r = -dl/dq).  Thelen (2003) parameters are
our choice: l_opt, l_slack of the order of the extrinsic index-finger muscles
(FDP/EDC index) in published upper-limb models, pennation 0.  l0 = l_slack + l_opt
so the fibers are at optimal length at q = 0 (the centre of the +-0.21 rad tapping
motion, Eq. 3.1) with a rigid tendon.  volume = F_max l_opt / sigma, sigma = 0.25 MPa (Eq. B.3).

{SCHEMA_NOTE}
"""
        ),
        *model_table("finger", "1-dof index finger (MCP flexion) with one flexor and one extensor, thesis Sec. 3.2.2"),
        "",
        "[muscle_model]",
        'type = "thelen2003"',
        'tendon = "rigid"',
        "",
    ]
    for name, sign, l_opt, l_slack in FINGER_MUSCLES:
        r = sign * FINGER_MOMENT_ARM
        l0 = l_slack + l_opt
        volume = FINGER_F_MAX * l_opt / SPECIFIC_TENSION
        side = -1 if sign > 0 else 1  # flexor on the palmar side (-y), extensor dorsal (+y)
        points = [
            ("palm", F("-0.07"), side * F("0.010"), 0),
            ("palm", F("-0.005"), side * F("0.011"), 0),
            ("finger", F("0.012"), side * F("0.009"), 0),
        ]
        out += [
            "[[muscles]]",
            f"name = {toml_str(name)}",
            f"f_max = {fnum(FINGER_F_MAX)}",
            f"l_opt = {fnum(l_opt)}",
            f"l_slack = {fnum(l_slack)}",
            "pennation = 0.0",
            f"volume = {fnum(volume)}",
            f"paths.constant = {toml_path(l0, {'mcp_flexion': [r]})}",
            f"points = {toml_points(points)}",
            "",
        ]
    return "\n".join(out)


# =============================================================================
# forearm: 1-dof elbow with 7 muscles (Sec. 3.3.2, Tables 3.2 and 3.5)
# =============================================================================

BODY_MASS = F(80)  # kg, Sec. 3.3.2
BODY_HEIGHT = F("1.8")  # m
# Winter (2005) Table 4.1 [thesis ref 10]: fraction of BM, length as fraction of
# BH, COM from the proximal end / length, radius of gyration about COM / length.
WINTER_FOREARM = dict(mass=F("0.016"), length=F("0.146"), com=F("0.430"), rog=F("0.303"))
WINTER_HAND = dict(mass=F("0.006"), length=F("0.108"), com=F("0.506"), rog=F("0.297"))
WINTER_UPPER_ARM_LENGTH = F("0.186")  # BH; the upper arm is fixed (display only)
# Longitudinal radius of gyration (about the long axis) / length: de Leva (1996)
# forearm value, used for forearm and hand.  Only makes the 3D inertia valid;
# it does not enter the elbow-flexion dynamics.
LONGITUDINAL_ROG = F("0.121")
ELBOW_RANGE = (F(0), F("2.6"))  # rad

# Table 3.2 (Garner & Pandy 2001): l_opt (cm), F_max (N), l_slack (cm), pennation (deg), V (cm^3)
TABLE_3_2 = (
    ("BRD", "27.03", "101.58", "6.04", "5.00", "83.19"),
    ("BICLH", "15.36", "392.91", "22.93", "10.00", "182.92"),
    ("BICSH", "13.07", "461.76", "22.98", "10.00", "182.92"),
    ("BRA", "10.28", "853.90", "1.75", "15.00", "256.96"),
    ("TRILH", "15.24", "692.21", "19.05", "15.00", "290.67"),
    ("TRIMH", "6.17", "1268.87", "19.64", "15.00", "237.28"),
    ("TRILT", "4.90", "619.67", "12.19", "15.00", "92.04"),
)
# Table 3.5 (Veeger et al. 1997 averages): |r| in cm; flexors +, triceps -.
TABLE_3_5 = {"BRD": "5.40", "BICLH": "2.73", "BICSH": "3.70", "BRA": "2.10", "TRILH": "2.00", "TRIMH": "2.58", "TRILT": "2.00"}
FLEXORS = ("BRD", "BICLH", "BICSH", "BRA")
# `angle` path shapes (an approximation, NOT Garner & Pandy's or Murray's data):
#   flexors: r(q) proportional to 1 - kappa (q - q_peak)^2 with r(0) = rho r(q_peak),
#   triceps: |r(q)| proportional to 1 - delta q / q_max (|r| at full flexion = 0.75 |r(0)|),
# each scaled so that its mean over [0, 2.6] rad equals the Table 3.5 value.
FLEXOR_SHAPE = {  # q_peak (rad), rho
    "BRD": (F("1.8"), F("0.35")),  # peak ~103 deg
    "BICLH": (F("1.65"), F("0.4")),  # peak ~95 deg
    "BICSH": (F("1.65"), F("0.4")),
    "BRA": (F("1.6"), F("0.5")),  # peak ~92 deg, flatter
}
TRICEPS_DELTA = F("0.25")


def forearm_body():
    bm, bh = BODY_MASS, BODY_HEIGHT
    fa, ha = WINTER_FOREARM, WINTER_HAND
    m_f, L_f = fa["mass"] * bm, fa["length"] * bh
    m_h, L_h = ha["mass"] * bm, ha["length"] * bh
    d_f = fa["com"] * L_f  # elbow -> forearm COM
    d_h = L_f + ha["com"] * L_h  # elbow -> hand COM (wrist at the end of the forearm)
    k_f, k_h = fa["rog"] * L_f, ha["rog"] * L_h
    mass = m_f + m_h
    com = (m_f * d_f + m_h * d_h) / mass  # distance from the elbow along the forearm
    # parallel-axis theorem about the combined COM (transverse axes x and z)
    i_trans = m_f * (k_f**2 + (d_f - com) ** 2) + m_h * (k_h**2 + (d_h - com) ** 2)
    i_long = m_f * (LONGITUDINAL_ROG * L_f) ** 2 + m_h * (LONGITUDINAL_ROG * L_h) ** 2
    return dict(
        m_f=m_f, L_f=L_f, d_f=d_f, k_f=k_f, m_h=m_h, L_h=L_h, d_h=d_h, k_h=k_h,
        mass=mass, com=com, izz=i_trans, ixx=i_trans, iyy=i_long,
        L_u=WINTER_UPPER_ARM_LENGTH * bh,
        # inertia about the elbow axis, handy for hand checks: I_elbow = Izz + m com^2
        i_elbow=i_trans + mass * com**2,
    )


def forearm_urdf(b) -> str:
    header = (
        f"{GENERATED_NOTE}\n\n"
        "forearm: 1-dof elbow, thesis Sec. 3.3.2.  Upper arm fixed to the world and vertical,\n"
        "shoulder at the world origin, elbow at y = -L_upper.  elbow_flexion rotates about +z:\n"
        "q = 0 forearm hangs straight down, q > 0 = flexion (q = pi/2: forearm points forward, +x).\n"
        "Forearm + hand = one rigid body, Winter's anthropometry for BM = 80 kg, BH = 1.80 m:\n"
        f"  forearm m = 0.016 BM = {fnum(b['m_f'])} kg, L = 0.146 BH = {fnum(b['L_f'])} m,\n"
        f"          COM 0.430 L = {fnum(b['d_f'])} m from the elbow, k = 0.303 L = {fnum(b['k_f'])} m\n"
        f"  hand    m = 0.006 BM = {fnum(b['m_h'])} kg, L = 0.108 BH = {fnum(b['L_h'])} m,\n"
        f"          COM L_f + 0.506 L_h = {fnum(b['d_h'])} m from the elbow, k = 0.297 L_h = {fnum(b['k_h'])} m\n"
        f"  combined m = {fnum(b['mass'])} kg, COM = (m_f d_f + m_h d_h) / m = {fnum(b['com'])} m from the elbow\n"
        f"  Izz = m_f (k_f^2 + (d_f - c)^2) + m_h (k_h^2 + (d_h - c)^2) = {fnum(b['izz'])} kg m^2 about the COM\n"
        f"  (about the elbow: {fnum(b['i_elbow'])} kg m^2); Iyy (long axis) uses RoG 0.121 L (de Leva 1996)."
    )
    L_u, L_f, L_h = b["L_u"], b["L_f"], b["L_h"]
    items = [
        Link(
            "upper_arm",
            visuals=(Visual("cylinder", (F("0.04"), L_u), xyz=(0, -L_u / 2, 0), rpy=CYL_ALONG_Y, material="fixed"),),
            comment=(
                "Upper arm, fixed to the world (massless here: it never moves). Origin = glenohumeral joint;\n"
                f"the humerus runs down -y to the elbow at y = -{fnum(L_u)} m (0.186 BH, Winter). Muscle origins attach here."
            ),
        ),
        Joint(
            "elbow_flexion",
            "revolute",
            "upper_arm",
            "forearm_hand",
            xyz=(0, -L_u, 0),
            axis=(0, 0, 1),
            lower=ELBOW_RANGE[0],
            upper=ELBOW_RANGE[1],
            comment="Elbow flexion about +z; 0 = forearm hanging down, + = flexion.",
        ),
        Link(
            "forearm_hand",
            Inertial(b["mass"], (0, -b["com"], 0), b["ixx"], b["iyy"], b["izz"]),
            visuals=(
                Visual("cylinder", (F("0.03"), L_f), xyz=(0, -L_f / 2, 0), rpy=CYL_ALONG_Y),
                Visual("box", (F("0.03"), L_h, F("0.08")), xyz=(0, -L_f - L_h / 2, 0)),
            ),
            comment="Forearm + hand as one rigid body (wrist fixed). Origin = elbow joint centre; forearm along -y.",
        ),
        Joint("hand_joint", "fixed", "forearm_hand", "hand", xyz=(0, -b["d_h"], 0)),
        Link("hand", comment="Frame at the hand's centre of mass (0.506 of hand length distal to the wrist)."),
    ]
    return render_urdf("forearm", header, items)


def _poly_mean(coeffs, q_max):
    """Mean of sum_k c_k q^k over [0, q_max] (exact)."""
    return sum(c * q_max**k / (k + 1) for k, c in enumerate(coeffs))


def _poly_integral(coeffs, q):
    return sum(c * q ** (k + 1) / (k + 1) for k, c in enumerate(coeffs))


def forearm_angle_coeffs(name: str):
    """`angle` moment-arm polynomial [c0, c1, c2] (exact) for one muscle."""
    r_mean = F(TABLE_3_5[name]) / 100
    q_max = ELBOW_RANGE[1]
    if name in FLEXORS:
        q_peak, rho = FLEXOR_SHAPE[name]
        kappa = (1 - rho) / q_peak**2
        shape = [rho, 2 * kappa * q_peak, -kappa]  # = 1 - kappa (q - q_peak)^2
        sign = 1
    else:
        shape = [F(1), -TRICEPS_DELTA / q_max]
        sign = -1
    scale = sign * r_mean / _poly_mean(shape, q_max)
    return [scale * c for c in shape]


def forearm_muscles():
    q_mid = (ELBOW_RANGE[0] + ELBOW_RANGE[1]) / 2
    rows = []
    for name, l_opt, f_max, l_slack, penn, vol in TABLE_3_2:
        l_opt_m = F(l_opt) / 100
        l_slack_m = F(l_slack) / 100
        alpha = math.radians(float(F(penn)))
        # fibers at optimal length at mid-range with a rigid tendon:
        # l_mt(q_mid) = l_slack + l_opt cos(alpha)  =>  l0 = that + integral_0^{q_mid} r
        l_ref = float(l_slack_m) + float(l_opt_m) * math.cos(alpha)
        r_const = (1 if name in FLEXORS else -1) * F(TABLE_3_5[name]) / 100
        c_angle = forearm_angle_coeffs(name)
        rows.append(
            dict(
                name=name,
                f_max=F(f_max),
                l_opt=l_opt_m,
                l_slack=l_slack_m,
                pennation=alpha,
                volume=F(vol) / 10**6,
                r_const=r_const,
                l0_const=l_ref + float(_poly_integral([r_const], q_mid)),
                c_angle=c_angle,
                l0_angle=l_ref + float(_poly_integral(c_angle, q_mid)),
            )
        )
    return rows


def forearm_points(name: str, b):
    """Display polylines (origin on upper_arm, insertion on forearm_hand)."""
    e = -b["L_u"]  # elbow y in the upper-arm frame
    P = {
        "BRD": [("upper_arm", "0.012", e + F("0.07")), ("forearm_hand", "0.015", F("-0.24"))],
        "BICLH": [("upper_arm", "0.02", F("-0.01")), ("upper_arm", "0.025", e + F("0.05")), ("forearm_hand", "0.012", F("-0.045"))],
        "BICSH": [("upper_arm", "0.03", F("-0.03")), ("upper_arm", "0.03", e + F("0.06")), ("forearm_hand", "0.012", F("-0.045"))],
        "BRA": [("upper_arm", "0.012", e + F("0.10")), ("forearm_hand", "0.008", F("-0.03"))],
        "TRILH": [("upper_arm", "-0.025", F("-0.03")), ("upper_arm", "-0.025", e + F("0.05")), ("forearm_hand", "-0.02", F("0.015"))],
        "TRIMH": [("upper_arm", "-0.012", e + F("0.15")), ("upper_arm", "-0.02", e + F("0.04")), ("forearm_hand", "-0.02", F("0.015"))],
        "TRILT": [("upper_arm", "-0.015", F("-0.08")), ("upper_arm", "-0.025", e + F("0.05")), ("forearm_hand", "-0.02", F("0.015"))],
    }[name]
    return [(body, F(x), y, 0) for body, x, y in P]


def forearm_toml(b) -> str:
    out = [
        comment_block(
            f"""
forearm - 1-dof elbow with seven muscles (thesis Sec. 3.3.2, Tables 3.2 and 3.5).
GENERATED by urdf/generate.py; rerun it instead of editing.

Skeleton (forearm.urdf): upper arm fixed to the world, vertical (shoulder at the origin,
elbow {fnum(b['L_u'])} m below).  Joint `elbow_flexion` about +z, 0 = forearm hanging
straight down, + = flexion, limits [0, 2.6] rad.  Forearm + hand are one rigid body
(Winter 2005 anthropometry, BM 80 kg, BH 1.80 m): mass {fnum(b['mass'])} kg, COM
{fnum(b['com'])} m from the elbow, Izz {fnum(b['izz'])} kg m^2 about the COM.
Frame `hand` = the hand's centre of mass, {fnum(b['d_h'])} m from the elbow.

Muscles: Table 3.2 (Garner & Pandy 2001) converted to SI: cm -> m, deg -> rad, cm^3 -> m^3.
Two path variants (r = -dl/dq; flexors BRD, BICLH, BICSH, BRA > 0, triceps < 0):
  constant: Table 3.5 moment arms (averages of Veeger et al. 1997), as in Sec. 3.4.
  angle:    a smooth APPROXIMATION of the known pattern, NOT Garner & Pandy's or
            Murray's data (the thesis's Fig. 3.5 curves are not tabulated):
            flexors r(q) = s (1 - kappa (q - q_peak)^2), r(0) = rho r(q_peak),
              BRD q_peak 1.8 rad (103 deg) rho 0.35; BICLH/BICSH 1.65 rad (95 deg) rho 0.4;
              BRA 1.6 rad (92 deg) rho 0.5;
            triceps r(q) = s (1 - 0.25 q / 2.6): |r| falls by 25 % from extension to 2.6 rad;
            s chosen so the mean of r over [0, 2.6] rad equals the Table 3.5 value.
l0 (= l_mt at q = 0) is chosen per muscle and variant so that, with a rigid tendon,
the fibers are at optimal length at mid-range q = 1.3 rad:
  l_mt(1.3) - l_slack = l_opt cos(pennation).
Over the full range the rigid-tendon fiber excursion is +-r*1.3 rad; for the short-fibered
TRIMH and TRILT that is about +-50 % of l_opt (Table 3.2 has long tendons for them).

{SCHEMA_NOTE}
"""
        ),
        *model_table("forearm", "1-dof elbow (flexion) with seven muscles, thesis Sec. 3.3.2 (Tables 3.2, 3.5)"),
        "",
        "[muscle_model]",
        'type = "thelen2003"',
        'tendon = "rigid"',
        "",
    ]
    for m in forearm_muscles():
        name = m["name"]
        src = next(row for row in TABLE_3_2 if row[0] == name)
        out += [
            "[[muscles]]",
            f"# Table 3.2: l_opt {src[1]} cm, F_max {src[2]} N, l_slack {src[3]} cm, "
            f"pennation {src[4]} deg, V {src[5]} cm^3; Table 3.5: r = {TABLE_3_5[name]} cm",
            f"name = {toml_str(name)}",
            f"f_max = {fnum(m['f_max'])}",
            f"l_opt = {fnum(m['l_opt'])}",
            f"l_slack = {fnum(m['l_slack'])}",
            f"pennation = {fnum(m['pennation'])}",
            f"volume = {fnum(m['volume'])}",
            f"paths.constant = {toml_path(m['l0_const'], {'elbow_flexion': [m['r_const']]})}",
            f"paths.angle = {toml_path(m['l0_angle'], {'elbow_flexion': m['c_angle']})}",
            f"points = {toml_points(forearm_points(name, b))}",
            "",
        ]
    return "\n".join(out)


# =============================================================================
# gait2d: 9 segments, 11 dof (Sec. 5.1, Tables 5.1-5.3, Sec. 4.1.1 Table 4.1)
# =============================================================================

GAIT_BM = F("64.740")  # kg, Table 5.1
GAIT_BH = F("1.696")  # m
# Table 5.1 (Winter): mass / BM, COM from the proximal end / length, RoG / length, length / BH
TABLE_5_1 = {
    "shank": dict(mass=F("0.0465"), dp=F("0.433"), rog=F("0.302"), length=F("0.246")),
    "thigh": dict(mass=F("0.100"), dp=F("0.433"), rog=F("0.323"), length=F("0.245")),
    # HAT length = glenohumeral joint to greater trochanter; COM 0.626 L from the shoulder
    "hat": dict(mass=F("0.678"), dp=F("0.626"), rog=F("0.496"), length=F("0.288")),
}
# Table 5.2 (Anderson & Pandy 1999): mass (kg), COM at dP = 0.5 of the segment, Izz (kg m^2)
TABLE_5_2 = {
    "hindfoot": dict(mass=F("0.6"), izz=F("0.0013")),
    "forefoot": dict(mass=F("0.6"), izz=F("0.0013")),
    "toes": dict(mass=F("0.2"), izz=F("0.0001")),
}
# Table 4.1: foot geometry (m, deg)
FOOT_AH, FOOT_AP, FOOT_PT, FOOT_BETA_DEG = F("0.074"), F("0.110"), F("0.073"), 106
# Out-of-plane inertia (the motion is planar, only Izz matters): for a segment
# along y, Ixx = Izz and Iyy = Izz / 4; for a segment along x (foot, toes),
# Iyy = Izz and Ixx = Izz / 4.  Valid (triangle inequalities hold), dynamically inert.
OUT_OF_PLANE_RATIO = Fraction(1, 4)
# Lateral offset of each hip from the HAT's midline, z = +offset right / -offset left.
# Display only: with all joints about z and gravity along -y it changes no
# generalized force, mass-matrix entry or contact force in the plane.
HIP_HALF_WIDTH = F("0.085")

# Table 5.3 (Ackermann 2007 / Gerritsen et al. 1998; pennation Menegaldo et al. 2003):
# F_max (N), l_opt (m), l_slack (m), pennation (deg), f_fast, r_A, r_K, r_H (m), l0 (m), width
TABLE_5_3 = (
    ("iliopsoas", "Ilio", "821", "0.102", "0.142", "7.5", "0.50", "0", "0", "-0.050", "0.248", "1.298"),
    ("rectus_femoris", "RF", "663", "0.081", "0.398", "5.0", "0.65", "0", "0.050", "-0.034", "0.474", "1.443"),
    ("glutei", "Gl", "1705", "0.200", "0.157", "3.0", "0.45", "0", "0", "0.062", "0.271", "0.625"),
    ("hamstrings", "Hams", "1770", "0.104", "0.334", "7.5", "0.35", "0", "-0.034", "0.072", "0.383", "1.197"),
    ("vasti", "Vas", "7403", "0.093", "0.223", "4.4", "0.50", "0", "0.042", "0", "0.271", "0.627"),
    ("gastrocnemius", "Gast", "1639", "0.055", "0.420", "14.3", "0.50", "0.053", "-0.020", "0", "0.404", "0.888"),
    ("tibialis_anterior", "TA", "1528", "0.082", "0.317", "6.0", "0.25", "-0.037", "0", "0", "0.464", "0.442"),
    ("soleus", "Sol", "3883", "0.055", "0.245", "23.6", "0.20", "0.053", "0", "0", "0.201", "1.039"),
)
TENDON_STRAIN = F("0.04")  # eps0 in Eq. A.11 (Winters quadratic tendon)

GAIT_JOINT_ORDER = (
    "torso_x", "torso_y", "torso_angle", "hip_r", "hip_l", "knee_r", "knee_l",
    "ankle_r", "ankle_l", "mtp_r", "mtp_l",
)  # Eq. 5.1


def foot_geometry():
    """Heel H, metatarsal P, toe T in the foot frame (origin = ankle A), standing at q = 0.

    Interpretation of beta (Table 4.1): the angle HAP at the ankle between the
    rays A->H and A->P.  Standing (ankle = 0) puts H and P on the ground, so
    both lie at the same height -h below A:
        AH cos(th_H) = AP cos(th_P) = h,  th_H + th_P = beta
    (th_H, th_P = angles of AH and AP from the downward vertical), giving
        tan(th_H) = (AH - AP cos beta) / (AP sin beta).
    T lies PT ahead of P on the ground (toes flat at mtp = 0).
    """
    beta = math.radians(FOOT_BETA_DEG)
    AH, AP, PT = float(FOOT_AH), float(FOOT_AP), float(FOOT_PT)
    th_h = math.atan2(AH - AP * math.cos(beta), AP * math.sin(beta))
    th_p = beta - th_h
    h = AH * math.cos(th_h)
    H = (-AH * math.sin(th_h), -h)
    P = (AP * math.sin(th_p), -AP * math.cos(th_p))
    T = (P[0] + PT, P[1])
    return dict(theta_h=th_h, theta_p=th_p, height=h, H=H, P=P, T=T)


def gait_bodies():
    bm, bh = GAIT_BM, GAIT_BH
    seg = {}
    for name, t in TABLE_5_1.items():
        m, L = t["mass"] * bm, t["length"] * bh
        k = t["rog"] * L
        seg[name] = dict(mass=m, length=L, dp=t["dp"] * L, izz=m * k * k)
    hat = seg["hat"]
    # the hips are (1 - 0.626) L_HAT below the HAT COM (COM is 0.626 L below the shoulder)
    hat["hip_drop"] = (1 - TABLE_5_1["hat"]["dp"]) * hat["length"]
    geo = foot_geometry()
    H, P = geo["H"], geo["P"]
    hf, ff, to = TABLE_5_2["hindfoot"], TABLE_5_2["forefoot"], TABLE_5_2["toes"]
    # hind-foot spans A-H and fore-foot spans A-P (Fig. 4.1); each COM at dP = 0.5
    c_h = (H[0] / 2, H[1] / 2)
    c_f = (P[0] / 2, P[1] / 2)
    m_foot = hf["mass"] + ff["mass"]
    w_h, w_f = float(hf["mass"] / m_foot), float(ff["mass"] / m_foot)
    c = (w_h * c_h[0] + w_f * c_f[0], w_h * c_h[1] + w_f * c_f[1])
    d2 = lambda a: (a[0] - c[0]) ** 2 + (a[1] - c[1]) ** 2  # noqa: E731
    izz_foot = float(hf["izz"] + ff["izz"]) + float(hf["mass"]) * d2(c_h) + float(ff["mass"]) * d2(c_f)
    seg["foot"] = dict(mass=m_foot, com=c, izz=izz_foot, hind_com=c_h, fore_com=c_f)
    seg["toes"] = dict(mass=to["mass"], com=(FOOT_PT / 2, 0), izz=to["izz"])
    total = hat["mass"] + 2 * (seg["thigh"]["mass"] + seg["shank"]["mass"] + m_foot + to["mass"])
    standing_y = float(hat["hip_drop"] + seg["thigh"]["length"] + seg["shank"]["length"]) + geo["height"]
    return dict(seg=seg, geo=geo, total_mass=total, standing_torso_y=standing_y)


def _along_y(m, com_y, izz):
    """Segment along y: Ixx = Izz, Iyy (long axis) = Izz / 4."""
    return Inertial(m, (0, com_y, 0), izz, izz * OUT_OF_PLANE_RATIO, izz)


def _along_x(m, com, izz):
    """Segment along x (foot, toes): Iyy = Izz, Ixx (long axis) = Izz / 4."""
    return Inertial(m, (com[0], com[1], 0), izz * OUT_OF_PLANE_RATIO, izz, izz)


def gait_urdf(g) -> str:
    seg, geo = g["seg"], g["geo"]
    hat, thigh, shank, foot, toes = (seg[k] for k in ("hat", "thigh", "shank", "foot", "toes"))
    H, P = geo["H"], geo["P"]
    header = (
        f"{GENERATED_NOTE}\n\n"
        "gait2d: sagittal 9-segment, 11-dof gait model, thesis Sec. 5.1 (Eq. 5.1, Tables 5.1, 5.2, 4.1).\n"
        "torso_x / torso_y: prismatic along world x / y through massless slider links, so\n"
        "(q[torso_x], q[torso_y]) is the HAT centre of mass in the world (Eq. 5.1); torso_angle and\n"
        "every leg joint rotate about (0, 0, -1), so: torso_angle + = forward lean, hip + = extension,\n"
        "knee + = flexion, ankle + = plantarflexion, mtp + = toe flexion (toes down).  q = 0 is upright\n"
        "standing: segments vertical, foot perpendicular to the shank (thesis phi_A = ankle, see the\n"
        f"muscle notes), heel and metatarsal head on the ground y = 0 when torso_y = {g['standing_torso_y']!r} m.\n"
        "Joint order: Pinocchio's URDF parser orders joints depth-first, siblings by joint name,\n"
        "giving torso_x, torso_y, torso_angle, hip_l, knee_l, ankle_l, mtp_l, hip_r, knee_r, ankle_r,\n"
        "mtp_r; Pinocchio needs subtrees contiguous, so no joint order can be Eq. 5.1's interleaved\n"
        "one.  The sidecar's [model] coordinate_order (Eq. 5.1) is applied at the Pinocchio boundary\n"
        "by name (pinmsk.Model.coordinate_order orders the written columns).\n"
        f"BM = {fnum(GAIT_BM)} kg, BH = {fnum(GAIT_BH)} m.  Total mass = {fnum(g['total_mass'])} kg\n"
        "  = BM (0.678 + 2 x 0.100 + 2 x 0.0465) + 2 x (0.6 + 0.6 + 0.2).\n"
        f"HAT   m = {fnum(hat['mass'])} L = {fnum(hat['length'])} Izz = {fnum(hat['izz'])}; hips {fnum(hat['hip_drop'])} m below the HAT COM\n"
        f"thigh m = {fnum(thigh['mass'])} L = {fnum(thigh['length'])} COM {fnum(thigh['dp'])} below the hip, Izz = {fnum(thigh['izz'])}\n"
        f"shank m = {fnum(shank['mass'])} L = {fnum(shank['length'])} COM {fnum(shank['dp'])} below the knee, Izz = {fnum(shank['izz'])}\n"
        f"foot  m = {fnum(foot['mass'])} (hind-foot + fore-foot) COM {_xyz(foot['com'])} from the ankle, Izz = {fnum(foot['izz'])}\n"
        f"toes  m = {fnum(toes['mass'])} COM {_xyz(toes['com'])} from the MTP joint, Izz = {fnum(toes['izz'])}\n"
        f"Foot (Table 4.1, beta read as the angle HAP at the ankle): ankle height {geo['height']!r} m,\n"
        f"H = {_xyz(H)}, P = {_xyz(P)} from the ankle; T = P + ({fnum(FOOT_PT)}, 0)."
    )
    items = [
        Link("ground", comment="World-fixed root (massless). The ground plane is y = 0."),
        Joint("torso_x", "prismatic", "ground", "torso_x_slider", axis=(1, 0, 0), lower=-50, upper=50,
              comment="Eq. 5.1 X_tor: HAT COM horizontal position."),
        Link("torso_x_slider", comment="Massless intermediate link."),
        Joint("torso_y", "prismatic", "torso_x_slider", "torso_y_slider", axis=(0, 1, 0), lower=-1, upper=3,
              comment="Eq. 5.1 Y_tor: HAT COM height above the ground."),
        Link("torso_y_slider", comment="Massless intermediate link."),
        Joint("torso_angle", "revolute", "torso_y_slider", "hat", axis=(0, 0, -1),
              lower=-math.pi / 2, upper=math.pi / 2,
              comment="Eq. 5.1 phi_T (measured from upright here; the thesis's phi_T = pi/2 when upright), + = forward lean."),
        Link(
            "hat",
            _along_y(hat["mass"], 0, hat["izz"]),
            visuals=(
                # trunk box from the hips (0.374 L below the COM) to the shoulders (0.626 L above)
                Visual("box", (F("0.16"), hat["length"], F("0.30")), xyz=(0, hat["dp"] - hat["length"] / 2, 0), material="trunk"),
                Visual("sphere", (F("0.10"),), xyz=(0, hat["dp"] + F("0.15"), 0), material="trunk"),
            ),
            comment="Head, arms and trunk. Origin = HAT centre of mass; shoulder 0.626 L above, hips 0.374 L below.",
        ),
    ]
    for side, sgn, mat in (("r", 1, "right"), ("l", -1, "left")):
        z = sgn * HIP_HALF_WIDTH
        Lt, Ls = thigh["length"], shank["length"]
        items += [
            Joint(f"hip_{side}", "revolute", "hat", f"thigh_{side}", xyz=(0, -hat["hip_drop"], z), axis=(0, 0, -1),
                  lower=F("-2.2"), upper=F("0.7"), comment=f"Hip, + = extension. z = {fnum(z)} is display only."),
            Link(f"thigh_{side}", _along_y(thigh["mass"], -thigh["dp"], thigh["izz"]),
                 visuals=(Visual("cylinder", (F("0.05"), Lt), xyz=(0, -Lt / 2, 0), rpy=CYL_ALONG_Y, material=mat),),
                 comment="Thigh. Origin = hip joint centre, femur along -y."),
            Joint(f"knee_{side}", "revolute", f"thigh_{side}", f"shank_{side}", xyz=(0, -Lt, 0), axis=(0, 0, -1),
                  lower=F("-0.2"), upper=F("2.5"), comment="Knee, + = flexion."),
            Link(f"shank_{side}", _along_y(shank["mass"], -shank["dp"], shank["izz"]),
                 visuals=(Visual("cylinder", (F("0.04"), Ls), xyz=(0, -Ls / 2, 0), rpy=CYL_ALONG_Y, material=mat),),
                 comment="Shank. Origin = knee joint centre, tibia along -y."),
            Joint(f"ankle_{side}", "revolute", f"shank_{side}", f"foot_{side}", xyz=(0, -Ls, 0), axis=(0, 0, -1),
                  lower=F("-0.8"), upper=F("1.0"),
                  comment="Ankle, + = plantarflexion; 0 = foot perpendicular to the shank (thesis phi_A = ankle)."),
            Link(f"foot_{side}", _along_x(foot["mass"], foot["com"], foot["izz"]),
                 visuals=(Visual("box", (P[0] - H[0], geo["height"], F("0.08")),
                                 xyz=((P[0] + H[0]) / 2, -geo["height"] / 2, 0), material=mat),),
                 comment="Hind-foot + fore-foot (Table 5.2). Origin = ankle joint centre A."),
            Joint(f"heel_{side}_joint", "fixed", f"foot_{side}", f"heel_{side}", xyz=(H[0], H[1], 0)),
            Link(f"heel_{side}", comment="Heel contact point H (Fig. 4.1)."),
            Joint(f"metatarsal_{side}_joint", "fixed", f"foot_{side}", f"metatarsal_{side}", xyz=(P[0], P[1], 0)),
            Link(f"metatarsal_{side}", comment="First metatarsal head P (Fig. 4.1); the MTP joint sits here."),
            Joint(f"mtp_{side}", "revolute", f"foot_{side}", f"toes_{side}", xyz=(P[0], P[1], 0), axis=(0, 0, -1),
                  lower=F("-1.0"), upper=F("0.6"), comment="Metatarsophalangeal joint at P, + = toe flexion (toes down)."),
            Link(f"toes_{side}", _along_x(toes["mass"], toes["com"], toes["izz"]),
                 visuals=(Visual("box", (FOOT_PT, F("0.015"), F("0.08")), xyz=(FOOT_PT / 2, F("0.0075"), 0), material=mat),),
                 comment="Phalanges (Table 5.2 toes). Origin = MTP joint at P."),
            Joint(f"toe_{side}_joint", "fixed", f"toes_{side}", f"toe_{side}", xyz=(FOOT_PT, 0, 0)),
            Link(f"toe_{side}", comment="Toe tip T (Fig. 4.1), PT ahead of P."),
        ]
    return render_urdf("gait2d", header, items)


def gait_points(name: str, side: str, g):
    hat, thigh, shank = g["seg"]["hat"], g["seg"]["thigh"], g["seg"]["shank"]
    z = (1 if side == "r" else -1) * HIP_HALF_WIDTH
    hy = -hat["hip_drop"]
    Lt, Ls = thigh["length"], shank["length"]
    T, S, Fo = f"thigh_{side}", f"shank_{side}", f"foot_{side}"
    pts = {
        "iliopsoas": [("hat", "0.02", hy + F("0.12"), z), ("hat", "0.05", hy + F("0.01"), z), (T, "0.01", F("-0.06"), 0)],
        "rectus_femoris": [("hat", "0.04", hy + F("0.04"), z), (T, "0.055", -Lt + F("0.02"), 0), (S, "0.04", F("-0.06"), 0)],
        "glutei": [("hat", "-0.09", hy + F("0.10"), z), ("hat", "-0.07", hy - F("0.02"), z), (T, "-0.02", F("-0.08"), 0)],
        "hamstrings": [("hat", "-0.05", hy - F("0.04"), z), (T, "-0.045", -Lt + F("0.05"), 0), (S, "-0.03", F("-0.05"), 0)],
        "vasti": [(T, "0.03", F("-0.20"), 0), (T, "0.055", -Lt + F("0.03"), 0), (S, "0.04", F("-0.06"), 0)],
        "gastrocnemius": [(T, "-0.02", -Lt + F("0.04"), 0), (S, "-0.045", F("-0.12"), 0), (Fo, "-0.055", F("-0.025"), 0)],
        "tibialis_anterior": [(S, "0.03", F("-0.15"), 0), (S, "0.035", -Ls + F("0.04"), 0), (Fo, "0.05", F("-0.03"), 0)],
        "soleus": [(S, "-0.03", F("-0.15"), 0), (S, "-0.04", -Ls + F("0.06"), 0), (Fo, "-0.055", F("-0.025"), 0)],
    }[name]
    return [(b, F(x), y, zz) for b, x, y, zz in pts]


def gait_toml(g) -> str:
    seg, geo = g["seg"], g["geo"]
    out = [
        comment_block(
            f"""
gait2d - sagittal 9-segment, 11-dof gait model (thesis Sec. 5.1).
GENERATED by urdf/generate.py; rerun it instead of editing.

Coordinates, in the order of Eq. 5.1 ([model] coordinate_order):
  torso_x, torso_y   HAT centre-of-mass position in the world (m), prismatic along x, y
  torso_angle        HAT orientation from upright, + = forward lean
  hip_r, hip_l       + = extension           knee_r, knee_l   + = flexion
  ankle_r, ankle_l   + = plantarflexion      mtp_r, mtp_l     + = toe flexion (toes down)
All revolute joints rotate about (0, 0, -1); world x forward, y up, z to the right.
q = 0: upright standing, segments vertical, foot perpendicular to the shank; the
thesis's ankle angle phi_A is our ankle (zero at neutral, see Lengths); its torso angle phi_T is
pi/2 when upright (Eq. 5.7) where torso_angle = 0.  Heel and metatarsal head touch
the ground y = 0 when torso_y = {g['standing_torso_y']!r} m
(hip drop + thigh + shank + ankle height).

Segments (Table 5.1, Winter; BM {fnum(GAIT_BM)} kg, BH {fnum(GAIT_BH)} m): HAT 0.678 BM,
thigh 0.100 BM, shank 0.0465 BM; foot = hind-foot + fore-foot = 1.2 kg, toes 0.2 kg
(Table 5.2).  Total mass {fnum(g['total_mass'])} kg.  Foot geometry Table 4.1 (AH 7.4 cm,
AP 11.0 cm, PT 7.3 cm, beta 106 deg read as the angle HAP at the ankle): ankle
{geo['height']:.5f} m above the ground, heel {-geo['H'][0]:.5f} m behind and metatarsal
head {geo['P'][0]:.5f} m ahead of the ankle.  Frames heel_r, metatarsal_r, toe_r (H, P, T), same _l.

Muscles: 8 groups per leg, Table 5.3 (Ackermann 2007; Gerritsen et al. 1998,
pennation Menegaldo et al. 2003), Nagano & Gerritsen (2001) contraction dynamics with
the Winters (1990) quadratic tendon (Eq. A.10-A.11, eps0 = 0.04); no parallel elastic
element - passive joint moments come from the Riener & Edrich effects below.
Lengths (Eq. 5.12): l_mt = l0 - r_H phi_H + r_K phi_K - r_A (phi_A - pi/2) with phi_A = ankle
(zero at neutral), i.e.  l_mt = (l0 + r_A pi/2) - r_H hip + r_K knee - r_A ankle, so the
moment arms r = -dl/dq are  hip: r_H,  knee: -r_K,  ankle: r_A  (thesis sign: extensors
and plantarflexors positive); zero entries are omitted.  The path's l0 (length at q = 0)
is Table 5.3's l_0^tm + r_A pi/2.  Reading phi_A as ankle + pi/2 instead would leave
soleus (l0 0.201 m < l_slack 0.245 m) and gastrocnemius (0.404 < 0.420 m) shorter than
their tendons at standing; with phi_A = ankle every fiber sits at 0.5-1.2 l_opt there.
volume = F_max l_opt / sigma with sigma = 0.25 MPa (thesis Eq. B.3).

{SCHEMA_NOTE}
"""
        ),
        *model_table("gait2d", "Sagittal 9-segment, 11-dof gait model with 8 muscle groups per leg, thesis Sec. 5.1"),
        "# The order pinmsk presents coordinates in (Eq. 5.1).  Pinocchio keeps its own depth-first",
        "# joint order (torso_x, torso_y, torso_angle, hip_l, knee_l, ankle_l, mtp_l, hip_r, knee_r,",
        "# ankle_r, mtp_r): subtrees must be contiguous there, so Eq. 5.1's interleaved order can only",
        "# be the order of written columns (pinmsk.Model.coordinate_order); arrays keep Pinocchio's.",
        "coordinate_order = [" + ", ".join(toml_str(n) for n in GAIT_JOINT_ORDER) + "]",
        "",
        "[muscle_model]",
        'type = "nagano_gerritsen"',
        'tendon = "compliant"                 # the thesis solves the inverse muscle model with the tendon',
        'tendon_model = "winters_quadratic"   # Eq. A.10: f_t = k_t (l_t - l_slack)^2, k_t = F_max / (eps0 l_slack)^2',
        f"tendon_strain = {fnum(TENDON_STRAIN)}                 # eps0, Eq. A.11",
        "parallel_elastic = false             # Sec. 5.1: the PE element is left out",
        "",
    ]
    for side in ("r", "l"):
        for name, short, f_max, l_opt, l_slack, penn, ffast, rA, rK, rH, l0, width in TABLE_5_3:
            arms = {}
            if F(rH) != 0:
                arms[f"hip_{side}"] = [F(rH)]
            if F(rK) != 0:
                arms[f"knee_{side}"] = [-F(rK)]
            if F(rA) != 0:
                arms[f"ankle_{side}"] = [F(rA)]
            volume = F(f_max) * F(l_opt) / SPECIFIC_TENSION
            out += [
                "[[muscles]]",
                f"# Table 5.3 {short}: r_A {rA}, r_K {rK}, r_H {rH} m, l0 {l0} m, pennation {penn} deg",
                f"name = {toml_str(f'{name}_{side}')}",
                f"f_max = {fnum(F(f_max))}",
                f"l_opt = {fnum(F(l_opt))}",
                f"l_slack = {fnum(F(l_slack))}",
                f"pennation = {fnum(math.radians(float(F(penn))))}",
                f"volume = {fnum(volume)}",
                f"fast_fraction = {fnum(F(ffast))}",
                f"width = {fnum(F(width))}",
                f"paths.constant = {toml_path(float(F(l0)) + float(F(rA)) * math.pi / 2, arms)}",
                f"points = {toml_points(gait_points(name, side, g))}",
                "",
            ]
    out += [
        comment_block(
            """
Passive joint moments of hip, knee and ankle (Riener & Edrich 1999, thesis Eq. 5.11),
one entry per leg.  Eq. 5.11 takes angles in degrees in the thesis's conventions
(hip + = extension, knee + = flexion, phi_A = ankle, zero at neutral); converting from these
coordinates is the effect class's job."""
        ).rstrip("\n"),
        "[[effects]]",
        'type = "riener_edrich_1999"',
        'side = "r"',
        "",
        "[[effects]]",
        'type = "riener_edrich_1999"',
        'side = "l"',
        "",
    ]
    return "\n".join(out)


# =============================================================================
# driver
# =============================================================================


def render_all() -> dict[str, str]:
    """``{file name in urdf/: text}`` for every generated file."""
    fb = finger_body()
    ab = forearm_body()
    gb = gait_bodies()
    return {
        "finger.urdf": finger_urdf(fb),
        "finger.toml": finger_toml(fb),
        "forearm.urdf": forearm_urdf(ab),
        "forearm.toml": forearm_toml(ab),
        "gait2d.urdf": gait_urdf(gb),
        "gait2d.toml": gait_toml(gb),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true", help="only compare with the committed files")
    ap.add_argument("--out", type=Path, default=HERE, help="output directory (default: this folder)")
    args = ap.parse_args(argv)
    stale = []
    for name, text in render_all().items():
        path = args.out / name
        if args.check:
            if not path.exists() or path.read_text(encoding="utf-8") != text:
                stale.append(name)
        else:
            path.write_text(text, encoding="utf-8")
            print(f"wrote {path}")
    if stale:
        print("out of date (run python urdf/generate.py): " + ", ".join(stale), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
