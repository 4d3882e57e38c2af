"""The noise floor of a comparison: noise models of the measured channels, propagated through the analysis.

Each measured input gets a :class:`pinmsk.signals.noise.NoiseModel`, fitted to
the trial's own channel above the movement's band (``band_start = 2 f_99``,
``f_99`` the frequency below which 99 % of the raw coordinates' power lies):

``coordinates``
    the raw angles and translations; white, or coloured when the spectrum
    shows a low-pass (a lab that filtered them) *with its flat passband*
    (``fit_noise(flat_passband=True)``): a movement's own spectrum falls like
    a low-pass just above its band (a walk's heel strikes), so a spectrum that
    falls from the band start on is movement, and the noise is white at the
    weighted median of the bands' levels, which the flat top of the spectrum
    sets -- movement is never counted as noise;
``moments``
    measured ``<coord>_moment`` channels; white only: a single record cannot
    tell low-passed noise from friction steps, which are signal;
``ground reaction``
    force, free-moment and centre-of-pressure channels of the trial, or of the
    separate record a ``grf=`` / ``external_loads=`` file gives (at its own
    rate); white only, for the same reason (heel strikes, plate on/off).  A
    plate's unloaded spans give its noise directly (:func:`_fit_ground_reaction`);
    the realisations act where the plate is loaded, as the analyses do;
``excitation``
    EMG envelopes / excitations, their own model: multiplicative (the noise
    scales with the envelope) and coloured by the envelope's low-pass, whose
    corner is ``trial.meta["emg_lowpass"]`` and design rate
    ``trial.meta["emg_rate"]`` when known (set by
    :func:`pinmsk.signals.emg.envelopes`), else fitted.  A low-pass below the
    second band edge (``sqrt(2) band_start``, 4 Hz for the forearm's trials)
    cannot be told from the activations' own harmonics and must be given
    (``trial.with_meta(emg_lowpass=3.0, emg_rate=1000.0)``).

Propagation: ``REALISATIONS`` seeded realisations of each source are added to
the measured channels and the comparison's residual is recomputed through the
same path as the measurement -- coordinates through the low-pass, the spline
derivatives, inverse dynamics (and the muscles' moment arms); GRF through
:func:`pinmsk.kinematics.prepare` (the same low-pass) and the feet's
Jacobians; moments directly; excitations through the model's muscle-level
chain and the muscle moments.  The floor of channel ``c`` is the RMS of the
change, ``sigma_c^2 = kinematic_c^2 + direct_c^2`` (coordinates vs. the rest).
Because the propagation runs through the model, the floor is recomputed for
every model compared (an added payload makes the angle noise count for more;
an added activation dynamics filters the EMG noise).

Levels the user states (``noise={channel or group: sigma}``) replace the
fitted models of those channels by white noise of that RMS (:func:`_stated`).

The floor is checked against the residual (:func:`consistency`): the residual
of any model holds the noise, so on a channel where its RMS lies below
``1 / CONSISTENT_RATIO`` of the floor, the floor counts more than the noise and
is capped at the residual's RMS (not a stated level), and the method says so.

A correction keeps the direct sources honest: in each band, the residual's
power beyond the propagated kinematic noise bounds the direct sources' (an
EMG envelope's activation harmonics are signal in the input but cancel in the
residual of a right model).  Where the residual shows less than the direct
sources predict, by more than twice the band's statistical spread, their
band powers are scaled down and their models refitted.
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Mapping

import numpy as np

from ..effects._base import is_prismatic
from ..kinematics import coordinate_filter, prepare
from ..signals.filtering import differentiate
from ..io.external_loads import read_external_loads
from ..io.tables import read_trial
from ..signals.noise import LOG_VAR, TOP_BAND, NoiseModel, band_edges, band_powers, fit_noise, signal_band
from ..signals.sampling import median_step
from ..trial import Trial, moment_channel, parse_ground_reaction
from .comparison import NoiseFloor

__all__ = ["CONSISTENT_RATIO", "REALISATIONS", "STATED_GROUPS", "consistency", "fit_sources", "ground_reaction_source",
           "parse_noise", "propagated_floor"]

#: Monte-Carlo realisations per source group.
REALISATIONS = 3
#: A floor more than this factor above the residual's RMS on a channel is inconsistent with it (capped).
CONSISTENT_RATIO = 1.5
#: records whose propagated floor lies more than this factor below the residual on every channel hold no
#: measurable noise (smoothed or processed data, e.g. coordinates from IK and RRA, filtered plates): the
#: floor is not estimable from them (:func:`propagated_floor`)
PROCESSED_RATIO = 1e3
_SEED = 12345


def fit_sources(model, trial, eq, *, mode: str, excitation_kind: str | None, grf_in_trial: bool,
                grf_source=None) -> dict:
    """``{group: NoiseModel}`` of the trial's measured channels (see the module notes).

    ``grf_source``: the ground reaction record (a Trial at its own rate) when the loads come from a
    separate file (``grf=``, ``external_loads=``) rather than the trial's own channels."""
    t = np.asarray(trial.time, dtype=float)
    rate = 1.0 / median_step(t)
    names = eq.kinematic_channels          # the measured coordinates (OpenSim's on an exact import)
    raw_q = np.column_stack([trial[c] for c in names])
    band_start = float(np.clip(2.0 * signal_band(raw_q, rate), 1.0, TOP_BAND * rate / 4.0))
    out = {"coordinates": fit_noise(raw_q, rate, band_start, channels=names, flat_passband=True)}
    if mode in ("torque", "motion"):
        names = [moment_channel(c) for c in eq.coordinates if moment_channel(c) in trial]
        if names:
            out["moments"] = fit_noise(np.column_stack([trial[n] for n in names]), rate, band_start,
                                       channels=names, coloured=False)
    grf = trial if grf_in_trial else grf_source
    if grf is not None:
        gm = _fit_ground_reaction(grf, band_start)
        if gm is not None:
            out["ground reaction"] = _WithSource.of(gm, None if grf_in_trial else grf_source)
    if mode == "muscle" and excitation_kind is not None:
        names = [f"{m}_{excitation_kind}" for m in model.muscle_names]
        corner = trial.meta.get("emg_lowpass")
        corner = float(corner) if corner and 0 < float(corner) < 0.5 * rate else None
        made_at = trial.meta.get("emg_rate")
        made_at = float(made_at) if corner is not None and made_at and float(made_at) > 0 else None
        out["excitation"] = fit_noise(np.column_stack([trial[n] for n in names]), rate, band_start,
                                      channels=names, multiplicative=True, corner=corner, design_rate=made_at)
    return out


