"""Diagnosis hook: the contact models as catalog candidates for models with foot contact sites.

:func:`contact_candidates` is what the diagnosis catalog (``pinmsk.diagnose``)
calls for a model and a trial.  It returns one :class:`ContactCandidate` per
contact model (point, linear volumetric, hyper-volumetric, hyper-volumetric
relaxed) when the model has the heel/metatarsal/toe sites and the trial the
driving and GRF channels; otherwise an empty list (so the catalog can always
ask).  Each candidate carries its three components (thesis defaults) and a
``fit(trial)`` that runs the Eq. 4.2 identification and returns a
:class:`ContactFit` -- ``objective_`` / ``objective_full_`` to rank by,
``n_free_`` for AIC/BIC, ``reaction_`` for the per-candidate GRF curve.  This
is how the diagnosis shows that a point contact cannot make the double hump of
the vertical GRF and a volumetric sphere can.

Only foot2d-like models (coordinates ankle_x, ankle_y, foot_angle, mtp) can be
kinematically driven today; for other models with the sites (gait2d) the
candidates are listed with ``drivable = False`` and ``fit`` raises.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from ..errors import ModelError
from .foot import KINDS, foot_contacts
from .identify import ALL_TERMS, DRIVE, GRF, VARIANTS as _VARIANTS, ContactFit


@dataclass
class ContactCandidate:
    """One contact model offered to the diagnosis: ``name``, ``kind``, ``relax``, ``components``."""

    name: str
    kind: str
    relax: bool
    components: list
    drivable: bool
    options: dict = field(default_factory=dict)

    @property
    def n_params(self) -> int:
        # as ContactFit fits them with its default terms (all three: friction too, for every model)
        return sum(sum(p.vary for p in c.params.values()) for c in self.components)

    def fit(self, model, trial, **options) -> ContactFit:
        """Run the identification of this candidate (see :class:`ContactFit`)."""
        if not self.drivable:
            raise ModelError(f"contact candidate '{self.name}': model '{model.name}' cannot be kinematically "
                             f"driven (needs coordinates {', '.join(DRIVE)}, mtp); use foot2d")
        return ContactFit(contact=self.kind, relax=self.relax, **{**self.options, **options}).fit(model, trial)


def contact_candidates(model, trial=None, *, side: str | None = None) -> list[ContactCandidate]:
    """Contact candidates for ``model`` (and ``trial``, if given: it must hold the GRF channels)."""
    try:
        sets = {kind: foot_contacts(model, kind, side=side) for kind in KINDS}
    except ModelError:
        return []
    if trial is not None and not all(c in trial for c in GRF):
        return []
    drivable = all(c in model.coordinates for c in DRIVE + ("mtp",))
    if drivable and trial is not None and not all(c in trial for c in DRIVE):
        drivable = False
    out = []
    for kind, relax in _VARIANTS:
        comps = foot_contacts(model, kind, side=side, relax=relax) if relax else sets[kind]
        out.append(ContactCandidate(f"{kind}{'_relaxed' if relax else ''}", kind, relax, comps, drivable))
    return out


# -- glue for the diagnosis's contact mode (pinmsk.diagnose.contact) ------------------------------

def drivable(model, trial=None) -> bool:
    """True if ``model`` has foot2d's sites and driving coordinates (and ``trial`` the driving and GRF channels)."""
    try:
        foot_contacts(model, "point")
    except ModelError:
        return False
    if not all(c in model.coordinates for c in DRIVE + ("mtp",)):
        return False
    return trial is None or all(c in trial for c in DRIVE + GRF)


def contact_problem(model, trial, *, cutoff=None, window=None, toe: str = "kinematic",
                    ground_speed: float | None = None, cop_threshold: float = 0.05):
    """The parameter-independent part of a contact identification, exactly as :class:`ContactFit`
    builds it with these options (kinematics, toe angle, measured GRF, COP mask): ``(problem, ground_speed)``.

    Every candidate fitted with the same options sees the same kinematics, so a model's own
    contacts can be evaluated on them (:func:`predict_reaction`) and compared like for like.
    """
    import numpy as np
    from .identify import SWING, toe_from_kinematics

    gs = ground_speed
    if gs is None:
        gs = float(trial.meta.get("ground_speed", 0.0)) if hasattr(trial, "meta") else 0.0
    cf = ContactFit(contact="hypervolumetric", cutoff=cutoff, window=window, toe=toe,
                    cop_threshold=cop_threshold, terms=ALL_TERMS)
    prob = cf._problem(model, trial, gs)
    if toe in ("kinematic", "fit"):
        mtp = toe_from_kinematics(prob.geom, prob.q, swing=prob.meas[0] < SWING * prob.scale[0])
        four = np.linalg.lstsq(prob.B, mtp, rcond=None)[0]
        prob.q[:, 3], prob.v[:, 3] = prob.B @ four, prob.dB @ four
    elif toe == "flat":
        four = np.linalg.lstsq(prob.B, -np.maximum(prob.q[:, 2], 0.0), rcond=None)[0]
        prob.q[:, 3], prob.v[:, 3] = prob.B @ four, prob.dB @ four
    return prob, gs


def site_kinematics_of(problem) -> dict:
    """``{site: SiteKinematics}`` of foot2d over the problem's frames."""
    from .foot import foot2d_site_kinematics
    return foot2d_site_kinematics(problem.geom, problem.q, problem.v)


def predict_reaction(problem, contacts):
    """The :class:`GroundReaction` of ``contacts`` (components on foot2d's heel/metatarsal/toe frames)
    over the problem's kinematics; ``None`` when ``contacts`` is empty."""
    from .foot import SITES, ground_reaction

    contacts = list(contacts)
    if not contacts:
        return None
    kin = site_kinematics_of(problem)
    outs = []
    for c in contacts:
        if c.target not in SITES:
            raise ModelError(f"contact {c.label}: the contact diagnosis evaluates spheres on foot2d's sites "
                             f"({', '.join(SITES)}), not on frame '{c.target}'")
        outs.append(c.evaluate_kinematics(kin[c.target]))
    return ground_reaction(outs)
