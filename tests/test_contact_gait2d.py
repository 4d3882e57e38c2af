"""gait2d standing on its six contact spheres (centres one radius above the sole sites)."""
import numpy as np
import pinocchio as pin
import pytest
from scipy.optimize import brentq

from pinmsk.components import Motion
from pinmsk.contact import foot_contacts, from_spec, ground_reaction

KINDS = ("point", "volumetric", "hypervolumetric")
STANDING = 1.068093646531213  # torso_y with heel and metatarsal sites on y = 0 (urdf/gait2d.toml)


@pytest.fixture(scope="module")
def gait():
    from pinmsk.model import load_model
    return load_model("gait2d")


def _pose(gait, y):
    q = np.zeros((1, gait.pin.nq))
    q[0, gait.coordinate_index("torso_y")] = y
    return Motion(np.zeros(1), q, np.zeros_like(q), np.zeros_like(q))


def _feet(gait, kind):
    return {side: foot_contacts(gait, kind, side=side) for side in ("r", "l")}


def test_sole_sites_put_the_sphere_centres_one_radius_up(gait):
    for c in foot_contacts(gait, "hypervolumetric", side="r"):
        assert c.center == "sole"
        out = c.evaluate(gait, _pose(gait, STANDING))
        # standing exactly on the sole sites: the spheres just touch (only the smoothing's ~0.1 N)
        assert abs(out.penetration[0]) < 1e-9 and out.normal[0] < 0.5
    assert all(c.center is None for c in foot_contacts(gait, "volumetric", side="r", center=None))


@pytest.mark.parametrize("kind", KINDS)
def test_static_standing_carries_body_weight(gait, kind):
    """1-dof search on torso_y: total vertical GRF = m g; COP between heel and toe; the contact
    generalized force on torso_y balances gravity (RNEA at rest, a second computation path)."""
    feet = _feet(gait, kind)
    mg = pin.computeTotalMass(gait.pin) * 9.81

    def fy(y):
        mo = _pose(gait, y)
        return sum(c.evaluate(gait, mo).normal[0] for cs in feet.values() for c in cs) - mg

    y = brentq(fy, STANDING - 0.03, STANDING + 0.001, xtol=1e-12, rtol=1e-14)
    # sinks into the spheres by less than a radius (hyper-volumetric ~5 mm; the soft linear
    # volumetric optimum of Table 4.3 ~24 mm)
    assert STANDING - 0.04 < y < STANDING
    mo = _pose(gait, y)
    total = 0.0
    for side, cs in feet.items():
        outs = [c.evaluate(gait, mo) for c in cs]
        gr = ground_reaction(outs)
        total += gr.normal[0]
        x_heel = outs[0].point[0, 0]
        x_toe = outs[2].point[0, 0]
        assert x_heel < gr.cop[0, 0] < x_toe, side
        assert gr.loaded[0]
    assert total == pytest.approx(mg, rel=1e-3)
    tau_c = sum(c.generalized_force(gait, mo) for cs in feet.values() for c in cs)[0]
    g = pin.rnea(gait.pin, gait.pin.createData(), mo.q[0], np.zeros(gait.pin.nv), np.zeros(gait.pin.nv))
    j = gait.coordinate_index("torso_y")
    assert tau_c[j] == pytest.approx(g[j], rel=1e-3)


def test_contacts_from_sidecar_spec_stand_like_foot_contacts(gait):
    specs = [{"type": "hypervolumetric", "frame": f"{s}_r", "radius": r, "k_h": k, "H": 0.74}
             for s, r, k in (("heel", 0.05, 8e5), ("metatarsal", 0.049, 1.4e6), ("toe", 0.044, 7.5e5))]
    cs = [from_spec(s) for s in specs]
    assert all(c.center == "sole" for c in cs)
    mo = _pose(gait, STANDING - 0.005)
    ref = foot_contacts(gait, "hypervolumetric", side="r")
    f_spec = sum(c.evaluate(gait, mo).normal[0] for c in cs)
    assert f_spec > 0
    for c, r in zip(cs, ref):
        assert c.values["R"] == pytest.approx(r.values["R"])


def test_ground_reaction_trial_of_the_models_contacts(gait):
    """The model-level GRF of gait2d standing on both feet: per-side channels named as trials name
    them, summing to body weight, each side's COP between its heel and toe."""
    from pinmsk.contact import contact_ground_reactions, ground_reaction_trial
    from pinmsk.errors import ModelError
    from pinmsk.trial import parse_ground_reaction

    feet = _feet(gait, "hypervolumetric")
    model = gait.with_effect(*feet["r"], *feet["l"])
    mg = pin.computeTotalMass(gait.pin) * 9.81
    y = brentq(lambda y: ground_reaction_trial(model, _pose(gait, y))["r_ground_force_vy"][0] * 2 - mg,
               STANDING - 0.03, STANDING + 0.001, xtol=1e-12)
    mo = _pose(gait, y)
    grf = ground_reaction_trial(model, mo)
    assert {parse_ground_reaction(n).side for n in grf.names} == {"r", "l"} and len(grf.names) == 18
    assert grf["r_ground_force_vy"][0] + grf["l_ground_force_vy"][0] == pytest.approx(mg, rel=1e-9)
    sides = contact_ground_reactions(model, mo)
    for side in ("r", "l"):
        heel, toe = (c.evaluate(model, mo).point[0, 0] for c in (feet[side][0], feet[side][2]))
        assert heel < grf[f"{side}_ground_force_px"][0] < toe
        assert grf[f"{side}_ground_force_px"][0] == sides[side].cop[0, 0]
    with pytest.raises(ModelError, match="has no contacts"):
        ground_reaction_trial(gait, mo)