@dataclass(frozen=True)
class _WithSource(NoiseModel):
    """A noise model of channels recorded in another file than the trial (``source``: that Trial)."""

    source: object = field(default=None, repr=False, compare=False)

    @classmethod
    def of(cls, m: NoiseModel, source) -> "_WithSource":
        return cls(**{f.name: getattr(m, f.name) for f in fields(NoiseModel)}, source=source)


def ground_reaction_source(options: Mapping):
    """The ground reaction record (a Trial at its own rate) of ``grf=`` or an ``external_loads=`` file's
    ``datafile``, or None when the loads are the trial's own channels (or absent)."""
    grf, xml = options.get("grf"), options.get("external_loads")
    if grf is None and xml is not None:
        loads = xml if hasattr(xml, "loads") else read_external_loads(xml)
        grf = loads.datafile
    if grf is None:
        return None
    return grf if isinstance(grf, Trial) else read_trial(grf)


#: Vertical force (N) below which a plate is unloaded: the analyses give it no force there
#: (:func:`pinmsk.grf.plate_wrench`'s ``min_force``), so its noise there never reaches a residual.
UNLOADED_FORCE = 20.0
#: Fewest unloaded samples (per plate, after the margins at the spans' ends) that give its noise directly.
UNLOADED_MIN = 20


def _plates(names):
    """``{side: (vertical force channel or None, every channel name)}`` of ground reaction channels."""
    out = {}
    for n in names:
        g = parse_ground_reaction(n)
        vert, every = out.get(g.side, (None, []))
        every.append(n)
        if g.quantity == "force" and g.axis == "y":
            vert = n
        out[g.side] = (vert, every)
    return out


