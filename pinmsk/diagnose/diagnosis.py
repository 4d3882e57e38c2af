"""The diagnosis: where the model fails, which effect is missing, and the add-refit loop.

:func:`diagnose` compares a model with a trial (:mod:`.compare`), locates the
failure (per-channel RMSE against the noise floor, the worst time windows,
the states the residual follows) and ranks every applicable effect of the
catalog (:func:`pinmsk.diagnose.catalog`) by how much of the residual it
explains *out of sample* (:mod:`.scoring`):

* each candidate is fitted on all frames (its reported parameters and
  uncertainties) and, for scoring, by blocked cross-validation (``folds``
  contiguous time blocks -- whole cycles when the motion is cyclic -- each
  predicted by the fit on the others, see :mod:`.fit`), so a flexible effect
  cannot win by fitting noise;
* the effects added at earlier steps (``refit=``; :func:`run` passes those it
  added) are refitted *jointly* with each candidate, warm-started from their
  values (lmfit's composite model), on all frames and in every fold: a first
  effect that absorbed part of a correlated second one gives it back, and each
  entry reports how the earlier parameters move (``refit``), with their
  correlations from the joint covariance;
* ``explained_fraction = improvement / MSE_before`` with ``improvement`` the
  held-out fall of the noise-whitened mean square (per channel and frame)
  against the earlier effects alone, cross-validated alike;
* ``significant`` when the held-out test (:func:`~.ranking.held_out_test`,
  Diebold-Mariano with an autocorrelation-robust variance) exceeds the
  Bonferroni critical value ``z`` of level ``alpha`` over the candidates, the
  in-sample BIC of the joint fit falls, the fit converged, and the candidate is
  *identifiable* (:func:`~.scoring.identifiability`: no parameter at a bound,
  a full-rank, well-conditioned sensitivity matrix, 95 % profile-likelihood
  intervals that close inside the bounds).  A non-identifiable candidate is
  shown, flagged, and never suggested;
* or, where the residual's mean over the trial is systematic on some channel,
  significant when it takes that mean away out of sample
  (:func:`~.scoring.mean_test`: the fall of the Wald chi-square of the held-out
  means, against the same critical value) while its held-out error and its
  BIC still fall.  A squared-error test gives a constant shift only half the
  power of the mean it explains, and a real walk's gait-locked residual, which
  no candidate explains, widens its error further; ``test["passes_by"]`` says
  which test passed;
* ranked by held-out improvement, best first (within 0.05 noise variances,
  fewer parameters first); ``best`` is the first that passes by its error,
  else the one that takes most of the mean away.

Stopping rule and verdict.  ``"missing_effect"`` while a candidate (or a pair,
:meth:`~.scoring.Scorer.pairs`, tried when the best single one leaves a residual
the noise does not explain) is significant: it is suggested however close to
the floor the error already is.  Otherwise ``"at_noise_floor"`` when the
held-out residual is consistent with the noise model
(:func:`~.scoring.consistent_with_noise`: each channel's and the total
RMS / floor within ``at_floor`` times the chi-square spread of its effectively
independent frames; ``at_floor`` allows for the uncertainty of the floor's
estimate), every effect in the model is identifiable and the residual is not
systematic (:func:`~.scoring.systematic_residual`: a mean over the trial
against its Newey-West error, a share locked to the movement's phase); else
``"missing_effect"`` with the residual *outside the catalog*: ``outside_catalog``
says what it follows (states, time, dominant frequency, phase of the movement;
:func:`~.scoring.residual_character`).

Backward elimination (:meth:`~.scoring.Scorer.elimination`): every earlier
effect is tested by leaving it out -- the model with it against the model
without it, the others refitted jointly on the same blocks, by the same
held-out test at level ``alpha`` over the effects in the model -- and named an
alias of another whose sensitivity spans the same direction; the least
significant one that is no longer significant is ``suggest_remove``.

Short trials: ``folds=None`` (the default) takes :data:`FOLDS` blocks, fewer
when the trial is too short for blocks of :data:`MIN_BLOCK` rows, at least two
(:func:`choose_folds`; the choice is in ``stopping["blocks"]``).

:func:`run` is the command-line loop: diagnose, then for each ``add`` entry fit
that effect jointly with the ones added before (their values move), put them
all in the model and diagnose again; then drop each ``remove`` entry, refit the
others without it and diagnose again.
"""
from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import Sequence

import numpy as np

from ..components import Component
from ..effects import registry
from ..effects._base import is_prismatic, moving_bodies, unactuated_coordinates
from ..errors import ConvergenceError, ModelError, PinmskError, TrialError
from ..fitting import Result
from ..io.output_files import write_json
from ..kinematics import independent_coordinates
from ..signals.sampling import median_step
from ..trial import moment_channel
from .catalog import CatalogContext
from .catalog import catalog as effect_catalog
from .compare import DEFAULT_CUTOFF, Comparison, compare
from .contact import DELTA_BIC, contact_window, model_with_contacts, rank_contacts, resolve
from .fit import EffectFit, JointProblem, describe_fit
from .ranking import EffectScore, _json, finite_or_none, held_out_test, windows_of
from .scoring import (ALIAS_CORRELATION, Scorer, consistent_with_noise, critical_z, cycle_edges,
                      describe_character, describe_systematic, model_with_components, residual_character,
                      systematic_residual)

__all__ = ["Diagnosis", "DiagnosisRun", "EffectScore", "diagnose", "run", "parse_effect", "describe_fit",
           "choose_folds", "AT_FLOOR", "THRESHOLD", "ALPHA", "FOLDS", "MIN_BLOCK", "MIN_TRAIN"]

#: least held-out improvement (noise variances per channel and frame) a significant effect must make on
#: top of the test: none -- the test decides, so an effect below the floor is found when it is real
THRESHOLD = 0.0
#: family-wise level of the held-out test over the candidates (Bonferroni)
ALPHA = 0.01
#: allowance for the noise floor's own estimation error when judging a residual consistent with it
AT_FLOOR = 1.25
#: at_noise_floor limit of the contact mode (ratio to the floor; its candidates are scored by BIC)
CONTACT_AT_FLOOR = 1.5
#: cross-validation blocks by default (fewer on a trial too short for them, see :func:`choose_folds`)
FOLDS = 5
#: fewest rows a held-out block holds when the trial allows
MIN_BLOCK = 20
#: fewest rows a training set keeps once a held-out block and its guard are left out
MIN_TRAIN = 10


