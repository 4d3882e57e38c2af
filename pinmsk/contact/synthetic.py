"""A synthetic foot trial with known contact parameters (for tests, examples and benchmarks).

One gait cycle of foot2d on a treadmill, from toe-off to toe-off (period 1 s):
swing (0-0.4 s), heel strike, a heel rocker about the heel sphere's centre,
foot flat, then heel rise about the metatarsal sphere's centre, the toes
following the 11-term Fourier series of Eq. 4.1 fitted to the kinematic toe
angle of :func:`pinmsk.contact.toe_from_kinematics` (known coefficients).  The
pivoting sphere's centre sits ``clearance`` m above the belt in stance and
lifts off before the cycle ends; in the lab frame the foot moves backwards with
the belt at ``ground_speed`` during stance and forwards in swing (periodic).
The ground reaction force and COP are then those of the chosen contact model
with known parameters (defaults: Tables 4.2-4.4), computed from the same
discrete kinematics (quintic-spline derivatives, no filter) the fit uses with
``cutoff=None``, so a fit can recover them exactly.
"""
from __future__ import annotations

import numpy as np

from ..signals.filtering import differentiate
from ..trial import Trial
from .foot import SITES, Foot2dGeometry, foot2d_site_kinematics, foot_contacts, ground_reaction
from .identify import SWING, fourier_basis, load_foot2d, toe_from_kinematics


def _smoothstep(u):
    u = np.clip(u, 0.0, 1.0)
    return u ** 3 * (10 - 15 * u + 6 * u ** 2)


def synthetic_foot_trial(*, contact: str = "hypervolumetric", values=None, rate: float = 100.0,
                         ground_speed: float = -1.0, clearance: float = 0.040, lift: float = 0.08,
                         noise: float = 0.0, seed: int = 0, model=None) -> Trial:
    """A :class:`pinmsk.Trial` of one foot2d cycle (see the module doc).

    Channels: ``ankle_x, ankle_y, foot_angle, mtp`` (the true toe angle) and
    ``ground_force_vx, ground_force_vy, ground_force_px`` (+ Gaussian noise of
    ``noise`` x peak on the forces, ``noise`` x 10 mm on the COP).
    ``meta``: ``ground_speed``, ``true_params`` ({site: {name: value}}),
    ``true_fourier`` (11,), ``contact``.
    """
    model = load_foot2d() if model is None else model
    geom = Foot2dGeometry.from_model(model)
    t = np.round(np.arange(0.0, 1.0 + 0.5 / rate, 1.0 / rate), 10)
    # foot angle, + = toes down
    th = np.empty_like(t)
    a, b = 0.9, -0.25
    m = t < 0.4
    th[m] = a + (b - a) * _smoothstep(t[m] / 0.4)
    m = (t >= 0.4) & (t < 0.55)
    th[m] = b - b * _smoothstep((t[m] - 0.4) / 0.15)
    m = (t >= 0.55) & (t < 0.75)
    th[m] = 0.0
    m = t >= 0.75
    th[m] = a * _smoothstep((t[m] - 0.75) / 0.25)
    # the pivot (heel centre for th <= 0, metatarsal centre for th > 0), lab frame
    tp = np.where(t >= 0.4, t, t + 1.0)
    u = np.clip((tp - 0.85) / 0.55, 0.0, 1.0)
    stride = abs(ground_speed) * 1.0
    x_heel = 0.3 + ground_speed * (tp - 0.4) + stride * _smoothstep(u)
    y_piv = clearance + lift * np.sin(np.pi * u) ** 2
    heel_pivot = th <= 0
    lpiv = np.where(heel_pivot[:, None], geom.heel[None, :2], geom.metatarsal[None, :2])
    x_piv = np.where(heel_pivot, x_heel, x_heel + geom.metatarsal[0] - geom.heel[0])
    c, s = np.cos(th), np.sin(th)
    # world = A + R(-th) l with R(-th) = [[c, s], [-s, c]]
    ax = x_piv - (c * lpiv[:, 0] + s * lpiv[:, 1])
    ay = y_piv - (-s * lpiv[:, 0] + c * lpiv[:, 1])
    # toes: Eq. 4.1 series fitted to the kinematic toe angle (toes flat on the ground when the heel
    # is up, neutral in swing; :func:`toe_from_kinematics`, what ContactFit's default toe mode uses)
    B, dB = fourier_basis(t - t[0], t[-1] - t[0])
    Q = np.column_stack([ax, ay, th])
    qs, vs, _ = differentiate(t, Q)
    cs = foot_contacts(model, contact, ground_speed=ground_speed, values=values)
    # swing = the force below SWING x its peak, as ContactFit decides it; iterate to a fixed point
    swing = t < 0.4
    for _ in range(5):
        four = np.linalg.lstsq(B, toe_from_kinematics(geom, Q, swing=swing), rcond=None)[0]
        q = np.column_stack([qs, B @ four])
        v = np.column_stack([vs, dB @ four])
        kin = foot2d_site_kinematics(geom, q, v)
        outs = [cc.evaluate_kinematics(kin[site]) for site, cc in zip(SITES, cs)]
        gr = ground_reaction(outs)
        new = gr.normal < SWING * np.max(np.abs(gr.normal))
        if np.array_equal(new, swing):
            break
        swing = new
    mtp = q[:, 3]
    fy, fx, px = gr.normal.copy(), gr.friction.copy(), gr.cop[:, 0].copy()
    if noise:
        rng = np.random.default_rng(seed)
        fy += noise * fy.max() * rng.standard_normal(t.size)
        fx += noise * np.abs(fx).max() * rng.standard_normal(t.size)
        px += noise * 0.01 * rng.standard_normal(t.size)
    px = np.where(fy > 0.02 * fy.max(), px, np.nan)  # undefined (NaN) below 2 % of the peak
    return Trial(t, {"ankle_x": ax, "ankle_y": ay, "foot_angle": th, "mtp": mtp,
                     "ground_force_vx": fx, "ground_force_vy": fy, "ground_force_px": px},
                 meta={"ground_speed": ground_speed, "contact": contact,
                       "true_params": {site: dict(cc.values) for site, cc in zip(SITES, cs)},
                       "true_fourier": four.tolist(), "source": "pinmsk.contact.synthetic_foot_trial"})