def _fit_ground_reaction(data, band_start):
    """White noise model of the ground reaction channels of ``data`` (a Trial at the plates' rate), the
    plates' own noise where their unloaded spans show it.

    A plate is unloaded where its vertical force is below :data:`UNLOADED_FORCE`; there it records its
    own noise.  Each unloaded span, less a margin of a fifth of it at either end (the load's onset and
    release), without its linear trend (a drifting zero is no noise), gives the standard deviation of
    each force and free-moment channel, white over the record's band; at least :data:`UNLOADED_MIN`
    such samples are needed.  A plate whose unloaded samples mostly hold one value was zeroed by the
    lab below a threshold and shows no noise there; its channels, and the centres of pressure
    (undefined when unloaded), keep the spectral fit of the whole record (white only: a single record
    cannot tell heel strikes and plate on/off from coloured noise).  The realisations act where each
    plate is loaded (:attr:`NoiseModel.modulation`: 1 loaded, 0 unloaded), as the analyses do."""
    names = []
    for n in data.names:
        g = parse_ground_reaction(n)
        x = np.asarray(data[n], dtype=float)
        if g is not None and np.all(np.isfinite(x)) and np.ptp(x) > 0:
            names.append(n)
    if not names:
        return None
    rate = 1.0 / median_step(np.asarray(data.time, dtype=float))
    X = np.column_stack([np.asarray(data[n], dtype=float) for n in names])
    model = fit_noise(X, rate, min(band_start, TOP_BAND * rate / 4.0), channels=names, coloured=False)
    white = model.white.copy()
    loaded = np.ones_like(X)
    notes = []
    col = {n: j for j, n in enumerate(names)}
    for side, (vert, every) in _plates(names).items():
        label = "plate" if side is None else f"plate {side}"
        if vert is None:
            continue
        off = np.asarray(data[vert], dtype=float) < UNLOADED_FORCE
        for n in every:
            loaded[:, col[n]] = (~off).astype(float)
        direct = [n for n in every if parse_ground_reaction(n).quantity != "point"]
        idx = np.flatnonzero(off)
        spans = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1) if idx.size else []
        cores = [sp[sp.size // 5: sp.size - sp.size // 5] for sp in spans]
        cores = [c for c in cores if c.size >= 5]
        n_core = int(sum(c.size for c in cores))
        if n_core < UNLOADED_MIN:
            notes.append(f"{label}: not unloaded long enough to show its own noise; white noise from the "
                         "spectrum of its record")
            continue
        core = np.concatenate(cores)
        V = np.column_stack([np.asarray(data[n], dtype=float)[core] for n in direct])
        _, counts = np.unique(V, axis=0, return_counts=True)
        if counts.max() > 0.5 * core.size:
            notes.append(f"{label}: zeroed by the lab while unloaded (no noise there); white noise from the "
                         "spectrum of its record")
            continue
        for n in direct:
            x = np.asarray(data[n], dtype=float)
            ss, dof = 0.0, 0
            for c in cores:
                tt = np.arange(c.size, dtype=float)
                res = x[c] - np.polyval(np.polyfit(tt, x[c], 1), tt)
                ss += float(res @ res)
                dof += c.size - 2
            white[col[n]] = np.sqrt(ss / max(dof, 1)) / np.sqrt(0.5 * rate)
        notes.append(f"{label}: force and moment noise from its {n_core} unloaded samples ("
                     + ", ".join(f"{n} {white[col[n]] * np.sqrt(0.5 * rate):.3g}" for n in direct) + ")")
    return replace(model, white=white, modulation=loaded, notes=tuple(notes))


#: Group names a stated noise level may use for all channels of a kind.
STATED_GROUPS = {"angles": "coordinates", "translations": "coordinates", "coordinates": "coordinates",
                 "moments": "moments", "ground_reaction": "ground reaction", "excitations": "excitation"}
_UNITS = {"deg": np.pi / 180.0, "rad": 1.0, "mm": 1e-3, "m": 1.0, "n": 1.0, "nm": 1.0}


def parse_noise(items) -> dict:
    """``["NAME=SIGMA[unit]", ...]`` (the command line's ``--noise``) -> ``{name: sigma}`` in SI units.

    ``unit`` is optional: ``deg`` or ``rad`` for angles, ``mm`` or ``m`` for translations, ``N`` or
    ``Nm`` for forces and moments (no unit: SI)."""
    from ..errors import TrialError

    out = {}
    for item in items or ():
        if "=" not in item:
            raise TrialError(f"--noise entries look like NAME=SIGMA (e.g. angles=0.1deg, pelvis_tx=0.5mm, "
                             f"moments=0.2), got {item!r}")
        name, val = (x.strip() for x in item.split("=", 1))
        low = val.lower().replace(" ", "")
        unit = next((u for u in sorted(_UNITS, key=len, reverse=True) if low.endswith(u)), None)
        num = low[: len(low) - len(unit)] if unit else low
        try:
            sigma = float(num) * (_UNITS[unit] if unit else 1.0)
        except ValueError:
            raise TrialError(f"--noise {item!r}: {val!r} is not a number with an optional unit "
                             "(deg, rad, mm, m, N, Nm)") from None
        out[name] = sigma
    return out


def _stated(models: dict, stated: Mapping, model) -> tuple[dict, list]:
    """The noise models with the user's stated levels (white, ``sigma`` RMS over the record's band) in
    place of the fitted ones; each name must be a measured channel or a group (:data:`STATED_GROUPS`).
    Returns ``(models, [(channel, sigma), ...])``."""
    from ..errors import TrialError

    if not stated:
        return models, []
    out = dict(models)
    done = []
    known = {n: g for g, m in models.items() for n in m.channels}
    for name, sigma in stated.items():
        sigma = float(sigma)
        if not np.isfinite(sigma) or sigma < 0:
            raise TrialError(f"noise: the level of {name!r} must be a finite sigma >= 0, got {sigma!r}")
        if name in STATED_GROUPS:
            g = STATED_GROUPS[name]
            if g not in out:
                raise TrialError(f"noise: {name!r} names {g} noise, but this comparison measures none "
                                 f"(its noise sources: {', '.join(out) or 'none'})")
            chans = list(out[g].channels)
            if g == "coordinates" and name != "coordinates":
                chans = [c for c in chans if is_prismatic(model, c) == (name == "translations")]
        elif name in known:
            g, chans = known[name], [name]
        else:
            raise TrialError(f"noise: {name!r} is no measured channel of this comparison nor a group; use "
                             f"one of {', '.join(sorted(STATED_GROUPS))} or a channel: "
                             f"{', '.join(list(known)[:12])}{', ...' if len(known) > 12 else ''}")
        m = out[g]
        white, coloured = m.white.copy(), m.coloured.copy()
        for c in chans:
            j = m.channels.index(c)
            level = sigma
            if m.modulation is not None and m.kind == "multiplicative":
                level = sigma / max(float(np.sqrt(np.mean(m.modulation[:, j] ** 2))), 1e-300)
            white[j], coloured[j] = level / np.sqrt(0.5 * m.rate), 0.0
            done.append((c, sigma))
        out[g] = replace(m, white=white, coloured=coloured,
                         notes=tuple(m.notes) + (f"stated: {', '.join(chans)} {sigma!r}",))
    return out, done


def _realisations(models, group, n):
    """Seeded realisations (R, n, k) of one group (its own stream, so groups are independent)."""
    seed = _SEED + sum(ord(ch) for ch in group)
    return models[group].sample(np.random.default_rng(seed), n, REALISATIONS)


def _kinematic(eq, models, cutoff, method="butterworth"):
    t = eq.motion.t
    xi = _realisations(models, "coordinates", t.size)
    out = []
    for r in range(REALISATIONS):
        # the coordinates' own filter (OpenSim's under its ExternalLoads convention): its noise gain
        dq, dv, da = differentiate(t, xi[r], cutoff=cutoff, method=method)
        out.append(eq.residual_for(eq.perturbed_motion(dq, dv, da)) - eq.e)
    return np.array(out)


def _direct(eq, models, trial, options, cutoff):
    """Realisations (R, n, C) of the residual's change by the moment, GRF and excitation noise."""
    t = eq.motion.t
    out = np.zeros((REALISATIONS,) + eq.e.shape)
    if "moments" in models:
        mm = models["moments"]
        xi = _realisations(models, "moments", t.size)
        col = {moment_channel(c): j for j, c in enumerate(eq.coordinates)}
        for k, name in enumerate(mm.channels):
            out[:, :, col[name]] += xi[:, eq.rows, k]
    if "ground reaction" in models:
        gm = models["ground reaction"]
        source = models["ground reaction"].source
        data = trial if source is None else source
        xi = _realisations(models, "ground reaction", np.asarray(data.time).size)
        for r in range(REALISATIONS):
            noisy = data.with_channels({n: np.asarray(data[n]) + xi[r, :, k] for k, n in enumerate(gm.channels)})
            if source is None:
                inputs = prepare(eq.model, noisy, cutoff=cutoff, frames=options.get("grf_frames"),
                                 grf_cutoff=options.get("grf_cutoff", "auto"),
                                 missing_coordinates=options.get("missing_coordinates", "refuse"))
            else:
                inputs = prepare(eq.model, trial, cutoff=cutoff, grf=noisy, external_loads=options.get("external_loads"),
                                 frames=options.get("grf_frames"), grf_cutoff=options.get("grf_cutoff", "auto"),
                                 missing_coordinates=options.get("missing_coordinates", "refuse"))
            out[r] += eq.residual_for(eq.motion, external=inputs.external) - eq.e
    if "excitation" in models:
        xi = _realisations(models, "excitation", t.size)
        eq.set_excitation_noise(list(xi))
        for r in range(REALISATIONS):
            out[r] += eq.excitation_response(xi[r])
    else:
        eq.set_excitation_noise(None)
    return out


def _band_correction(eq, rate, edges, kin, direct):
    """Factors (<= 1) on the direct sources' band powers from the residual's band powers: ``(J,)`` over
    all channels, and ``(J, C)`` per compared channel (for a source whose channels are the compared ones:
    the measured moments).

    A band is corrected only where the residual's power, allowed two standard deviations of its
    statistical spread, falls short of the propagated total.  Per channel, because one channel's
    propagated kinematic noise (a floating base's, say) says nothing of another's measured moment."""
    Pc = band_powers(eq.e, rate, edges)
    Kc = np.mean([band_powers(x, rate, edges) for x in kin], axis=0)
    Dc = np.mean([band_powers(x, rate, edges) for x in direct], axis=0)
    n_eff = 2.0 * np.diff(edges) * (eq.rows.size / rate)
    slack = np.exp(2.0 * np.sqrt(LOG_VAR / n_eff))

    def factor(P, K, D, slack):
        with np.errstate(divide="ignore", invalid="ignore"):
            f = np.where((D > 0) & (P * slack < K + D), (P * slack - K) / D, 1.0)
        return np.clip(f, 0.01, 1.0)

    return (factor(Pc.sum(axis=1), Kc.sum(axis=1), Dc.sum(axis=1), slack),
            factor(Pc, Kc, Dc, slack[:, None]))


def propagated_floor(eq, trial, *, mode: str, excitation_kind: str | None, cutoff, options: Mapping,
                     channels, grf_in_trial: bool, fits: dict | None = None, noise: Mapping | None = None
                     ) -> NoiseFloor:
    """The comparison's :class:`~pinmsk.diagnose.comparison.NoiseFloor` (see the module notes).

    ``fits`` reuses the input noise models fitted for another model of the same trial; ``noise`` states
    noise levels (``{channel or group: sigma}``, SI units, white over the record's band) in place of
    the fitted ones: they are propagated like the fitted ones, neither corrected by the residual's band
    powers nor capped by it (the consistency check is still reported)."""
    model = eq.model
    if fits is None:
        source = None if grf_in_trial else ground_reaction_source(options)
        fits = fit_sources(model, trial, eq, mode=mode, excitation_kind=excitation_kind, grf_in_trial=grf_in_trial,
                           grf_source=source)
        fits, _ = _stated(fits, noise or {}, model)
    stated = [(c, float(v)) for g in fits.values() for c, v in _stated_of(g)]
    rate = fits["coordinates"].rate
    band_start = fits["coordinates"].band_start
    kin = _kinematic(eq, fits, cutoff, coordinate_filter(options.get("grf_cutoff", "auto"),
                                                       options.get("external_loads")))
    used = dict(fits)
    direct_groups = [g for g in fits if g != "coordinates"]
    direct = _direct(eq, fits, trial, options, cutoff)
    correction = None
    if direct_groups:
        edges = band_edges(band_start, rate)
        s, s_channel = _band_correction(eq, rate, edges, kin, direct)
        col = {moment_channel(c): j for j, c in enumerate(eq.coordinates)}
        free = [g for g in direct_groups if not any(n.startswith("stated: ") for n in fits[g].notes)]
        if (np.any(s < 0.999) or np.any(s_channel < 0.999)) and free:
            correction = s
            for g in free:                       # the user's stated levels stand
                old = fits[g]
                if g == "ground reaction":
                    # white noise: one factor, its band powers' share-weighted mean
                    w = np.diff(edges)
                    used[g] = old.scaled(np.sqrt(float(np.sum(w * s) / np.sum(w))))
                    continue
                given = old.corner_given
                # the measured moments are the compared channels: each gets its own channel's factors
                scale = (s_channel[:, [col[n] for n in old.channels]]
                         if g == "moments" and all(n in col for n in old.channels) else s[:, None])
                used[g] = fit_noise(np.column_stack([trial[n] for n in old.channels]), rate, band_start,
                                    channels=old.channels, multiplicative=old.kind == "multiplicative",
                                    corner=float(old.corner[0]) if given else None,
                                    design_rate=float(old.design_rate[0]) if given else None,
                                    coloured=g in ("excitation", "coordinates"), band_scale=scale)
            direct = _direct(eq, used, trial, options, cutoff)
    kin_rms = np.sqrt(np.mean(kin ** 2, axis=(0, 1)))
    dir_rms = np.sqrt(np.mean(direct ** 2, axis=(0, 1)))
    sigma = np.sqrt(kin_rms ** 2 + dir_rms ** 2)
    sigma = np.where(sigma > 0, sigma, np.finfo(float).tiny)
    method = _method(model, used, band_start, cutoff, correction)
    if stated:
        method += ("; noise levels stated by the user (white over the record's band, in place of the fitted "
                   "ones): " + ", ".join(f"{c} {_level(model, c, v) if c in model.coordinates else f'{v:.4g}'}"
                                         .replace(f"{c} {c} ", f"{c} ") for c, v in stated))
    check = consistency(eq.e, sigma, channels)
    if stated:
        check["stated"] = True
        if check["capped"]:
            method += "; " + check["text"].replace("so the floor there is capped at the residual's RMS",
                                                   "but the levels are stated, so the floor stands")
        check["capped"], check["factors"] = [], np.ones_like(sigma)
    if check["capped"]:
        f = check["factors"]
        sigma, kin_rms, dir_rms = sigma * f, kin_rms * f, dir_rms * f
        method += "; " + check["text"]
    rms = np.sqrt(np.mean(np.asarray(eq.e, dtype=float) ** 2, axis=0))
    estimable = bool(stated or not np.all(rms > PROCESSED_RATIO * sigma))
    if not estimable:
        # no noise in the records to speak of: a floor of 1e-5 N would weigh the channels by its accidents;
        # each is weighed by its own residual instead, and the floor is said to be unknown
        f = rms / sigma
        estimate = sigma
        sigma, kin_rms, dir_rms = rms.copy(), kin_rms * f, dir_rms * f
        method += (f"; the records hold no measurable noise above {band_start:.3g} Hz (the propagated floor, "
                   f"{float(np.sqrt(np.mean(estimate ** 2))):.3g} over the channels, lies more than "
                   f"{PROCESSED_RATIO:.0f} times below the residual on every channel: smoothed or processed "
                   "data): the floor is NOT ESTIMABLE from them, so each channel is weighed by its residual's "
                   "RMS (as given) instead; state the noise with --noise NAME=SIGMA")
    info = {"method": "propagated noise models", "band_start_hz": band_start, "realisations": REALISATIONS,
            "sources": {g: m.to_dict() for g, m in used.items()},
            "kinematic": {c: float(v) for c, v in zip(channels, kin_rms)},
            "direct": {c: float(v) for c, v in zip(channels, dir_rms)},
            "consistency": {k: v for k, v in check.items() if k not in ("factors", "text")},
            "estimable": estimable,
            **({} if estimable else {"estimate": {c: float(v) for c, v in zip(channels, estimate)}}),
            **({"stated": {c: v for c, v in stated}} if stated else {})}
    if correction is not None:
        edges = band_edges(band_start, rate)
        info["band_correction"] = [{"band_hz": [float(a), float(b)], "factor": float(f)}
                                   for a, b, f in zip(edges[:-1], edges[1:], correction)]
    return NoiseFloor(tuple(channels), sigma, dir_rms, kin_rms, method, models=used, fits=fits, info=info)


def consistency(residual, sigma, channels, *, limit: float = CONSISTENT_RATIO) -> dict:
    """The floor checked against the residual it is the floor of.

    The residual of any model holds the noise: ``E[rms^2] = sigma^2 + (what the model misses)^2``, so
    a residual whose RMS lies below ``sigma / limit`` on a channel shows that the floor there counts
    more than the noise (movement in the measured channels above the band start, a spectrum whose
    tail the noise model took for noise).  Such a channel's floor is capped at the residual's RMS --
    the most noise the residual admits.  Returns ``{"limit", "checked": {channel: {"estimate",
    "residual_rms", "ratio"}}, "capped": [channels], "factors" (C,), "text"}``."""
    e = np.asarray(residual, dtype=float)
    rms = np.sqrt(np.mean(e ** 2, axis=0))
    ratio = rms / sigma
    bad = (ratio < 1.0 / limit) & (rms > 0)
    factors = np.where(bad, rms / sigma, 1.0)
    checked = {c: {"estimate": float(s), "residual_rms": float(r), "ratio": float(q)}
               for c, s, r, q in zip(channels, sigma, rms, ratio)}
    capped = [c for c, b in zip(channels, bad) if b]
    text = ""
    if capped:
        text = ("inconsistent with the residual on " + ", ".join(
            f"{c} (estimate {checked[c]['estimate']:.3g}, residual RMS {checked[c]['residual_rms']:.3g})"
            for c in capped) + f": a residual below 1/{limit:g} of its floor shows the floor counts more than "
            "the noise, so the floor there is capped at the residual's RMS")
    return {"limit": float(limit), "checked": checked, "capped": capped, "factors": factors, "text": text}


def _stated_of(m) -> list:
    """``[(channel, sigma)]`` of the levels stated in a noise model's notes (see :func:`_stated`)."""
    out = []
    for note in m.notes:
        if note.startswith("stated: "):
            body = note[len("stated: "):]
            names, _, val = body.rpartition(" ")
            out.extend((c.strip(), float(val)) for c in names.split(","))
    return out


def _level(model, name, rms):
    if name in model.coordinates:
        return f"{name} {rms * 1000:.3g} mm" if is_prismatic(model, name) else f"{name} {np.rad2deg(rms):.3g} deg"
    return f"{name} {rms:.3g}"


def _method(model, models, band_start, cutoff, correction) -> str:
    parts = []
    cm = models["coordinates"]
    parts.append("angle noise (" + cm.describe() + ": " + ", ".join(
        _level(model, c, s) for c, s in zip(cm.channels, cm.rms())) + f") through the "
        f"{f'{cutoff:g}-Hz low-pass' if cutoff else 'unfiltered path'}, spline derivatives and inverse dynamics")
    if "moments" in models:
        mm = models["moments"]
        parts.append("moment noise (" + mm.describe() + ": " + ", ".join(
            f"{c} {s:.3g} N m" for c, s in zip(mm.channels, mm.rms())) + ") directly")
    if "ground reaction" in models:
        gm = models["ground reaction"]
        src = getattr(gm, "source", None)
        where = (f" of {Path(str(src.meta.get('source'))).name if src.meta.get('source') else 'the GRF record'}"
                 f" at {gm.rate:.4g} Hz" if src is not None else "")
        parts.append(f"ground-reaction noise{where} ({gm.describe()}, {len(gm.channels)} channels"
                     + (": " + "; ".join(gm.notes) if gm.notes else "") + ") through the same low-pass and the feet, "
                     "where each plate is loaded")
    if "excitation" in models:
        em = models["excitation"]
        parts.append("EMG/excitation noise (" + em.describe() + ", RMS " + ", ".join(
            f"{s:.2g}" for s in em.rms()) + ") through the muscle-level chain and the muscle moments")
    text = (f"noise models fitted to each measured channel above {band_start:.3g} Hz (twice the top of the "
            "movement's band; robust half-octave band powers, white or Butterworth-coloured spectrum by BIC, "
            "the angles coloured only where a flat passband shows, so the movement's own tail is not noise), "
            f"propagated by {REALISATIONS} seeded Monte-Carlo realisations: " + "; ".join(parts))
    if correction is not None:
        text += (f"; direct noise capped by the residual's band powers (lowest factor {np.min(correction):.2g})")
    return text