class Diagnosis:
    """Result of :func:`diagnose` for one model and trial.

    Attributes: ``model``, ``comparison`` (:class:`~.compare.Comparison`),
    ``rmse`` and ``noise_floor`` (channel -> value, plus ``total``),
    ``worst_windows``, ``correlations`` (channel -> [(state, r)]),
    ``ranking`` (list of :class:`EffectScore`, best first), ``verdict``,
    ``best`` (the best significant effect or None), ``pairs`` (pairs fitted
    jointly), ``refit`` (the earlier effects as refitted here),
    ``outside_catalog`` (what an unexplained residual follows, or None),
    ``stopping`` (the test and the noise-consistency check behind the verdict).
    """

    def __init__(self, comparison: Comparison, ranking: list, worst_windows: list, correlations: dict,
                 settings: dict, skipped: list, *, scorer: Scorer | None = None, pairs=None,
                 elimination=None):
        self.comparison = comparison
        self.model = comparison.model
        self.ranking = ranking
        self.worst_windows = worst_windows
        self.correlations = correlations
        self.settings = settings
        self.skipped = skipped
        self.scorer = scorer
        self.pairs = list(pairs or [])
        self.elimination = list(elimination or [])
        self.rmse = comparison.rmse()
        self.noise_floor = comparison.noise.to_dict()
        self.ratio = comparison.ratio()
        self.channel_ratios = {ch: self.rmse[ch] / self.noise_floor[ch] for ch in comparison.channels}
        self.outside_catalog = None
        self.stopping = {}
        self.refit = scorer.base_moves() if scorer is not None else {}
        if comparison.mode == "contact":
            worst = max(self.channel_ratios.values())
            self.verdict = ("at_noise_floor" if max(self.ratio, worst) <= settings["at_floor"]
                            else "missing_effect")
            return
        held = scorer.base_cv
        ok, ratio_cv, limit, _ = consistent_with_noise(held, comparison.eq_noise.sigma, settings["at_floor"])
        unidentified = [c.label for c, info in zip(scorer.refit, scorer.base_ident)
                        if not info.get("determined", True)]
        switched_off = [c.label for c, info in zip(scorer.refit, scorer.base_ident)
                        if info.get("determined", True) and not info.get("identifiable", True)]
        self.stopping = {
            "rule": "held-out test (Diebold-Mariano, HAC variance) at family-wise level alpha over the "
                    "candidates (Bonferroni), or, where the residual's mean over the trial is systematic, the "
                    "held-out test of that mean (Wald chi-square, Newey-West) at the same level; in-sample "
                    "BIC falls, held-out error falls, identifiable parameters",
            "alpha": settings["alpha"], "critical_z": settings["z_critical"],
            "candidates_tested": len(ranking), "blocks": settings["blocks"],
            "folds": settings["folds"], "folds_chosen": settings.get("folds_chosen", "given"),
            "held_out_ratio": ratio_cv, "consistent_limit": limit, "consistent_with_noise": ok,
            "noise_floor_method": comparison.noise.method,
            "not_identifiable_in_model": unidentified, "switched_off_in_model": switched_off,
            "suggest_remove": self.suggest_remove,
        }
        # a systematic residual (a mean over the trial, a pattern locked to the movement's phase) is no noise
        systematic = systematic_residual(comparison, held, alpha=settings["alpha"],
                                         channels=[moment_channel(x) for x in comparison.eq.coordinates])
        self.stopping["systematic"] = systematic
        estimable = (comparison.eq_noise.info or {}).get("estimable", True) is not False
        self.stopping["floor_estimable"] = estimable
        if self.best is not None or self.best_pair is not None:
            self.verdict = "missing_effect"
        elif ok and not unidentified and not systematic["systematic"] and estimable:
            self.verdict = "at_noise_floor"
        else:
            self.verdict = "missing_effect"
            if not ok or systematic["systematic"]:
                ch = residual_character(comparison, comparison.eq.e if comparison.mode != "motion"
                                        else comparison.residual)
                names = comparison.channels if comparison.mode != "motion" else comparison.channels
                sysch = systematic["channels"]
                self.outside_catalog = {
                    "held_out_ratio": ratio_cv, "consistent_limit": limit,
                    "systematic": list(systematic["systematic"]),
                    "channels": {n: dict(info, systematic=sysch.get(n), summary="; ".join(
                        x for x in (describe_systematic(sysch.get(n) or {}),
                                    describe_character(info, comparison.coordinates)) if x))
                        for n, info in ch.items() if n in names},
                }

    @property
    def best(self) -> EffectScore | None:
        """The first significant candidate by held-out error; else, of those that pass only by taking a
        systematic mean away (:func:`~.scoring.mean_test`), the one that takes most of it."""
        return best_of(self.ranking)

    @property
    def best_pair(self) -> dict | None:
        """The best significant pair (better than the best single candidate), or None."""
        for p in self.pairs:
            if p["significant"]:
                return p
        return None

    @property
    def suggest_remove(self) -> str | None:
        """The label of the effect in the model that backward elimination drops (no longer significant
        beside the others), or None."""
        for e in self.elimination:
            if e["suggest_remove"]:
                return e["label"]
        return None

    def without(self, label: str):
        """The model without the effect ``label``, the other effects refitted jointly without it (as the
        backward elimination fitted them) when it is one of the effects refitted here."""
        self.model.component(label)
        for e in self.elimination:
            if e["label"] == label and e.get("components") is not None:
                return model_with_components(self.model.without(label), e["components"])
        return self.model.without(label)

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

        A name the ranking holds gives that entry's fit (with the earlier
        effects refitted jointly when there are any); anything else is fitted by
        :class:`~pinmsk.diagnose.fit.EffectFit` (alone).  Either way the
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
                _check_converged(s)
                return s.fit
        return EffectFit(comp, max_nfev=max_nfev).fit(self.comparison).result_

    def joint_fit(self, effect, target: str | None = None, *, max_nfev: int = 100) -> tuple[list, Result]:
        """``(components, result)``: ``effect`` fitted jointly with the earlier effects (``refit``).

        ``components`` are the earlier effects with their refitted values and the
        new effect last, as they go into the model; ``result`` the new effect's
        fit.  A ranked candidate gives its entry's joint fit.
        """
        comp = _resolve(effect, target, self)
        plain = not (isinstance(effect, str) and parse_effect(effect)[2]) and not isinstance(effect, Component)
        for s in self.ranking:
            if plain and s.label == comp.label:
                _check_converged(s)
                return list(s.components), s.fit
        fit = EffectFit(comp, max_nfev=max_nfev).fit(self.comparison)
        sc = self.scorer
        if sc is None or not sc.refit:
            return [fit.effect_], fit.result_
        jp = JointProblem(self.comparison.eq, sc.sigma, sc.refit + [fit.effect_], problems=sc.problems)
        x0 = np.concatenate([sc.base_x, fit.theta_])
        x, conv, msg = jp.solve(x0=x0, max_nfev=max_nfev)
        if not (conv or jp.linear):
            raise ConvergenceError(f"the joint fit of {comp.label} with "
                                   f"{', '.join(c.label for c in sc.refit)} did not converge ({msg})")
        from .scoring import _joint_result
        res = _joint_result(jp, x, True, msg, sc.base_sse, self.comparison.eq)
        return jp.components_at(x, res.info["joint_stderr"]), res

    def with_effect(self, effect=None, target: str | None = None):
        """The model with an effect added, fitted jointly with the earlier effects (default: the best
        significant one)."""
        if self.comparison.mode == "contact":
            if effect is None:
                if self.best is None:
                    raise ModelError(f"no significant effect to add: the verdict is {self.verdict}; "
                                     "name one explicitly")
                return _model_plus(self.model, self.best.fit)
            return _model_plus(self.model, self.fit(effect, target))
        if effect is None:
            if self.best is None:
                raise ModelError("no significant effect to add: the verdict is "
                                 f"{self.verdict}; name one explicitly")
            return model_with_components(self.model, self.best.components)
        comps, _ = self.joint_fit(effect, target)
        return model_with_components(self.model, comps)

    # -- reporting -----------------------------------------------------------------------
    def to_dict(self, added: Sequence = (), refits: Sequence = ()) -> dict:
        """The diagnosis as a JSON-ready dict (``added``: the fits added before it, for ``"added"``;
        ``refits``: what each add step's joint refit changed, for ``"refit"``)."""
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
            "refit": [_json(r) for r in refits],
            "pairs": [_pair_json(p) for p in self.pairs],
            "outside_catalog": _json(self.outside_catalog),
            "stopping": _json(self.stopping),
            "elimination": [_json({k: v for k, v in e.items() if k != "components"}) for e in self.elimination],
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
        unknown = (c.eq_noise.info or {}).get("estimable") is False
        floor_head = "weight" if unknown else "noise floor"
        lines.append(f"  {'channel':<{w}}  {'rmse':>10}  {floor_head:>11}  {'ratio':>6}"
                     + ("   (floor not estimable: each channel weighed by its residual's RMS as given)"
                        if unknown else ""))
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
        if self.refit and self.refit.get("effects"):
            lines.append("effects in the model, refitted with every candidate (values from the joint fit "
                         "without one):")
            for eff in self.refit["effects"]:
                lines.append(f"  {eff['label']}: " + ", ".join(
                    f"{n} = {v['after']:.4g}" + (f" ± {v['stderr']:.2g}" if v["stderr"] is not None else "")
                    for n, v in eff["params"].items()))
        lines.extend(self._elimination_lines())
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
            means = [s.test["mean"] for s in self.ranking if (s.test.get("mean") or {}).get("applies")]
            on = (", ".join(c.channels[k] for k in means[0]["systematic"]) if means else "")
            mean_note = (f"; z mean = held-out test of the systematic mean of {on} (significant above the same "
                         "value, when the held-out error falls too)" if means else "")
            lines.append(f"ranking ({self.settings['blocks']}; explained = held-out share of the residual's "
                         f"mean square; z = held-out test, significant above {self.settings['z_critical']:.2f} "
                         f"with identifiable parameters{mean_note}):")
            lw = max(len(s.label) for s in self.ranking)
            for k, s in enumerate(self.ranking, 1):
                sig = ("yes (mean)" if s.test.get("passes_by") == "mean" else "yes") if s.significant else "no"
                z = s.test.get("z", float("nan"))
                zm = f"  z mean {s.test['mean']['z']:6.2f}" if means and s.test.get("mean") else ""
                lines.append(f"  {k:>2}. {s.label:<{lw}}  explained {100 * s.explained_fraction:6.1f}%  "
                             f"z {z:7.2f}{zm}  rmse after {s.rmse_after['total']:.4g}  significant {sig:<10}  "
                             f"{s.describe_params()}" + (f"  [{s.note}]" if s.note else ""))
                if s.refit:
                    moved = [f"{e['label']}.{n} {v['before']:.4g} -> {v['after']:.4g}"
                             for e in s.refit["effects"] for n, v in e["params"].items()
                             if abs(v["change"]) > 1e-12]
                    if moved:
                        lines.append("      refitted with it: " + ", ".join(moved))
                if s.aliases:
                    lines.append("      explains the same as " + ", ".join(f"{a} (r = {r:+.3f})" for a, r in s.aliases)
                                 + ": this trial cannot tell them apart")
        else:
            lines.append("ranking: no catalog effect applies to this model and trial")
        if self.pairs:
            lines.append("pairs fitted jointly (tested against the best single candidate):")
            for p in self.pairs[:3]:
                comps = ", ".join(f"{x.label} ({describe_fit_of(x)})" for x in p["components"])
                lines.append(f"  {' + '.join(p['effects'])}: held-out gain {p['improvement_over_best']:+.3g}, "
                             f"z {p['z']:.2f}, significant {'yes' if p['significant'] else 'no'}; {comps}"
                             + (f"  [{'; '.join(p['flags'])}]" if p["flags"] else ""))
        for label, why in self.skipped:
            lines.append(f"  (skipped {label}: {why})")
        if self.outside_catalog:
            lines.append("residual outside the catalog:")
            for ch, info in self.outside_catalog["channels"].items():
                lines.append(f"  {ch:<{w}}  {info['summary']}")
        lines.append(self.verdict_line())
        return "\n".join(lines)

    def _elimination_lines(self) -> list:
        """The backward elimination: each effect in the model tested by leaving it out."""
        if not self.elimination:
            return []
        zc = self.elimination[0]["critical_z"]
        mean = any(e.get("z_mean") is not None for e in self.elimination)
        out = [f"effects in the model, each tested by leaving it out (the others refitted; held-out z"
               f"{', and z mean of the systematic mean that comes back without it' if mean else ''}, "
               f"significant above {zc:.2f}):"]
        lw = max(len(e["label"]) for e in self.elimination)
        for e in self.elimination:
            if e["z"] is None:
                out.append(f"  {e['label']:<{lw}}  not tested: {e['without']}")
                continue
            sig = "yes" if e["significant"] else "no "
            alias = (f"  alias of {e['alias_of']} (r = {e['alias_correlation']:.3f})" if e["alias_of"] else "")
            held = "" if e["determined"] else "  [its parameters are not determined]"
            drop = f"  -> remove it: --remove {e['label']}" if e["suggest_remove"] else ""
            zm = f"  z mean {e['z_mean']:6.2f}" if e.get("z_mean") is not None else ""
            out.append(f"  {e['label']:<{lw}}  z {e['z']:7.2f}{zm}  held-out gain {e['improvement']:+.3g}  "
                       f"significant {sig}{alias}{held}{drop}")
        return out

    def _removal_clause(self) -> str:
        """``"; X is no longer significant ...: remove it with --remove X"`` when elimination drops one."""
        label = self.suggest_remove
        if label is None:
            return ""
        e = next(x for x in self.elimination if x["label"] == label)
        others = [x["label"] for x in self.elimination if x["label"] != label]
        why = (f"; an alias of {e['alias_of']}, r = {e['alias_correlation']:.3f}" if e["alias_of"] else "")
        beside = f" beside {', '.join(others)}" if others else ""
        zm = f", z mean {e['z_mean']:.2f}" if e.get("z_mean") is not None else ""
        return (f"; {label} is no longer significant{beside} (held-out z {e['z']:.2f}{zm} < {e['critical_z']:.2f} "
                f"when it is left out{why}): remove it with --remove {label}")

    def verdict_line(self) -> str:
        line = self._verdict_line()
        return line + self._removal_clause() if self.comparison.mode != "contact" else line

    def _verdict_line(self) -> str:
        ch, worst = max(self.channel_ratios.items(), key=lambda kv: kv[1])
        where = (f"the error is {self.ratio:.2f}x the noise floor" if len(self.channel_ratios) == 1
                 else f"the error is {self.ratio:.2f}x the noise floor over all channels, {worst:.2f}x on {ch}")
        if self.comparison.mode == "contact":
            if self.verdict == "at_noise_floor":
                return (f"verdict: at_noise_floor -- the error is {self.ratio:.2f}x the noise floor "
                        f"(worst channel {worst:.2f}x; <= {self.settings['at_floor']:g}x); nothing to add")
            if self.best is not None:
                return (f"verdict: missing_effect -- {where}; best explanation: the {self.best.label} contact "
                        f"model (BIC {self.best.fit.stats.bic_change:+.4g}, fitted parameters above); add it "
                        f"with --add {self.best.label}")
            return (f"verdict: missing_effect -- {where}, but no contact model explains it significantly")
        st = self.stopping
        if self.verdict == "at_noise_floor":
            return (f"verdict: at_noise_floor -- {where}; the held-out residual is consistent with the noise "
                    f"model ({st['held_out_ratio']:.2f}x <= {st['consistent_limit']:.2f}x) and no candidate is "
                    "significant out of sample; nothing to add")
        best, pair = self.best, self.best_pair
        if best is not None or pair is not None:
            parts = []
            if best is not None:
                alias = (" -- indistinguishable on this trial from " + ", ".join(a for a, _ in best.aliases)
                         if best.aliases else "")
                remedy = ""
                if hasattr(best.effect, "describe_remedy"):
                    remedy = f"; {best.effect.describe_remedy(self.model)}"
                if best.test.get("passes_by") == "mean":
                    mt = best.test["mean"]
                    names = [self.comparison.channels[k] for k in mt["systematic"]]
                    named = {a for a, _ in best.aliases}
                    others = [s.label for s in self.significant if s is not best and s.label not in named
                              and s.test.get("passes_by") == "mean"]
                    also = (f"; {', '.join(others)} take{'s' if len(others) == 1 else ''} less of it away"
                            if others else "")
                    why = (f"takes the systematic mean of {', '.join(names)} away (held-out chi-square of the "
                           f"means {mt['chi2_before']:.3g} -> {mt['chi2_after']:.2g}, z {mt['z']:.1f}; its "
                           f"held-out error z {best.test['z']:.1f}){also}")
                else:
                    why = f"held-out z {best.test['z']:.1f}"
                parts.append(f"best explanation: {best.label} ({best.describe_params()}; {why}){alias}{remedy}; "
                             f"add it with --add {best.label}")
            if pair is not None and (best is None or best.label not in pair["effects"]):
                adds = " ".join(f"--add {e}" for e in pair["effects"])
                parts.append(f"the pair {' + '.join(pair['effects'])} fitted jointly explains significantly more "
                             f"than {'any single effect' if best is None else best.label + ' alone'} "
                             f"(z {pair['z']:.1f}): {adds}")
            return f"verdict: missing_effect -- {where}; " + "; ".join(parts)
        if st.get("not_identifiable_in_model") and st.get("consistent_with_noise"):
            return (f"verdict: missing_effect -- {where}, consistent with the noise, but only through "
                    f"{', '.join(st['not_identifiable_in_model'])}, whose parameters this trial does not "
                    "determine (see the flags): the effect that is really missing is another one; remove it")
        held = st.get("not_identifiable_in_model") or []
        also = (f"; the model holds {', '.join(held)}, whose parameters this trial does not determine (held at "
                "their values, see the flags): remove it and diagnose again" if held else "")
        sysch = (st.get("systematic") or {}).get("systematic") or []
        what = "; ".join(f"{ch}: {describe_systematic(st['systematic']['channels'][ch])}" for ch in sysch)
        if st.get("floor_estimable") is False:
            return ("verdict: missing_effect -- the noise floor is not estimable from these records (no "
                    "measurable noise in them: smoothed or processed data), so nothing can be called noise; no "
                    "catalog effect explains the residual out of sample, each channel weighed by its own "
                    "residual (see what the residual follows above" + (f"; it is systematic: {what}" if sysch else "")
                    + "); state the noise with --noise NAME=SIGMA "
                    "to judge it against a floor" + also)
        if sysch:
            size = (f"held-out {st['held_out_ratio']:.2f}x, within what the noise model allows, "
                    f"{st['consistent_limit']:.2f}x" if st.get("consistent_with_noise") else
                    f"held-out {st['held_out_ratio']:.2f}x, more than the noise model allows, "
                    f"{st['consistent_limit']:.2f}x")
            return (f"verdict: missing_effect -- {where} ({size}), but the residual is systematic, not noise "
                    f"({what}), and no catalog effect explains it out of sample: the gap is outside the catalog "
                    "(see what the residual follows above)" + also)
        return (f"verdict: missing_effect -- {where} (held-out {st['held_out_ratio']:.2f}x, more than the noise "
                f"model allows, {st['consistent_limit']:.2f}x), but no catalog effect explains it out of sample: "
                "the gap is outside the catalog (see what the residual follows above: segment lengths, moment "
                "arms, a time-varying disturbance, ...) or the noise floor is underestimated" + also)

    def __repr__(self) -> str:
        return (f"<Diagnosis {self.model.name} {self.comparison.mode}: total rmse {self.rmse['total']:.4g}, "
                f"{self.ratio:.2f}x floor, {self.verdict}>")


