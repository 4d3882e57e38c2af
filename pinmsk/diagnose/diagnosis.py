"""The diagnosis: where the model fails, which effect is missing, and the add-refit loop.

:func:`diagnose` compares a model with a trial (:mod:`.compare`), locates the
failure (per-channel RMSE against the noise floor, the worst time windows,
the states the residual follows) and ranks every applicable effect of the
catalog (:func:`pinmsk.diagnose.catalog`) by how much of the residual it
explains *out of sample*:

* each candidate is fitted on all frames (its reported parameters and
  uncertainties) and, for scoring, by blocked cross-validation (``folds``
  contiguous time blocks, each predicted by the fit on the others, see
  :mod:`.fit`), so a flexible effect cannot win by fitting noise;
* ``explained_fraction = 1 - MSE_heldout_after / MSE_before`` (noise-whitened
  mean squares over channels and frames);
* ``significant`` when the held-out improvement ``MSE_before - MSE_heldout_after``
  exceeds ``threshold`` (default 0.1) in units of the noise variance -- the
  effect explains at least ~30 % of the noise floor's RMS on data it was not
  fitted to -- and the in-sample BIC falls;
* ranked by held-out error, best first.

Verdict: ``"at_noise_floor"`` when the error is within ``at_floor`` (1.5) times
the noise floor -- both over all channels (RMS of ``rmse_c / floor_c``) and on
every single channel -- else ``"missing_effect"``.  When no catalog effect is
significant the verdict stays ``missing_effect`` (the error *is* above the
floor) and the summary says the gap lies outside the catalog.

:func:`run` is the command-line loop: diagnose, then for each ``add`` entry fit
that effect on all frames, add it to the model (``model.with_effect``) and
diagnose again.
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from ..components import Component
from ..effects import registry
from ..effects._base import is_prismatic, moving_bodies, unactuated_coordinates
from ..errors import ConvergenceError, ModelError, PinmskError, TrialError
from ..fitting import Result
from ..io.output_files import write_json
from ..signals.sampling import median_step
from .catalog import CatalogContext
from .catalog import catalog as effect_catalog
from .compare import DEFAULT_CUTOFF, Comparison, compare, simulate_windows
from .contact import DELTA_BIC, contact_window, model_with_contacts, rank_contacts, resolve
from .fit import EffectFit, describe_fit
from .ranking import EffectScore, finite_or_none, windows_of

__all__ = ["Diagnosis", "DiagnosisRun", "EffectScore", "diagnose", "run", "parse_effect", "describe_fit",
           "AT_FLOOR", "THRESHOLD"]

#: held-out mean-square improvement (in noise variances) that makes an effect significant
THRESHOLD = 0.1
#: error / noise floor at or below which the verdict is at_noise_floor
AT_FLOOR = 1.5
_MIN_BLOCK = 20


class Diagnosis:
    """Result of :func:`diagnose` for one model and trial.

    Attributes: ``model``, ``comparison`` (:class:`~.compare.Comparison`),
    ``rmse`` and ``noise_floor`` (channel -> value, plus ``total``),
    ``worst_windows``, ``correlations`` (channel -> [(state, r)]),
    ``ranking`` (list of :class:`EffectScore`, best first), ``verdict``,
    ``best`` (the best significant effect or None).
    """

    def __init__(self, comparison: Comparison, ranking: list, worst_windows: list, correlations: dict,
                 settings: dict, skipped: list):
        self.comparison = comparison
        self.model = comparison.model
        self.ranking = ranking
        self.worst_windows = worst_windows
        self.correlations = correlations
        self.settings = settings
        self.skipped = skipped
        self.rmse = comparison.rmse()
        self.noise_floor = comparison.noise.to_dict()
        self.ratio = comparison.ratio()
        self.channel_ratios = {ch: self.rmse[ch] / self.noise_floor[ch] for ch in comparison.channels}
        worst = max(self.channel_ratios.values())
        self.verdict = ("at_noise_floor" if max(self.ratio, worst) <= settings["at_floor"]
                        else "missing_effect")

    @property
    def best(self) -> EffectScore | None:
        for s in self.ranking:
            if s.significant:
                return s
        return None

    @property
    def significant(self) -> list:
        return [s for s in self.ranking if s.significant]

    def score(self, family: str, target: str | None = None) -> EffectScore | None:
        """The ranking entry of ``family`` (best target, or ``target``), or None."""
        for s in self.ranking:
            if s.family == family and (target is None or s.target == target):
                return s
        return None

    def fit(self, effect, target: str | None = None, *, max_nfev: int = 100) -> Result:
        """The fit of an effect (family name, ``family:target`` or a Component) on all frames.

        A name the ranking holds gives that entry's fit; anything else is
        fitted by :class:`~pinmsk.diagnose.fit.EffectFit`.  Either way the
        answer is a :class:`~pinmsk.fitting.Result` (see ``EffectFit``).
        Raises :class:`~pinmsk.errors.ConvergenceError` if the fit does not
        converge within ``max_nfev`` evaluations.
        """
        if self.comparison.mode == "contact":
            return resolve(self, effect, target).fit
        comp = _resolve(effect, target, self)
        plain = isinstance(effect, str) and not parse_effect(effect)[2]
        for s in self.ranking:
            if plain and s.label == comp.label:
                if not s.converged:
                    raise ConvergenceError(
                        f"the fit of {s.label} did not converge ({s.fit.stats.message}); it cannot be added as "
                        "is. Check that the trial covers the effect or pass fixed parameter values"
                    )
                return s.fit
        return EffectFit(comp, max_nfev=max_nfev).fit(self.comparison).result_

    def with_effect(self, effect=None, target: str | None = None):
        """The model with an effect added, fitted (default: the best significant one)."""
        if effect is None:
            if self.best is None:
                raise ModelError("no significant effect to add: the verdict is "
                                 f"{self.verdict}; name one explicitly")
            return _model_plus(self.model, self.best.fit)
        return _model_plus(self.model, self.fit(effect, target))

    # -- reporting -----------------------------------------------------------------------
    def to_dict(self, added: Sequence = ()) -> dict:
        """The diagnosis as a JSON-ready dict (``added``: the fits added before it, for ``"added"``)."""
        inputs = self.comparison.inputs
        return {
            "inputs": inputs.meta() if inputs is not None else {},
            "rmse": dict(self.rmse),
            "noise_floor": dict(self.noise_floor),
            "worst_windows": [dict(w) for w in self.worst_windows],
            "ranking": [s.to_dict() for s in self.ranking],
            "verdict": self.verdict,
            "added": [_added_json(a) for a in added],
            "noise_model": self.comparison.noise.to_json(),
        }

    def summary_text(self, *, header: bool = True) -> str:
        c = self.comparison
        lines = []
        if header:
            src = c.trial.meta.get("source") or "trial"
            dur = float(c.trial.time[-1] - c.trial.time[0])
            lines.append(f"pinmsk diagnosis: model {self.model.name}, {Path(str(src)).name} "
                         f"({dur:.2f} s, {c.trial.n_frames} frames), {c.mode}-level comparison")
            if self.model.components:
                lines.append("model effects: " + ", ".join(x.label for x in self.model.components))
            if c.inputs is not None:
                lines.extend(c.inputs.describe())
            lines.append(f"noise floor: {c.noise.method}")
        unit = _unit(c)
        w = max([len(ch) for ch in c.channels] + [8])
        lines.append(f"  {'channel':<{w}}  {'rmse':>10}  {'noise floor':>11}  {'ratio':>6}")
        for ch in c.channels:
            r, f = self.rmse[ch], self.noise_floor[ch]
            lines.append(f"  {ch:<{w}}  {r:>10.4g}  {f:>11.4g}  {r / f:>5.1f}x")
        lines.append(f"  {'total':<{w}}  {self.rmse['total']:>10.4g}  {self.noise_floor['total']:>11.4g}  "
                     f"{self.ratio:>5.1f}x   ({unit}; ratio = RMS of per-channel ratios)")
        if self.worst_windows:
            lines.append("worst windows:")
            for ww in self.worst_windows[:5]:
                f = self.noise_floor[ww["channel"]]
                lines.append(f"  {ww['channel']:<{w}}  {ww['start']:7.2f}-{ww['end']:<7.2f} s  rmse "
                             f"{ww['rmse']:.4g} ({ww['rmse'] / f:.1f}x floor)")
        if self.correlations and self.verdict == "missing_effect":
            lines.append("residual follows:")
            for ch, cors in self.correlations.items():
                if cors:
                    lines.append(f"  {ch:<{w}}  " + ", ".join(f"{s} (r = {r:+.2f})" for s, r in cors[:3]))
        if self.ranking and c.mode == "contact":
            lines.append(f"ranking (contact models identified by Eq. 4.2, scored by BIC = chi2 + k ln n with the "
                         f"noise floor as sigma; significant when BIC falls by > {self.settings['delta_bic']:g}; "
                         "explained = in-sample share of chi2):")
            lw = max(len(s.label) for s in self.ranking)
            for k, s in enumerate(self.ranking, 1):
                sig = "yes" if s.significant else "no "
                ww = s.worst_windows[0] if s.worst_windows else None
                where = (f"  worst {ww['channel']} {ww['start']:.2f}-{ww['end']:.2f} s" if ww else "")
                lines.append(f"  {k:>2}. {s.label:<{lw}}  k = {s.fit.stats.k:>2}  dBIC {s.fit.stats.bic_change:10.1f}  "
                             f"explained {100 * s.explained_fraction:6.1f}%  rmse after "
                             + ", ".join(f"{ch} {s.rmse_after[ch]:.3g}" for ch in c.channels)
                             + f"  significant {sig}{where}" + (f"  [{s.note}]" if s.note else ""))
                lines.append(f"      {s.describe_params()}")
        elif self.ranking:
            lines.append(f"ranking ({self.settings['folds']}-fold blocked cross-validation; explained = "
                         "held-out share of the residual's mean square):")
            lw = max(len(s.label) for s in self.ranking)
            for k, s in enumerate(self.ranking, 1):
                sig = "yes" if s.significant else "no "
                lines.append(f"  {k:>2}. {s.label:<{lw}}  explained {100 * s.explained_fraction:6.1f}%  "
                             f"rmse after {s.rmse_after['total']:.4g}  significant {sig}  {s.describe_params()}"
                             + (f"  [{s.note}]" if s.note else ""))
        else:
            lines.append("ranking: no catalog effect applies to this model and trial")
        for label, why in self.skipped:
            lines.append(f"  (skipped {label}: {why})")
        lines.append(self.verdict_line())
        return "\n".join(lines)

    def verdict_line(self) -> str:
        ch, worst = max(self.channel_ratios.items(), key=lambda kv: kv[1])
        if self.verdict == "at_noise_floor":
            return (f"verdict: at_noise_floor -- the error is {self.ratio:.2f}x the noise floor "
                    f"(worst channel {worst:.2f}x; <= {self.settings['at_floor']:g}x); nothing to add")
        where = (f"the error is {self.ratio:.1f}x the noise floor" if len(self.channel_ratios) == 1
                 else f"the error is {self.ratio:.1f}x the noise floor over all channels, {worst:.1f}x on {ch}")
        if self.best is not None and self.comparison.mode == "contact":
            return (f"verdict: missing_effect -- {where}; best explanation: the {self.best.label} contact model "
                    f"(BIC {self.best.fit.stats.bic_change:+.4g}, fitted parameters above); add it with "
                    f"--add {self.best.label}")
        if self.best is not None:
            return (f"verdict: missing_effect -- {where}; best explanation: {self.best.label} "
                    f"({self.best.describe_params()}); add it with --add {self.best.label}")
        return (f"verdict: missing_effect -- {where}, but no catalog effect explains it significantly: "
                "the gap is outside the catalog (segment lengths, moment arms, sensor offsets, ...) or the "
                "noise floor is underestimated")

    def __repr__(self) -> str:
        return (f"<Diagnosis {self.model.name} {self.comparison.mode}: total rmse {self.rmse['total']:.4g}, "
                f"{self.ratio:.2f}x floor, {self.verdict}>")


def _model_plus(model, fit):
    """``model`` with a fitted effect; a contact model replaces the contacts on its frames."""
    if getattr(fit.effect, "kind", None) == "contact" and hasattr(fit, "components"):
        return model_with_contacts(model, fit)
    return model.with_effect(fit.effect)


def _unit(c: Comparison) -> str:
    if c.mode == "contact":
        return "N and m"
    lin = [is_prismatic(c.model, x) for x in c.coordinates]
    if c.mode == "motion":
        return "m and rad" if any(lin) and not all(lin) else ("m" if all(lin) else "rad")
    return "N and N m" if any(lin) and not all(lin) else ("N" if all(lin) else "N m")


def _added_json(a) -> dict:
    fit = a.fit if isinstance(a, EffectScore) else a
    eff = fit.effect
    return {"effect": eff.family, "target": eff.target,
            "params": {k: float(v) for k, v in fit.params.items()},
            "stderr": {k: finite_or_none(v) for k, v in fit.stderr.items()}}


# -- building blocks -------------------------------------------------------------------------

def parse_effect(text: str):
    """``"family"``, ``"family:target"`` or ``"family:target:p=v[,p=v]"`` -> (family, target, values)."""
    if not isinstance(text, str) or not text.strip():
        raise ModelError(f"an effect is written FAMILY[:TARGET[:PARAM=VALUE,...]], got {text!r}")
    parts = text.strip().split(":")
    family = parts[0].strip()
    registry.get(family)
    target = parts[1].strip() if len(parts) > 1 and parts[1].strip() else None
    values = {}
    for chunk in parts[2:]:
        for item in chunk.split(","):
            item = item.strip()
            if not item:
                continue
            if "=" not in item:
                raise ModelError(f"effect parameters are written NAME=VALUE, got {item!r} in {text!r}")
            k, v = item.split("=", 1)
            try:
                values[k.strip()] = float(v)
            except ValueError:
                raise ModelError(f"parameter {k.strip()!r} in {text!r}: {v!r} is not a number") from None
    return family, target, values


def _resolve(effect, target, diag: Diagnosis) -> Component:
    model = diag.model
    if isinstance(effect, Component):
        effect.check_target(model)
        return effect
    if isinstance(effect, tuple):
        effect, target = effect[0], effect[1] if len(effect) > 1 else target
    family, t2, values = parse_effect(effect)
    target = target if target is not None else t2
    cls = registry.get(family)
    if target is None:
        s = diag.score(family)
        if s is not None:
            return s.effect if not values else s.effect.with_params(values)
        applicable = sorted({x.label for x in diag.ranking} | {lab for lab, _ in diag.skipped})
        raise ModelError(
            f"effect '{family}' does not apply to model '{model.name}' with this trial; name a target "
            f"({family}:TARGET) or pick one of: {', '.join(applicable) or 'none'}"
        )
    try:
        comp = cls(target, **values)
        comp.check_target(model)
    except ModelError as exc:
        targets = _targets(cls, model)
        raise ModelError(f"{exc}. Targets for {family} in model '{model.name}': {targets}") from None
    return comp


def _targets(cls, model) -> str:
    kind = getattr(cls, "target_kind", "coordinate")
    if kind == "coordinate":
        return ", ".join(model.coordinates)
    if kind in ("frame", "body"):
        names = list(moving_bodies(model)) if kind == "body" else list(model.frame_names)
        return ", ".join(names)
    if kind == "muscle":
        return "muscles, " + ", ".join(model.muscle_names)
    if kind == "side":
        return "r, l"
    return "(none)"


def _worst_windows(c: Comparison, window: float, k: int = 5) -> list:
    if c.mode == "contact":
        window = contact_window(c, window)
    return windows_of(c.time, c.residual, c.channels, c.noise.to_dict(), window, k=k, mask=c.mask)


def _correlations(c: Comparison, k: int = 4) -> dict:
    out = {}
    res = c.residual
    for j, ch in enumerate(c.channels):
        r = res[:, j]
        rs = r - r.mean()
        vals = []
        for name, s in c.states.items():
            s = np.asarray(s, dtype=float)
            ss = s - s.mean()
            den = np.sqrt(np.sum(rs ** 2) * np.sum(ss ** 2))
            if den > 0:
                vals.append((name, float(np.sum(rs * ss) / den)))
        vals.sort(key=lambda x: -abs(x[1]))
        out[ch] = vals[:k]
    return out


def _score(c: Comparison, est: EffectFit, settings) -> EffectScore:
    """The ranking entry of a fitted candidate: held-out error by blocked cross-validation."""
    fit = est.result_
    conv, msg = fit.stats.converged, fit.stats.message
    e_cv, cv_ok = est.cross_validate(folds=settings["folds"], guard=settings["guard"])
    sig = c.eq_noise.sigma
    mse0 = float(np.mean((c.eq.e / sig) ** 2))
    mse1 = float(np.mean((e_cv / sig) ** 2))
    # A muscle-level effect also filters the measured signals' noise; that part of the fall is not
    # physics.  Count only the fall beyond the change of the noise floor it causes.
    floor_change = 0.0
    if est.problem_.signal and c.mode == "muscle":
        emg_after = c.eq.emg_noise(fit.effect)
        after2 = c.noise.propagated ** 2 + emg_after ** 2
        floor_change = float(np.mean((sig ** 2 - after2) / sig ** 2))
    improvement = mse0 - mse1 - floor_change
    explained = max(improvement / mse0, -1.0) if mse0 > 0 else 0.0
    if c.mode == "motion":
        rmse_after = _motion_rmse_after(c, fit.effect)
    else:
        r = np.sqrt(np.mean(e_cv ** 2, axis=0))
        rmse_after = {ch: float(v) for ch, v in zip(c.channels, r)}
        rmse_after["total"] = float(np.sqrt(np.mean(r ** 2)))
    converged = bool(conv)
    note = "" if converged else f"fit did not converge: {msg}"
    significant = converged and improvement >= settings["threshold"] and fit.stats.bic_change < 0
    return EffectScore(fit, rmse_after, explained, improvement, significant, converged, note)


def _motion_rmse_after(c: Comparison, effect) -> dict:
    model = c.model.with_effect(effect)
    eq = c.eq
    qs = simulate_windows(model, c.trial, eq.motion, eq.rows, c.options["sim_window"])
    r = np.sqrt(np.mean((c.measured - qs) ** 2, axis=0))
    out = {ch: float(v) for ch, v in zip(c.channels, r)}
    out["total"] = float(np.sqrt(np.mean(r ** 2)))
    return out


def diagnose(model, trial, *, mode: str = "auto", cutoff: float | None = DEFAULT_CUTOFF,
             candidates=None, frames: Sequence[str] | None = None, folds: int = 5,
             threshold: float = THRESHOLD, at_floor: float = AT_FLOOR, window: float = 1.0,
             grf_frames=None, grf=None, external_loads=None, grf_cutoff="same", sim_window: float = 0.5,
             comparison: Comparison | None = None,
             delta_bic: float | None = None, _fits=None) -> Diagnosis:
    """Compare ``model`` with ``trial``, locate the failure and rank the missing effects.

    ``candidates``: effects to rank (Components, or family names / ``family:target``
    strings); default the whole catalog that applies (:func:`pinmsk.diagnose.catalog`).
    ``frames`` names frames for frame effects (a payload).  See the module
    docstring for the scoring and :func:`pinmsk.diagnose.compare.compare` for
    ``mode``, ``cutoff`` and the noise floor.

    In contact mode (:mod:`pinmsk.diagnose.contact`) the candidates are the
    contact models of the foot, scored by BIC with the noise floor as sigma
    (significant below ``-delta_bic``, default
    :data:`~pinmsk.diagnose.contact.DELTA_BIC`); ``folds`` and ``threshold``
    do not apply.
    """
    if folds < 2:
        raise ModelError(f"folds must be >= 2 for cross-validation, got {folds}")
    c = comparison if comparison is not None else compare(
        model, trial, mode=mode, cutoff=cutoff, grf_frames=grf_frames, grf=grf, external_loads=external_loads,
        grf_cutoff=grf_cutoff, sim_window=sim_window)
    if c.mode == "contact":
        return _diagnose_contact(c, candidates, folds, threshold, at_floor, window, cutoff, delta_bic, _fits)
    n = c.eq.rows.size
    if n < folds * _MIN_BLOCK:
        raise TrialError(
            f"{n} analysable samples are too few for {folds} cross-validation blocks of at least "
            f"{_MIN_BLOCK}; record a longer trial or pass folds={max(2, n // _MIN_BLOCK)}"
        )
    dt = median_step(c.eq.motion.t)
    guard = int(np.ceil(1.0 / (cutoff * dt))) if cutoff else 2
    settings = {"folds": folds, "threshold": threshold, "at_floor": at_floor, "guard": guard,
                "window": window, "cutoff": cutoff}
    ctx = CatalogContext(c.mode, tuple(c.eq.coordinates), unactuated_coordinates(c.model), tuple(frames or ()))
    if candidates is None:
        cands = effect_catalog(model, trial, frames=frames, context=ctx)
    else:
        cands = []
        for x in candidates:
            if isinstance(x, Component):
                cands.append(x)
                continue
            fam, tgt, vals = parse_effect(x) if isinstance(x, str) else (x[0], x[1], {})
            if tgt is None:
                cands.extend(effect_catalog(model, trial, families=[fam], frames=frames, context=ctx))
            else:
                comp = registry.get(fam)(tgt, **vals)
                comp.check_target(model)
                cands.append(comp)
    ranking, skipped = [], []
    for comp in cands:
        try:
            ranking.append(_score(c, EffectFit(comp, strict=False).fit(c), settings))
        except PinmskError as exc:
            skipped.append((comp.label, str(exc)))
    ranking = _order(ranking)
    windows = _worst_windows(c, window)
    cors = _correlations(c)
    return Diagnosis(c, ranking, windows, cors, settings, skipped)


def _diagnose_contact(c, candidates, folds, threshold, at_floor, window, cutoff, delta_bic, fits) -> Diagnosis:
    if candidates is not None:
        raise ModelError("contact mode ranks the contact models of the foot (point, volumetric, "
                         "hypervolumetric, hypervolumetric_relaxed); candidates= does not apply")
    settings = {"folds": folds, "threshold": threshold, "at_floor": at_floor, "guard": 0, "window": window,
                "cutoff": cutoff, "delta_bic": DELTA_BIC if delta_bic is None else float(delta_bic),
                "criterion": "bic"}
    ranking, skipped, fits = rank_contacts(c, settings, fits)
    d = Diagnosis(c, ranking, _worst_windows(c, window), _correlations(c), settings, skipped)
    d.contact_fits = fits
    return d


def _order(ranking: list, tie: float = 0.05) -> list:
    """Best held-out improvement first; within ``tie`` (noise variances) the fewer parameters first."""
    out = sorted(ranking, key=lambda s: (not s.converged, -s.improvement))
    for _ in range(len(out)):
        swapped = False
        for i in range(len(out) - 1):
            a, b = out[i], out[i + 1]
            if (a.converged == b.converged and a.target == b.target and a.fit.stats.k > b.fit.stats.k
                    and a.improvement - b.improvement < tie):
                out[i], out[i + 1] = b, a
                swapped = True
        if not swapped:
            break
    return out


class DiagnosisRun:
    """The loop of :func:`run`: ``steps[0]`` for the model as given, one more per added effect."""

    def __init__(self, steps: list, added: list):
        self.steps = steps
        self.added = added

    @property
    def final(self) -> Diagnosis:
        return self.steps[-1]

    @property
    def model(self):
        return self.final.model

    # the final state, as on a Diagnosis
    rmse = property(lambda self: self.final.rmse, doc="final RMSE per channel (and total)")
    noise_floor = property(lambda self: self.final.noise_floor, doc="noise floor per channel (and total)")
    worst_windows = property(lambda self: self.final.worst_windows)
    ranking = property(lambda self: self.final.ranking)
    verdict = property(lambda self: self.final.verdict)
    best = property(lambda self: self.final.best)
    comparison = property(lambda self: self.final.comparison)
    ratio = property(lambda self: self.final.ratio)
    correlations = property(lambda self: self.final.correlations)

    def to_dict(self) -> dict:
        """The loop as a JSON-ready dict: the final diagnosis and the effects added."""
        return self.final.to_dict(self.added)

    def summary_text(self) -> str:
        first = self.steps[0]
        if len(self.steps) == 1:
            return first.summary_text()
        out = [first.summary_text()]
        for k, (fit, step) in enumerate(zip(self.added, self.steps[1:]), 1):
            prev = self.steps[k - 1]
            out.append("")
            out.append(f"step {k}: added {fit.effect.label} ({describe_fit(fit)})")
            out.append(f"  total rmse {prev.rmse['total']:.4g} -> {step.rmse['total']:.4g} "
                       f"(noise floor {step.noise_floor['total']:.4g}; {prev.ratio:.1f}x -> {step.ratio:.2f}x)")
            out.append(step.summary_text(header=False))
        return "\n".join(out)

    def write_json(self, path) -> Path:
        """The JSON summary (parent folders created); refused if any number is NaN or infinite."""
        return write_json(path, self.to_dict(), parents=True)

    def __repr__(self) -> str:
        return f"<DiagnosisRun {len(self.added)} added, final {self.final!r}>"


def run(model, trial, *, add: Sequence = (), first: Diagnosis | None = None, **options) -> DiagnosisRun:
    """Diagnose, then fit and add each ``add`` entry in turn, diagnosing after each.

    ``add`` entries: ``"family"`` (its best-ranked target), ``"family:target"``,
    ``(family, target)`` tuples or Components.  Writes nothing: the JSON
    summary, report and figures are :func:`pinmsk.presentation.report.save_diagnosis`.
    ``options`` go to :func:`diagnose`; ``first`` reuses a diagnosis of this
    model and trial already made as step 0.
    """
    if isinstance(add, (str, Component)):
        add = [add]
    d = first if first is not None else diagnose(model, trial, **options)
    steps, added = [d], []
    for entry in add or ():
        if isinstance(entry, tuple):
            fam, tgt = entry[0], (entry[1] if len(entry) > 1 else None)
            fit = steps[-1].fit(fam, tgt)
        else:
            fit = steps[-1].fit(entry)
        new_model = _model_plus(steps[-1].model, fit)
        comp = steps[-1].comparison.with_model(new_model)
        opts = {k: v for k, v in options.items() if k not in ("mode", "cutoff", "grf_frames", "grf", "grf_cutoff",
                                                                    "external_loads", "sim_window")}
        if comp.mode == "contact":
            opts["_fits"] = getattr(steps[-1], "contact_fits", None)   # the fits depend on the trial only
        steps.append(diagnose(new_model, trial, comparison=comp, cutoff=steps[-1].settings["cutoff"], **opts))
        added.append(fit)
    return DiagnosisRun(steps, added)