def describe_fit_of(comp) -> str:
    """``name = value ± stderr`` of a component's free parameters (its Parameters' stderr)."""
    return ", ".join(f"{n} = {p.value:.4g}" + (f" ± {p.stderr:.2g}" if p.stderr is not None and np.isfinite(p.stderr)
                                               else "") for n, p in comp.params.items() if p.vary)


def _check_converged(s: EffectScore) -> None:
    if not s.converged:
        raise ConvergenceError(
            f"the fit of {s.label} did not converge ({s.fit.stats.message}); it cannot be added as "
            "is. Check that the trial covers the effect, or hold some parameters at given values "
            "(--add FAMILY:TARGET:NAME=VALUE; 'family:target:name=value' in Python)"
        )


def _pair_json(p: dict) -> dict:
    return _json({
        "effects": list(p["effects"]),
        "params": {c.label: {n: q.value for n, q in c.params.items()} for c in p["components"]},
        "stderr": {c.label: {n: q.stderr for n, q in c.params.items()} for c in p["components"]},
        "refit": {c.label: {n: q.value for n, q in c.params.items()} for c in p["refit"]},
        "improvement_over_best": p["improvement_over_best"], "z": p["z"],
        "bic_change_over_best": p["bic_change_over_best"], "rmse_after": p["rmse_after"],
        "significant": p["significant"], "flags": list(p["flags"]),
    })


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
    if isinstance(a, Component):          # a component as it is in the final model (after the refits)
        return {"effect": a.family, "target": a.target,
                "params": {k: float(p.value) for k, p in a.params.items()},
                "stderr": {k: finite_or_none(p.stderr if p.stderr is not None else float("nan"))
                           for k, p in a.params.items() if p.vary}}
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
            return s.effect if not values else _held(s.effect, values)
        applicable = sorted({x.label for x in diag.ranking} | {lab for lab, _ in diag.skipped})
        raise ModelError(
            f"effect '{family}' does not apply to model '{model.name}' with this trial; name a target "
            f"({family}:TARGET) or pick one of: {', '.join(applicable) or 'none'}"
        )
    try:
        comp = cls(target)
        comp.check_target(model)
        comp = _held(_for_model(comp, model), values) if values else _for_model(comp, model)
    except ModelError as exc:
        targets = _targets(cls, model)
        raise ModelError(f"{exc}. Targets for {family} in model '{model.name}': {targets}") from None
    return comp


def _held(comp: Component, values: dict) -> Component:
    """``comp`` with the parameters an effect spec names (``family:target:p=v``) held at those values: the
    fit moves only the others."""
    return comp.with_params(values, vary={n: False for n in values})


def _targets(cls, model) -> str:
    kind = getattr(cls, "target_kind", "coordinate")
    if kind == "coordinate":
        return ", ".join(independent_coordinates(model))      # OpenSim's on an exact import
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




def _for_model(comp, model):
    """A candidate with its model-dependent bounds (a rest angle within the joint's range)."""
    hook = getattr(comp, "for_model", None)
    return hook(model) if hook is not None else comp


def choose_folds(n: int, folds: int | None, guard: int) -> tuple[int, str]:
    """The number of cross-validation blocks for ``n`` analysed rows, and a note when a short trial set it.

    Given ``folds`` are taken as they are, refused when a block would hold fewer than
    :data:`MIN_BLOCK` rows.  By default (``folds=None``) :data:`FOLDS` blocks, fewer when the trial
    is too short for blocks of :data:`MIN_BLOCK` rows, and at least two (one stride of a walk:
    each half predicted by the fit on the other).  Every training set must keep
    :data:`MIN_TRAIN` rows once ``guard`` rows either side of its held-out block are left out
    (the filter's correlation length), else the trial is refused.
    """
    if folds is not None:
        folds = int(folds)
        if n < folds * MIN_BLOCK:
            k = n // MIN_BLOCK
            fix = (f"pass --folds {k} (folds={k} in Python)" if k >= 2 else
                   "leave --folds out (folds=None) to let the diagnosis choose")
            raise TrialError(f"{n} analysable samples are too few for {folds} cross-validation blocks of at "
                             f"least {MIN_BLOCK}; record a longer trial or {fix}")
        note = ""
    else:
        folds = int(min(max(n // MIN_BLOCK, 2), FOLDS))
        note = "" if folds == FOLDS else (f"{folds} folds, not {FOLDS}: {n} analysable samples make only "
                                          f"{folds} blocks of {MIN_BLOCK} or more" if n >= 2 * MIN_BLOCK else
                                          f"2 folds of {n // 2} samples: {n} analysable samples are too few "
                                          f"for blocks of {MIN_BLOCK}")
    block = int(np.ceil(n / folds))
    train = n - block - (2 * guard if folds > 2 else guard)
    if train < MIN_TRAIN:
        raise TrialError(f"{n} analysable samples are too few for {folds}-fold cross-validation: leaving out a "
                         f"block of {block} and {guard} samples beside it (one period of the low-pass) leaves "
                         f"{max(train, 0)} to fit on, fewer than {MIN_TRAIN}; record a longer trial")
    return folds, note


def diagnose(model, trial, *, mode: str = "auto", cutoff: float | None = DEFAULT_CUTOFF,
             candidates=None, frames: Sequence[str] | None = None, folds: int | None = None,
             threshold: float = THRESHOLD, at_floor: float | None = None, window: float = 1.0,
             grf_frames=None, grf=None, external_loads=None, grf_cutoff="auto", sim_window: float = 0.5,
             noise=None,
             comparison: Comparison | None = None, refit: Sequence = (), alpha: float = ALPHA,
             pairs: bool = True, delta_bic: float | None = None, missing_coordinates: str = "refuse",
             _fits=None) -> Diagnosis:
    """Compare ``model`` with ``trial``, locate the failure and rank the missing effects.

    ``candidates``: effects to rank (Components, or family names / ``family:target``
    strings); default the whole catalog that applies (:func:`pinmsk.diagnose.catalog`).
    ``frames`` names frames for frame effects (a payload).  ``refit``: labels of
    effects in ``model`` to refit jointly with every candidate (the ones added at
    earlier steps; :func:`run` passes them).  ``alpha``: family-wise level of the
    held-out test; ``at_floor``: allowance for the noise floor's estimation error
    when the held-out residual is judged consistent with the noise (default
    :data:`AT_FLOOR`; contact mode: the ratio at or below which the verdict is
    at_noise_floor, :data:`CONTACT_AT_FLOOR`); ``threshold``: least held-out
    improvement in noise variances on top of the test (default 0); ``pairs``:
    try pairs of candidates when the best single one leaves a residual; ``folds``:
    cross-validation blocks (default None: chosen for the trial's length,
    :func:`choose_folds`).  See the
    module docstring for the scoring and :func:`pinmsk.diagnose.compare.compare`
    for ``mode``, ``cutoff``, ``missing_coordinates`` (an exact OpenSim import's coordinates the trial
    leaves out) and the noise floor.

    In contact mode (:mod:`pinmsk.diagnose.contact`) the candidates are the
    contact models of the foot, scored by BIC with the noise floor as sigma
    (significant below ``-delta_bic``, default
    :data:`~pinmsk.diagnose.contact.DELTA_BIC`); ``folds``, ``threshold``,
    ``refit`` and ``alpha`` do not apply.

    ``noise``: noise levels the user states (``{channel or group: sigma}``, SI units), in place of
    the fitted ones (:func:`pinmsk.diagnose.noise.propagated_floor`).
    """
    folds_given = folds is not None
    if folds is not None and (int(folds) != folds or folds < 2):
        raise ModelError(f"folds must be a whole number >= 2 for cross-validation, got {folds}")
    if not 0 < alpha < 1:
        raise ModelError(f"alpha is a significance level in (0, 1), got {alpha}")
    c = comparison if comparison is not None else (partial(compare, noise=noise) if noise else compare)(
        model, trial, mode=mode, cutoff=cutoff, grf_frames=grf_frames, grf=grf, external_loads=external_loads,
        grf_cutoff=grf_cutoff, sim_window=sim_window, missing_coordinates=missing_coordinates)
    if c.mode == "contact":
        return _diagnose_contact(c, candidates, FOLDS if folds is None else int(folds), threshold,
                                 CONTACT_AT_FLOOR if at_floor is None else at_floor, window, cutoff,
                                 delta_bic, _fits)
    n = c.eq.rows.size
    refit_comps = _refit_components(c.model, refit)
    dt = median_step(c.eq.motion.t)
    # one period of the low-pass (60 Hz at 6 Hz: 10 rows, not 11 by round-off)
    guard = int(np.ceil(1.0 / (cutoff * dt) - 1e-9)) if cutoff else 2
    folds, short = choose_folds(n, folds, guard)
    cyc = cycle_edges(c.time, _main_coordinate(c), folds)
    if cyc is not None and min(np.diff([0, *cyc[0], n])) < min(MIN_BLOCK, n // folds):
        cyc = None
    blocks = (f"{folds}-fold blocked cross-validation over whole cycles (period {cyc[1]:.3g} s)" if cyc
              else f"{folds}-fold blocked cross-validation")
    if short:
        blocks += f" ({short})"
    settings = {"folds": folds, "folds_chosen": "given" if folds_given else "auto", "threshold": threshold,
                "at_floor": AT_FLOOR if at_floor is None else at_floor,
                "guard": guard, "window": window, "cutoff": cutoff, "alpha": alpha, "blocks": blocks,
                "block_edges": cyc[0] if cyc else None, "joint_nfev": 50, "cv_nfev": 20, "profile": True,
                "refit": [x.label for x in refit_comps]}
    ctx = CatalogContext(c.mode, tuple(c.eq.coordinates), unactuated_coordinates(c.model), tuple(frames or ()),
                         tuple(sorted({e.frame for e in c.eq.external})))
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
                comp = registry.get(fam)(tgt)
                comp.check_target(model)
                comp = _for_model(comp, model)
                cands.append(comp.with_params(vals) if vals else comp)
    settings["z_critical"] = critical_z(alpha, max(len(cands), 1))
    scorer = Scorer(c, settings, refit_comps)
    ranking, skipped = [], []
    for comp in cands:
        try:
            ranking.append(scorer.score(comp))
        except PinmskError as exc:
            skipped.append((comp.label, str(exc)))
    ranking = _order(ranking, c.model, c.eq_noise.sigma, settings["z_critical"])
    _aliases(ranking, c.eq_noise.sigma)
    found = []
    if pairs and ranking:
        best = best_of(ranking)
        left = best.heldout if best is not None else scorer.base_cv
        if not consistent_with_noise(left, c.eq_noise.sigma, settings["at_floor"])[0]:
            found = scorer.pairs(ranking, best)
    windows = _worst_windows(c, window)
    cors = _correlations(c)
    elimination = scorer.elimination(critical_z(alpha, len(refit_comps))) if refit_comps else []
    return Diagnosis(c, ranking, windows, cors, settings, skipped, scorer=scorer, pairs=found,
                     elimination=elimination)


def _main_coordinate(c) -> np.ndarray:
    """The coordinate that moves most (rotations before translations, trend removed): the movement's cycle."""
    q = c.eq.motion_rows.q
    s = np.linspace(-1.0, 1.0, q.shape[0])[:, None]
    x = q - q.mean(axis=0)
    x = x - s * (np.sum(s * x, axis=0) / np.sum(s * s))
    rot = np.array([not is_prismatic(c.model, n) for n in c.model.coordinates])
    sd = np.where(rot, x.std(axis=0), 0.0) if rot.any() else x.std(axis=0)
    return q[:, [int(np.argmax(sd))]]


def _refit_components(model, refit) -> list:
    """The model's effects named in ``refit`` (labels or components), refused by name when absent."""
    have = {x.label: x for x in model.components}
    out = []
    for r in refit or ():
        label = r.label if isinstance(r, Component) else str(r)
        if label not in have:
            raise ModelError(f"refit names '{label}', which model '{model.name}' does not have "
                             f"(its effects: {', '.join(have) or 'none'})")
        comp = have[label]
        if comp.kind == "contact":
            raise ModelError(f"refit: {label} is a contact model; contact models are not refitted jointly")
        if label not in [x.label for x in out]:
            out.append(comp)
    return out


def best_of(ranking: list) -> EffectScore | None:
    """The suggestion of a ranking: the first significant candidate that passes by its held-out error;
    else, of those that pass only by taking a systematic mean away, the one that takes most of it."""
    sig = [s for s in ranking if s.significant]
    for s in sig:
        if s.test.get("passes_by") != "mean":
            return s
    return max(sig, key=lambda s: s.test["mean"]["z"]) if sig else None


def _aliases(ranking: list, sigma, *, top: int = 3) -> None:
    """Record, on the leading significant candidates, the others this trial cannot tell them from: their
    fitted changes correlate (``|r| >= 0.9``) and the held-out test between the two is not significant
    (``|z| < 2``)."""
    pool = [s for s in ranking if s.converged and s.fit.info.get("delta") is not None and s.improvement > 0
            and s.heldout is not None]
    lead = [s for s in pool if s.significant][:top]
    best = best_of(ranking)
    if best is not None and best in pool and best not in lead:
        lead.append(best)
    if not lead:
        return
    vec = {}
    for s in pool:
        d = (s.fit.info["delta"] / sigma).ravel()
        nrm = np.linalg.norm(d)
        if nrm > 0:
            vec[s.label] = d / nrm
    for s in lead:
        if s.label not in vec:
            continue
        for t in pool:
            if t is s or t.label not in vec:
                continue
            r = float(np.dot(vec[s.label], vec[t.label]))
            if abs(r) < ALIAS_CORRELATION:
                continue
            z = held_out_test(t.heldout / sigma, s.heldout / sigma)["z"]
            if abs(z) < 2.0:
                s.aliases.append((t.label, r))


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


def _body_joint(effect, model):
    """The joint carrying the body an inertial effect acts on (a payload's site, a segment's mass or
    centre of mass), else None."""
    try:
        if effect.family == "payload":
            return effect.site(model)[0]
        if effect.family in ("segment_mass", "com_offset"):
            return effect._joint(model)
    except PinmskError:
        return None
    return None


def _same_site(a, b, model) -> bool:
    """Whether two candidates, one of them a payload, load one body: payload sites on it (its centre of
    mass, its axis, a fitted point, a marker) or a payload and the body's own mass or centre of mass."""
    if model is None or "payload" not in (a.effect.family, b.effect.family):
        return False
    ja, jb = _body_joint(a.effect, model), _body_joint(b.effect, model)
    return ja is not None and ja == jb


def _at_own_com(a, b, model, k: float = 2.0) -> bool:
    """Whether ``a``, a payload at a fitted point, sits at the centre of mass of the body whose own mass
    ``b`` (``segment_mass``) changes, within ``k`` standard errors on every fitted coordinate: then the
    two differ only by the rotational inertia, and the body's own mass is the simpler reading."""
    if not (str(a.target).endswith("@point") and b.effect.family == "segment_mass"):
        return False
    pm = model.pin
    body = a.target[: -len("@point")]
    f = pm.frames[model.frame_id(body)]
    c = np.asarray(f.placement.actInv(np.asarray(pm.inertias[f.parentJoint].lever, dtype=float)))
    for i, n in enumerate(("x", "y", "z")):
        se = a.stderr.get(n)
        if se is None or not np.isfinite(se):
            continue                    # held (a planar model's normal): nothing to compare
        if abs(a.params[n] - c[i]) > k * se:
            return False
    return True


def _order(ranking: list, model=None, sigma=None, z_critical: float = 2.0, tie: float = 0.05) -> list:
    """Best held-out improvement first.  Of two candidates with one target the one with fewer parameters
    comes first when the other's held-out gain is within ``tie`` noise variances of it.  Of two payload
    sites on one body (:func:`_same_site`: a marker and a fitted point on the body's axis) the one with
    fewer parameters comes first when it is significant itself, unless the other is better held out by
    the bar every candidate meets: the extra parameter must earn its place out of sample,
    ``z >= z_critical`` in the paired :func:`held_out_test`; and a payload at a fitted point that sits
    at its body's centre of mass (:func:`_at_own_com`) comes after that body's own mass."""
    def richer_wins(a, b) -> bool:
        if sigma is None or a.heldout is None or b.heldout is None:
            return True
        return held_out_test(b.heldout / sigma, a.heldout / sigma)["z"] >= z_critical

    # exact aliases (a gain and a segment mass on one body) tie: the physical effect first
    out = sorted(ranking, key=lambda s: (not s.converged, -float(f"{s.improvement:.9g}"),
                                         getattr(s.effect, "level", "") == "sensor"))
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
    for _ in range(len(out)):
        moved = False
        for i in range(len(out)):
            for k in range(i + 1, len(out)):
                a, b = out[i], out[k]
                if (a.converged == b.converged and a.fit.stats.k > b.fit.stats.k and a.target != b.target
                        and _same_site(a, b, model) and b.significant
                        and (not richer_wins(a, b) or _at_own_com(a, b, model))):
                    out.insert(i, out.pop(k))
                    moved = True
                    break
            if moved:
                break
        if not moved:
            break
    return out


class DiagnosisRun:
    """The loop of :func:`run`: ``steps[0]`` for the model as given, one more per added effect.

    ``added`` holds each added effect's fit as made at its step (jointly with
    the earlier ones); ``refits`` what each step's joint refit changed (the
    earlier effects' values before and after, their errors and correlations);
    the final values of every added effect are those of the final model.
    :meth:`residual_report` gives the floating-base residuals of every step.
    """

    def __init__(self, steps: list, added: list, refits: list | None = None, removed: list | None = None):
        self.steps = steps
        self.added = added
        self.refits = list(refits or [])
        #: one entry per ``remove`` step (after the adds): the effect taken out and how the others moved
        self.removed = list(removed or [])

    @property
    def final(self) -> Diagnosis:
        return self.steps[-1]

    @property
    def step_labels(self) -> list:
        """One short label per step: ``"model"``, ``"+ LABEL"`` per add, ``"- LABEL"`` per removal."""
        return (["model"] + [f"+ {a.effect.label}" for a in self.added]
                + [f"- {r['removed']}" for r in self.removed])

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

    def final_effects(self) -> list:
        """The added effects with the values and errors of the final joint fit (the last step's refit of
        every added effect, against that step's noise floor); an effect that fit holds keeps its value
        in the final model."""
        out = []
        final = self.final
        sc = final.scorer
        errs, refit = {}, {}
        if sc is not None and sc.refit:
            for comp, prob, sl in zip(sc.base.components, sc.base.problems, sc.base.slices):
                errs[comp.label] = dict(zip(prob.names, sc.base_se[sl]))
            refit = {c.label: c for c in sc.base.components_at(sc.base_x)}
        gone = {r["removed"] for r in self.removed}
        for a in self.added:
            label = a.effect.label
            if label in gone:
                continue
            try:
                comp = final.model.component(label)
            except ModelError:
                out.append(a.effect)
                continue
            if label in refit:
                comp = refit[label]
            if label in errs:
                comp = comp.with_params(stderr={k: float(v) for k, v in errs[label].items()})
            out.append(comp)
        return out

    def to_dict(self) -> dict:
        """The loop as a JSON-ready dict: the final diagnosis, the effects added (final values), what
        each step's joint refit changed and the floating-base ``residual_report`` of every step."""
        if self.final.comparison.mode == "contact":
            out = self.final.to_dict([a for a in self.added if a.effect.label not in
                                      {r["removed"] for r in self.removed}], self.refits)
        else:
            out = self.final.to_dict(self.final_effects(), self.refits)
        out["removed"] = [_json(r) for r in self.removed]
        out["residual_report"] = self.residual_report()
        return out

    def residual_report(self, *, height: float | None = None) -> dict | None:
        """The floating-base residuals before and after each added effect (None without a floating base).

        Per step (``steps``: ``step``, ``model`` as given or the effect ``added``), per unactuated
        coordinate the diagnosis compares: the residual's mean, RMS and peak over the analysed frames, in
        N (N m) and in percent of body weight (of body weight x height), against OpenSim's limits
        (:func:`pinmsk.residuals.residual_table`).  The residual is what inverse dynamics of the step's
        model (its effects included) leaves at the coordinate, as ``pinmsk id`` reports it.  Body weight:
        the given model's mass times ``|g|``; ``height`` default: the given model's mean centre-of-mass
        height over the analysed frames times :data:`~pinmsk.residuals.STATURE_PER_COM_HEIGHT`.  The
        same body weight and height serve every step, so the percentages compare.
        """
        from ..residuals import OPENSIM_RESIDUAL_LIMITS, com_height, height_from_com, residual_table
        first = self.steps[0]
        if first.comparison.mode == "contact":
            return None
        model = first.model
        base = unactuated_coordinates(model)
        eq = first.comparison.eq
        coords = [c for c in eq.coordinates if c in base]
        if not coords:
            return None
        g = float(np.linalg.norm(model.gravity))
        bw = model.mass * g
        com_h = com_height(model, eq.motion_rows.q)
        h = height_from_com(com_h) if height is None else float(height)
        out = {"body_weight_N": bw, "body_weight_from": f"mass of model '{model.name}' as given "
                                                      f"({model.mass:.4g} kg) x |g| ({g:.4g} m/s^2)",
               "height_m": h,
               "height_from": ("given" if height is not None else
                               f"mean centre-of-mass height {com_h:.4g} m over the analysed frames / 0.55"),
               "limits": {u: {k: list(v) for k, v in lim.items()} for u, lim in OPENSIM_RESIDUAL_LIMITS.items()},
               "limits_source": "OpenSim, Simulation with OpenSim - Best Practices: evaluating RRA results",
               "steps": []}
        for k, d in enumerate(self.steps):
            e = d.comparison.eq
            cols = [e.coordinates.index(c) for c in coords if c in e.coordinates]
            names = [e.coordinates[j] for j in cols]
            vals = e.tau_act[:, cols]
            units = ["N" if is_prismatic(d.model, c) else "N*m" for c in names]
            f_ext = 0.0
            if e._ext_rows:
                total = sum(np.asarray(x.force, dtype=float) for x in e._ext_rows)
                f_ext = float(np.max(np.linalg.norm(total, axis=1)))
            tab = residual_table(vals, names, units, body_weight=bw, height=h, peak_external_force=f_ext,
                                 com_height=com_h)
            n_add = len(self.added)
            added = self.added[k - 1].effect.label if 0 < k <= n_add else None
            removed = self.removed[k - 1 - n_add]["removed"] if k > n_add else None
            entry = {"step": k, "model": "as given" if k == 0 else (f"+ {added}" if added else f"- {removed}"),
                     "added": added, "removed": removed,
                     "frames": tab["frames"], "peak_external_force_N": f_ext,
                     "coordinates": tab["coordinates"], "ok": tab["ok"]}
            out["steps"].append(entry)
        return out

    def residual_lines(self) -> list[str]:
        """The residual report as text: one block per step."""
        from ..residuals import residual_table_lines
        rep = self.residual_report()
        if rep is None:
            return []
        lines = [f"floating-base residuals (mean, RMS, peak; % of body weight {rep['body_weight_N']:.4g} N, "
                 f"moments of body weight x height {rep['height_m']:.3g} m ({rep['height_from']}); "
                 "verdict by OpenSim's checklist for RRA: forces peak <= 10-25 N and RMS <= 5-15 N, moments "
                 "peak <= 75 N m and RMS <= 50 N m):"]
        for st in rep["steps"]:
            lines.append(f"  step {st['step']}: model {st['model']}")
            lines += residual_table_lines(st, indent="    ")
        return lines

    def summary_text(self) -> str:
        first = self.steps[0]
        res = self.residual_lines()
        if len(self.steps) == 1:
            return "\n".join([first.summary_text()] + ([""] + res if res else []))
        out = [first.summary_text()]
        for k, (fit, step) in enumerate(zip(self.added, self.steps[1:]), 1):
            prev = self.steps[k - 1]
            out.append("")
            out.append(f"step {k}: added {fit.effect.label} ({describe_fit(fit)})")
            refit = self.refits[k - 1] if k - 1 < len(self.refits) else None
            if refit and refit.get("effects"):
                out.append("  refitted jointly with it:")
                for e in refit["effects"]:
                    for n, v in e["params"].items():
                        se = f" ± {v['stderr']:.2g}" if v["stderr"] is not None else ""
                        out.append(f"    {e['label']}.{n}: {v['before']:.4g} -> {v['after']:.4g}{se} "
                                   f"({v['change']:+.3g})")
                cors = refit.get("correlations") or {}
                if cors:
                    out.append("    correlations: " + ", ".join(f"{k2} {r:+.2f}" for k2, r in cors.items()))
            out.append(f"  total rmse {prev.rmse['total']:.4g} -> {step.rmse['total']:.4g} "
                       f"(noise floor {step.noise_floor['total']:.4g}; {prev.ratio:.1f}x -> {step.ratio:.2f}x)")
            out.append(step.summary_text(header=False))
        n_add = len(self.added)
        for k, (rem, step) in enumerate(zip(self.removed, self.steps[1 + n_add:]), n_add + 1):
            prev = self.steps[k - 1]
            out.append("")
            out.append(f"step {k}: removed {rem['removed']}")
            if rem.get("effects"):
                out.append("  the others refitted without it:")
                for e in rem["effects"]:
                    for n, v in e["params"].items():
                        out.append(f"    {e['label']}.{n}: {v['before']:.4g} -> {v['after']:.4g} ({v['change']:+.3g})")
            out.append(f"  total rmse {prev.rmse['total']:.4g} -> {step.rmse['total']:.4g} "
                       f"(noise floor {step.noise_floor['total']:.4g}; {prev.ratio:.2f}x -> {step.ratio:.2f}x)")
            out.append(step.summary_text(header=False))
        if res:
            out += [""] + res
        return "\n".join(out)

    def write_json(self, path) -> Path:
        """The JSON summary (parent folders created); refused if any number is NaN or infinite."""
        return write_json(path, self.to_dict(), parents=True)

    def __repr__(self) -> str:
        return f"<DiagnosisRun {len(self.added)} added, final {self.final!r}>"


def run(model, trial, *, add: Sequence = (), remove: Sequence = (), first: Diagnosis | None = None,
        **options) -> DiagnosisRun:
    """Diagnose, then fit and add each ``add`` entry in turn, diagnosing after each.

    Each add is a joint refit: the entry is fitted together with the effects
    added before it (warm-started from their values), all of them go into the
    model with their new values, and the next diagnosis refits them again with
    every candidate.  ``add`` entries: ``"family"`` (its best-ranked target),
    ``"family:target"``, ``(family, target)`` tuples or Components.  Writes
    nothing: the JSON summary, report and figures are
    :func:`pinmsk.presentation.report.save_diagnosis`.  ``options`` go to
    :func:`diagnose`; ``first`` reuses a diagnosis of this model and trial
    already made as step 0.

    ``remove``: labels (``family:target``) of effects to drop after the adds, one
    step each (backward elimination: the diagnosis names an effect no longer
    significant beside the others, ``suggest_remove``).  The other effects
    refitted jointly are refitted without it, as the elimination test fitted
    them, and the model is diagnosed again.
    """
    if isinstance(add, (str, Component)):
        add = [add]
    if isinstance(remove, str):
        remove = [remove]
    refit = list(options.pop("refit", ()) or ())
    d = first if first is not None else diagnose(model, trial, refit=refit, **options)
    if first is not None and d.comparison.mode != "contact":
        refit = list(d.settings.get("refit", refit))
    steps, added, refits = [d], [], []
    for entry in add or ():
        prev = steps[-1]
        if isinstance(entry, tuple):
            fam, tgt = entry[0], (entry[1] if len(entry) > 1 else None)
        else:
            fam, tgt = entry, None
        comp = prev.comparison
        opts = {k: v for k, v in options.items() if k not in ("mode", "cutoff", "grf_frames", "grf", "grf_cutoff",
                                                                    "external_loads", "sim_window",
                                                                    "missing_coordinates")}
        if comp.mode == "contact":
            fit = prev.fit(fam, tgt)
            new_model = _model_plus(prev.model, fit)
            opts["_fits"] = getattr(prev, "contact_fits", None)   # the fits depend on the trial only
            refits.append({})
        else:
            comps, fit = prev.joint_fit(fam, tgt)
            new_model = model_with_components(prev.model, comps)
            refits.append(_step_refit(prev, comps, fit))
            refit = refit + [comps[-1].label]
            opts["refit"] = refit
        steps.append(diagnose(new_model, trial, comparison=comp.with_model(new_model),
                              cutoff=prev.settings["cutoff"], **opts))
        added.append(fit)
    removed = []
    for label in remove or ():
        prev = steps[-1]
        label = _removal_label(prev.model, label)
        new_model = prev.without(label)
        opts = {k: v for k, v in options.items() if k not in ("mode", "cutoff", "grf_frames", "grf", "grf_cutoff",
                                                                    "external_loads", "sim_window")}
        if prev.comparison.mode == "contact":
            opts["_fits"] = getattr(prev, "contact_fits", None)
        else:
            refit = [r for r in refit if (r.label if isinstance(r, Component) else str(r)) != label]
            opts["refit"] = refit
        removed.append(_step_removal(prev, new_model, label))
        steps.append(diagnose(new_model, trial, comparison=prev.comparison.with_model(new_model),
                              cutoff=prev.settings["cutoff"], **opts))
    return DiagnosisRun(steps, added, refits, removed)


def _removal_label(model, label) -> str:
    """The label of the effect ``label`` names in ``model`` (``family:target``, or a family the model holds
    once); refused by name with the model's effects otherwise."""
    label = label.label if isinstance(label, Component) else str(label).strip()
    have = [c.label for c in model.components]
    if label in have:
        return label
    same = [x for x in have if x.split(":", 1)[0] == label]
    if len(same) == 1:
        return same[0]
    raise ModelError(f"remove names '{label}', which model '{model.name}' does not have "
                     f"(its effects: {', '.join(have) or 'none'})"
                     + ("; name its target, one of " + ", ".join(same) if len(same) > 1 else ""))


def _step_removal(prev: Diagnosis, new_model, label: str) -> dict:
    """What removing ``label`` did to the other effects: their values before (in ``prev``'s model) and after
    the joint refit without it."""
    out = {"removed": label, "effects": []}
    have = {c.label for c in new_model.components}
    for old in prev.model.components:
        if old.label == label or old.label not in have:
            continue
        new = new_model.component(old.label)
        params = {n: {"before": float(old.values[n]), "after": float(new.values[n]),
                      "change": float(new.values[n] - old.values[n])}
                  for n, p in old.params.items() if p.vary and new.values[n] != old.values[n]}
        if params:
            out["effects"].append({"effect": old.family, "target": old.target, "label": old.label,
                                   "params": params})
    return out


def _step_refit(prev: Diagnosis, comps: list, fit: Result) -> dict:
    """What adding ``comps[-1]`` did to the earlier effects: their values before (in ``prev``'s model) and
    after the joint refit, standard errors and correlations (from the joint covariance)."""
    new = comps[-1]
    out = {"added": new.label, "effects": [], "correlations": {}}
    names = fit.info.get("joint_names") or []
    corr = fit.info.get("joint_corr")
    for comp in comps[:-1]:
        old = prev.model.component(comp.label)
        params = {}
        for n, p in comp.params.items():
            if not p.vary:
                continue
            se = p.stderr if p.stderr is not None and np.isfinite(p.stderr) else None
            params[n] = {"before": float(old.values[n]), "after": float(p.value),
                         "change": float(p.value - old.values[n]), "stderr": se}
        out["effects"].append({"effect": comp.family, "target": comp.target, "label": comp.label,
                               "params": params})
    if corr is not None and names:
        for i in range(len(names)):
            for j in range(i + 1, len(names)):
                r = corr[i, j]
                if np.isfinite(r) and abs(r) >= 0.3:
                    out["correlations"][f"{names[i]}~{names[j]}"] = float(r)
    return out
