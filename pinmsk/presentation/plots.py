"""Figures (matplotlib, headless): trials and the diagnosis.

Every function builds a :class:`matplotlib.figure.Figure` on the Agg canvas
directly -- no pyplot, no global backend switch, no display -- and either
returns it or saves it as PNG (every ``plot_*`` takes ``path=``; ``save_*``
functions write files).  Trials and results:

* :func:`plot_channels` / :func:`save_channels` -- channels of any Trial against time;
* :func:`plot_moments` -- the ``<coord>_moment`` channels of a Trial;
* :func:`plot_muscles` -- muscle forces or activations over time, optionally
  against EMG (``<muscle>_emg`` channels, or a separate EMG Trial), with the
  correlation in the legend (:func:`emg_correlations`);
* :func:`plot_results_comparison` -- two results (e.g. SO vs FSO) on one time
  base, and their difference (:func:`align_results`);
* :func:`save_results_figures` -- all of these for one result.

Diagnosis figures:

* :func:`plot_comparison` -- model vs measurement per channel, with the noise
  floor as a band around the model, and the residual beneath;
* :func:`plot_residual_heatmap` -- residual / noise floor over time x channel;
* :func:`plot_ranking` -- candidate effects by held-out explained fraction;
* :func:`plot_error_steps` -- total and per-channel error after each added effect;
* :func:`plot_effect_contribution` -- the residual beside the best candidate's
  fitted contribution (the per-effect breakdown).

:func:`save_diagnosis_figures` writes all of them for a run;
:func:`save_channels` plots channels of any Trial (``pinmsk id --plot``).
"""
from __future__ import annotations

import io
from pathlib import Path
from typing import Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..contact.foot import SITES
from ..errors import PinmskError
from ..io.output_files import atomic_write
from ..trial import moment_channel, moment_channels

__all__ = ["new_figure", "figure_png", "save_figure", "save_channels", "plot_channels", "plot_moments",
           "muscles_in", "emg_source", "emg_correlations", "plot_muscles", "align_results",
           "plot_results_comparison", "find_emg", "results_figures", "save_results_figures", "plot_comparison",
           "plot_residual_heatmap", "plot_ranking", "plot_error_steps", "plot_effect_contribution",
           "save_diagnosis_figures"]

_MEASURED = "0.35"
_MODEL = "#c0392b"
_BAND = "#f5b7b1"
_SIG = "#1f77b4"
_NOT = "0.7"


def new_figure(width: float = 8.0, height: float = 4.0, *, layout: str | None = "constrained") -> Figure:
    """A Figure on its own Agg canvas (``layout=None``: placed by ``subplots_adjust``)."""
    fig = Figure(figsize=(width, height), dpi=100, layout=layout)
    FigureCanvasAgg(fig)
    return fig


def figure_png(fig: Figure) -> bytes:
    """PNG bytes of a figure."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def save_figure(fig: Figure, path, **savefig) -> Path:
    """Write ``fig`` as PNG to ``path`` (parent folders created) atomically; returns the path."""
    return atomic_write(path, lambda fh: fig.savefig(fh, format="png", **savefig), binary=True, parents=True)


# -- trials ----------------------------------------------------------------------------------

def plot_channels(trial, channels: Sequence[str], *, ylabel: str = "", title: str | None = None,
                  path=None) -> Figure:
    """``channels`` of a Trial against time, one panel each (missing channels are left out)."""
    chans = [c for c in channels if c in trial]
    if not chans:
        raise PinmskError(f"none of the channels {list(channels)[:6]} is in the trial "
                          f"(it has {', '.join(trial.names[:8])}{' ...' if trial.n_channels > 8 else ''})")
    t = np.asarray(trial.time)
    fig = new_figure(8.0, 1.6 + 1.4 * len(chans))
    axes = fig.subplots(len(chans), 1, sharex=True, squeeze=False)[:, 0]
    for ax, c in zip(axes, chans):
        ax.plot(t, trial[c], lw=1.0, color=_SIG)
        ax.set_ylabel(ylabel or trial.units.get(c, "") or c, fontsize=8)
        ax.set_title(c, fontsize=9, loc="left")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    if title:
        fig.suptitle(title, fontsize=10)
    if path is not None:
        save_figure(fig, path)
    return fig


def save_channels(trial, channels: Sequence[str], out_dir, *, stem: str = "channels",
                  ylabel: str = "", per_figure: int = 8) -> list[Path]:
    """Plot ``channels`` of a Trial against time; one PNG per ``per_figure`` channels."""
    chans = [c for c in channels if c in trial]
    out = []
    for k in range(0, len(chans), per_figure):
        fig = plot_channels(trial, chans[k:k + per_figure], ylabel=ylabel)
        name = f"{stem}.png" if len(chans) <= per_figure else f"{stem}_{k // per_figure + 1}.png"
        out.append(save_figure(fig, Path(out_dir) / name))
    return out


def moment_channels_in(trial, coordinates=None) -> list[str]:
    """The ``<coord>_moment`` channels of a Trial (of ``coordinates`` if given), in order."""
    if coordinates is None:
        return [c for c in trial.names if c.endswith("_moment")]
    return [n for n in moment_channels(coordinates) if n in trial]


def plot_moments(trial, coordinates=None, *, title: str | None = None, path=None) -> Figure:
    """Joint moments (the ``<coord>_moment`` channels) against time."""
    chans = moment_channels_in(trial, coordinates)
    if not chans:
        raise PinmskError("the trial has no <coord>_moment channels to plot; run inverse dynamics "
                          "first (pinmsk.inverse_dynamics or `pinmsk id`)")
    return plot_channels(trial, chans, ylabel="moment (N m)", title=title or "joint moments", path=path)


# -- muscles, EMG, comparisons -----------------------------------------------------------------

_QUANTITIES = {"force": ("_force", "force (N)"), "activation": ("_activation", "activation (0-1)")}


def _suffix(quantity: str) -> tuple[str, str]:
    if quantity not in _QUANTITIES:
        raise PinmskError(f"quantity must be one of {', '.join(_QUANTITIES)}; got {quantity!r}")
    return _QUANTITIES[quantity]


def muscles_in(results, quantity: str = "force", muscles=None) -> list[str]:
    """Muscles with a ``<muscle>_<quantity>`` channel in ``results`` (restricted to ``muscles``)."""
    suf, _ = _suffix(quantity)
    # a static optimization's actuators (<name>_force, named in its meta) are not muscles
    meta = getattr(results, "meta", None) or {}
    listed = meta.get("actuator_names") or (meta.get("header") or {}).get("actuator_names") or ""
    actuators = {n.strip() for n in str(listed).split(",") if n.strip()}
    have = [c[: -len(suf)] for c in results.names if c.endswith(suf) and len(c) > len(suf)
            and c[: -len(suf)] not in actuators]
    if muscles is None:
        return have
    missing = [m for m in muscles if m not in have]
    if missing:
        raise PinmskError(f"no {quantity} channel for muscle(s) {missing} in the results "
                          f"(muscles with {quantity}: {', '.join(have) or 'none'})")
    return list(muscles)


def emg_source(results, emg=True, muscles=None) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """EMG per muscle as ``{muscle: (time, values)}`` (muscles without EMG left out).

    ``emg``: True -- the ``<muscle>_emg`` channels of ``results``; a Trial --
    its ``<muscle>_emg`` channels, or channels named ``<muscle>`` (as
    :func:`pinmsk.signals.emg.envelopes` writes them); None or False -- no EMG.
    ``muscles`` default to those with a force or activation channel in ``results``.
    """
    if emg is None or emg is False:
        return {}
    if muscles is None:
        muscles = list(dict.fromkeys(muscles_in(results, "activation") + muscles_in(results, "force")))
    src = results if emg is True else emg
    if not hasattr(src, "names") or not hasattr(src, "time"):
        raise PinmskError(f"emg must be True (the <muscle>_emg channels of the results), a Trial or None; "
                          f"got {type(emg).__name__}")
    names = ("{}_emg",) if emg is True else ("{}_emg", "{}")
    out = {}
    for m in muscles:
        for pattern in names:
            if pattern.format(m) in src:
                out[m] = (np.asarray(src.time, dtype=float), np.asarray(src[pattern.format(m)], dtype=float))
                break
    return out


def _on_base(t, t_src, x):
    """``x(t_src)`` linearly interpolated at the ``t`` inside ``t_src``'s span; (mask, values)."""
    inside = (t >= t_src[0] - 1e-12) & (t <= t_src[-1] + 1e-12)
    return inside, np.interp(t[inside], t_src, x)


def _pearson(a, b) -> float:
    a = np.asarray(a, float) - np.mean(a)
    b = np.asarray(b, float) - np.mean(b)
    den = np.sqrt(np.sum(a * a) * np.sum(b * b))
    return float(np.sum(a * b) / den) if len(a) > 1 and den > 0 else float("nan")


def emg_correlations(results, emg=True, *, quantity: str = "activation", muscles=None) -> dict[str, float]:
    """Pearson r between each muscle's ``quantity`` and its EMG (``emg`` as in :func:`emg_source`).

    The EMG is interpolated linearly onto the result's time base, over the
    frames where both exist.  NaN where either signal is constant.
    """
    mus = muscles_in(results, quantity, muscles)
    suf, _ = _suffix(quantity)
    t = np.asarray(results.time, dtype=float)
    out = {}
    for m, (te, x) in emg_source(results, emg, mus).items():
        inside, xe = _on_base(t, te, x)
        out[m] = _pearson(np.asarray(results[m + suf])[inside], xe) if inside.sum() > 1 else float("nan")
    return out


def _colors(n):
    from matplotlib import colormaps
    cmap = colormaps["tab10" if n <= 10 else "tab20"]
    return [cmap(i % cmap.N) for i in range(n)]


def muscle_group(name: str) -> str:
    """A muscle's group: its name without the digits that number its bundles, side kept
    (``glmax1_r`` -> ``glmax_r``, ``vasmed_l`` -> ``vasmed_l``, ``BICLH`` -> ``BICLH``)."""
    import re

    m = re.fullmatch(r"(.*?)(_[lr])?", name)
    base, side = m.group(1), m.group(2) or ""
    return re.sub(r"(?<=[A-Za-z])\d+$", "", base) + side


def _grid(fig, n, ncols):
    ncols = min(ncols, n)
    nrows = -(-n // ncols)
    axes = fig.subplots(nrows, ncols, sharex=True, squeeze=False).ravel()
    for ax in axes[n:]:
        ax.set_visible(False)
    return axes[:n], nrows, ncols


def plot_muscles(results, *, quantity: str = "force", muscles=None, emg=None, normalize_emg: bool = True,
                 max_overlaid: int = 10, title: str | None = None, path=None) -> Figure:
    """Muscle forces or activations over time, optionally against EMG.

    Without EMG (``emg=None``) the muscles share one panel (up to
    ``max_overlaid``, else one small panel each).  With EMG (``emg=True``: the
    ``<muscle>_emg`` channels of ``results``; or a separate EMG Trial with
    ``<muscle>_emg`` or ``<muscle>`` channels; see :func:`emg_source`) each muscle that has
    EMG gets a panel with the EMG on the result's axis -- divided by its peak
    times the peak of the result (``normalize_emg``) so the shapes compare --
    and the correlation r (:func:`emg_correlations`) in the legend.
    """
    suf, unit = _suffix(quantity)
    mus = muscles_in(results, quantity, muscles)
    if not mus:
        raise PinmskError(f"the results have no <muscle>{suf} channels to plot "
                          f"(channels: {', '.join(results.names[:8])})")
    t = np.asarray(results.time, dtype=float)
    src = emg_source(results, emg, mus)
    if emg is not None and emg is not False and not src:
        raise PinmskError(f"no EMG found for the muscles {', '.join(mus)}: expected channels "
                          f"<muscle>_emg{' or <muscle>' if emg is not True else ''} "
                          f"in the {'results' if emg is True else 'EMG trial'}")
    colors = dict(zip(mus, _colors(len(mus))))
    if src:
        r = emg_correlations(results, emg, quantity=quantity, muscles=list(src))
        fig = new_figure(10.0, 0.8 + 2.0 * -(-len(src) // 2))
        axes, _, _ = _grid(fig, len(src), 2)
        for ax, (m, (te, x)) in zip(axes, src.items()):
            y = np.asarray(results[m + suf])
            ax.plot(t, y, color=colors[m], lw=1.4, label=f"{m} {quantity}")
            inside, xe = _on_base(t, te, x)
            peak = np.max(np.abs(xe)) if xe.size else 0.0
            scale = (np.max(np.abs(y)) / peak if peak > 0 and np.max(np.abs(y)) > 0 else 1.0) \
                if normalize_emg else 1.0
            ax.plot(t[inside], xe * scale, color="k", lw=0.9, ls="--",
                    label=f"EMG{' (scaled to peak)' if normalize_emg else ''}, r = {r[m]:.2f}")
            ax.set_title(m, fontsize=9, loc="left")
            ax.set_ylabel(unit, fontsize=8)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7, loc="upper right")
        default = f"muscle {quantity} vs EMG"
    elif len(mus) <= max_overlaid:
        fig = new_figure(9.0, 4.0)
        ax = fig.subplots()
        for m in mus:
            ax.plot(t, results[m + suf], color=colors[m], lw=1.2, label=m)
        ax.set_ylabel(unit)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, ncol=min(len(mus), 4), loc="upper right")
        axes = [ax]
        default = f"muscle {quantity}"
    else:
        # one small panel per muscle group (bundles overlaid), laid out on a fixed grid: the
        # constrained layout of dozens of panels costs more than the solve that made them
        groups: dict[str, list[str]] = {}
        for m in mus:
            groups.setdefault(muscle_group(m), []).append(m)
        nrows = -(-len(groups) // 4)
        height = 0.8 + 1.5 * nrows
        fig = new_figure(12.0, height, layout=None)
        axes, _, _ = _grid(fig, len(groups), 4)
        fig.subplots_adjust(left=0.06, right=0.99, bottom=0.5 / height, top=1 - 0.55 / height,
                            wspace=0.25, hspace=0.45)
        for ax, (g, ms) in zip(axes, groups.items()):
            for m, color in zip(ms, _colors(len(ms))):
                ax.plot(t, results[m + suf], color=color, lw=1.0, label=m)
            ax.set_title(g if len(ms) == 1 else f"{g} ({len(ms)})", fontsize=8, loc="left")
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
        for ax in axes[::4]:
            ax.set_ylabel(unit, fontsize=8)
        default = f"muscle {unit}, by muscle group"
    for ax in axes[-2:]:
        ax.set_xlabel("time (s)")
    fig.suptitle(title or default, fontsize=10)
    if path is not None:
        save_figure(fig, path)
    return fig


def align_results(first, second, *, quantity: str = "force", muscles=None):
    """Two results on one time base: ``(t, muscles, A, B)``.

    ``t`` is the time of ``first`` inside the span of ``second``; ``A`` (N, m)
    are ``first``'s values there and ``B`` ``second``'s, interpolated linearly;
    ``muscles`` are those both results have (or ``muscles``).
    """
    suf, _ = _suffix(quantity)
    if muscles is None:
        other = set(muscles_in(second, quantity))
        mus = [m for m in muscles_in(first, quantity) if m in other]
    else:
        mus = muscles_in(first, quantity, muscles)
        muscles_in(second, quantity, muscles)
    if not mus:
        raise PinmskError(f"the two results have no muscle {quantity} channel in common")
    t1 = np.asarray(first.time, float)
    t2 = np.asarray(second.time, float)
    inside = (t1 >= t2[0] - 1e-12) & (t1 <= t2[-1] + 1e-12)
    if inside.sum() < 2:
        raise PinmskError(f"the results do not overlap in time ({t1[0]:.4g}-{t1[-1]:.4g} s vs "
                          f"{t2[0]:.4g}-{t2[-1]:.4g} s); compare results of the same trial")
    t = t1[inside]
    A = np.stack([np.asarray(first[m + suf])[inside] for m in mus], axis=1)
    B = np.stack([np.interp(t, t2, np.asarray(second[m + suf])) for m in mus], axis=1)
    return t, mus, A, B


def plot_results_comparison(first, second, *, labels: Sequence[str] = ("SO", "FSO"),
                            quantity: str = "force", muscles=None, title: str | None = None,
                            path=None) -> Figure:
    """Two results (e.g. SO vs FSO) on one time base (:func:`align_results`), and the difference.

    Top: ``first`` solid, ``second`` dashed, one colour per muscle.  Bottom:
    ``second - first`` per muscle, with its RMS in the legend.
    """
    la, lb = labels
    suf, unit = _suffix(quantity)
    t, mus, A, B = align_results(first, second, quantity=quantity, muscles=muscles)
    fig = new_figure(9.0, 6.5)
    ax, axd = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 2]})
    for j, (m, c) in enumerate(zip(mus, _colors(len(mus)))):
        ax.plot(t, A[:, j], color=c, lw=1.4, label=m)
        ax.plot(t, B[:, j], color=c, lw=1.0, ls="--")
        rms = float(np.sqrt(np.mean((B[:, j] - A[:, j]) ** 2)))
        axd.plot(t, B[:, j] - A[:, j], color=c, lw=1.0, label=f"{m} (rms {rms:.3g})")
    ax.plot([], [], color="k", lw=1.4, label=la)
    ax.plot([], [], color="k", lw=1.0, ls="--", label=lb)
    ax.set_ylabel(unit)
    ax.set_title(f"muscle {quantity}: {la} (solid) vs {lb} (dashed)", fontsize=9, loc="left")
    ax.legend(fontsize=7, ncol=4, loc="upper right")
    ax.grid(alpha=0.3)
    axd.axhline(0.0, color="k", lw=0.6)
    axd.set_ylabel(f"{lb} - {la}")
    axd.set_xlabel("time (s)")
    axd.set_title("difference", fontsize=9, loc="left")
    axd.legend(fontsize=7, ncol=4, loc="upper right")
    axd.grid(alpha=0.3)
    if title:
        fig.suptitle(title, fontsize=10)
    if path is not None:
        save_figure(fig, path)
    return fig


def find_emg(results, trial=None):
    """Where EMG is for :func:`results_figures`: True if ``results`` has ``<muscle>_emg``
    channels, else ``trial`` if it has them for the result's muscles, else None."""
    if emg_source(results, True):
        return True
    if trial is not None and emg_source(results, trial):
        return trial
    return None


def results_figures(results, *, trial=None, emg=None, coordinates=None) -> dict[str, Figure]:
    """The standard figures of one result, ``{name: Figure}``.

    ``moments`` (from ``results``, else ``trial``, when either has
    ``<coord>_moment`` channels), ``forces``, ``activations``, and
    ``activations_vs_emg`` (or ``forces_vs_emg`` without activations) when
    there is EMG: ``emg`` (True or a Trial, as in :func:`emg_source`), by
    default :func:`find_emg` of ``results`` and ``trial``.
    """
    figs = {}
    for src in (results, trial):
        if src is not None and moment_channels_in(src, coordinates):
            figs["moments"] = plot_moments(src, coordinates)
            break
    for q, name in (("force", "forces"), ("activation", "activations")):
        if muscles_in(results, q):
            figs[name] = plot_muscles(results, quantity=q)
    if emg is None:
        emg = find_emg(results, trial)
    for q, name in (("activation", "activations_vs_emg"), ("force", "forces_vs_emg")):
        if muscles_in(results, q) and emg_source(results, emg, muscles_in(results, q)):
            figs[name] = plot_muscles(results, quantity=q, emg=emg)
            break
    return figs


def save_results_figures(results, out_dir, *, trial=None, emg=None, coordinates=None) -> dict[str, Path]:
    """:func:`results_figures` as ``<out_dir>/<name>.png``; returns ``{name: path}``."""
    return {name: save_figure(fig, Path(out_dir) / f"{name}.png")
            for name, fig in results_figures(results, trial=trial, emg=emg, coordinates=coordinates).items()}


# -- diagnosis -------------------------------------------------------------------------------

def _channels(c, max_channels):
    """The channels worth showing: the largest ratios first, at most ``max_channels``, in order."""
    r = np.sqrt(np.mean(c.residual ** 2, axis=0)) / c.noise.sigma
    keep = sorted(np.argsort(-r)[:max_channels])
    return keep


def channel_unit(c, j: int) -> str:
    """SI unit of compared channel ``j`` of comparison ``c``: the trial's stated unit, else by its
    level -- contact: N (forces) or m (centre of pressure); motion: rad or m; torque/muscle: the
    coordinate's generalized force, N m (rotation) or N (translation)."""
    name = c.channels[j]
    stated = (getattr(c.trial, "units", None) or {}).get(name, "")
    if stated:
        return stated
    if c.mode == "contact":
        return "m" if name[-3:-1] == "_p" else "N"
    coord = c.coordinates[j] if len(c.coordinates) == len(c.channels) else name
    try:
        from ..effects._base import is_prismatic

        prismatic = is_prismatic(c.model, coord)
    except Exception:          # a channel that is no joint of the model (a sensor): rotational
        prismatic = False
    if c.mode == "motion":
        return "m" if prismatic else "rad"
    return "N" if prismatic else "N m"


def plot_comparison(diag, path=None, *, title: str | None = None, max_channels: int = 6) -> Figure:
    """Model vs measurement per channel (noise floor as a band around the model), residual beneath."""
    c = diag.comparison
    keep = _channels(c, max_channels)
    fig = new_figure(9.0, 1.0 + 2.4 * len(keep))
    axes = fig.subplots(2 * len(keep), 1, sharex=True, squeeze=False,
                        gridspec_kw={"height_ratios": [2, 1] * len(keep)})[:, 0]
    t = c.time
    for k, j in enumerate(keep):
        ax, axr = axes[2 * k], axes[2 * k + 1]
        sig = c.noise.sigma[j]
        ax.fill_between(t, c.modelled[:, j] - sig, c.modelled[:, j] + sig, color=_BAND, lw=0,
                        label="model ± noise floor")
        ax.plot(t, c.measured[:, j], color=_MEASURED, lw=0.8, label="measured")
        ax.plot(t, c.modelled[:, j], color=_MODEL, lw=1.2, label="model")
        ratio = np.sqrt(np.mean(c.residual[:, j] ** 2)) / sig
        ax.set_title(f"{c.channels[j]}  (rmse {ratio:.1f}x noise floor)", fontsize=9, loc="left")
        unit = channel_unit(c, j)
        ax.set_ylabel(unit, fontsize=8)
        ax.grid(alpha=0.3)
        axr.axhspan(-sig, sig, color=_BAND, lw=0)
        axr.plot(t, c.residual[:, j], color="k", lw=0.7)
        axr.set_ylabel(f"residual ({unit})", fontsize=8)
        axr.grid(alpha=0.3)
        if k == 0:
            ax.legend(fontsize=7, loc="upper right", ncol=3)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(title or f"{diag.model.name}: {c.mode}-level comparison ({diag.verdict})", fontsize=10)
    if path is not None:
        save_figure(fig, path)
    return fig


def plot_residual_heatmap(diag, path=None, *, clip: float | None = None) -> Figure:
    """Residual divided by the noise floor, time x channel, on a symmetric log colour scale.

    Linear within one noise floor (|z| <= 1), logarithmic beyond, up to the
    data's largest |z| (or ``clip`` if given): residuals of 2 and of 200 floors
    stay distinguishable instead of saturating the scale.
    """
    from matplotlib.colors import SymLogNorm

    c = diag.comparison
    z = c.residual / c.noise.sigma
    finite = np.abs(z[np.isfinite(z)])
    top = float(clip) if clip is not None else max(float(finite.max()) if finite.size else 1.0, 2.0)
    z = np.clip(z, -top, top)
    fig = new_figure(9.0, 1.5 + 0.35 * len(c.channels))
    ax = fig.subplots()
    norm = SymLogNorm(linthresh=1.0, linscale=0.6, vmin=-top, vmax=top, base=10)
    im = ax.imshow(z.T, aspect="auto", cmap="RdBu_r", norm=norm, interpolation="nearest",
                   extent=[c.time[0], c.time[-1], len(c.channels) - 0.5, -0.5])
    ax.set_yticks(range(len(c.channels)))
    ax.set_yticklabels(c.channels, fontsize=7)
    ax.set_xlabel("time (s)")
    ax.set_title("residual / noise floor (symmetric log scale, linear within ±1)", fontsize=9, loc="left")
    decades = [10.0 ** k for k in range(0, int(np.floor(np.log10(top))) + 1)]
    ticks = [-d for d in decades[::-1]] + [0.0] + decades
    bar = fig.colorbar(im, ax=ax, ticks=ticks)
    bar.ax.set_yticklabels([f"{v:g}" for v in ticks], fontsize=7)
    bar.set_label("residual / floor", fontsize=8)
    if path is not None:
        save_figure(fig, path)
    return fig


def plot_ranking(diag, path=None, *, max_effects: int = 12) -> Figure:
    """Candidates by held-out explained fraction (significant ones coloured), best on top."""
    ranking = diag.ranking[:max_effects]
    fig = new_figure(9.0, 1.2 + 0.55 * max(len(ranking), 1))
    ax = fig.subplots()
    if not ranking:
        ax.text(0.5, 0.5, "no applicable effect", ha="center", va="center")
        ax.set_axis_off()
    else:
        vals = [max(s.explained_fraction, -0.1) for s in ranking]
        y = np.arange(len(ranking))
        ax.barh(y, vals, color=[_SIG if s.significant else _NOT for s in ranking])
        ax.set_yticks(y)
        ax.set_yticklabels([f"{s.label}\n{_short(s.describe_params())}" for s in ranking], fontsize=7)
        ax.invert_yaxis()
        ax.set_xlim(-0.1, 1.12)
        ax.axvline(0, color="k", lw=0.6)
        for yi, s in zip(y, ranking):
            ax.text(max(s.explained_fraction, 0) + 0.01, yi, f"{100 * s.explained_fraction:.1f}%",
                    va="center", fontsize=7)
        ax.set_xlabel("explained fraction of the residual (held out); blue = significant")
    ax.set_title(f"missing effects ranked ({diag.verdict})", fontsize=9, loc="left")
    if path is not None:
        save_figure(fig, path)
    return fig


def plot_error_steps(run, path=None) -> Figure:
    """Total (and per-channel) RMSE / noise floor after each added effect."""
    steps = run.steps if hasattr(run, "steps") else [run]
    labels = getattr(run, "step_labels", None) or ["model"] + [f"+ {a.effect.label}" for a in getattr(run, "added", [])]
    fig = new_figure(max(5.0, 1.8 * len(steps) + 3), 3.6)
    ax = fig.subplots()
    x = np.arange(len(steps))
    ax.bar(x, [s.ratio for s in steps], color=_SIG, width=0.55, label="total (RMS of channel ratios)")
    chans = steps[0].comparison.channels
    if len(chans) > 1:
        for ch in chans[:8]:
            ax.plot(x, [s.rmse[ch] / s.noise_floor[ch] for s in steps], marker="o", lw=0.8, label=ch)
    ax.axhline(1.0, color="k", lw=0.8, ls="--", label="noise floor")
    limit = (getattr(steps[-1], "stopping", None) or {}).get("consistent_limit", steps[-1].settings["at_floor"])
    ax.axhline(limit, color="0.5", lw=0.8, ls=":", label="consistent with the noise")
    ax.set_xticks(x)
    ax.set_xticklabels(labels, fontsize=8, rotation=15)
    ax.set_ylabel("rmse / noise floor")
    ax.set_yscale("log")
    ax.legend(fontsize=7)
    ax.set_title("error after each added effect", fontsize=9, loc="left")
    if path is not None:
        save_figure(fig, path)
    return fig


def plot_effect_contribution(diag, path=None, *, score=None) -> Figure:
    """The residual beside the fitted contribution of one effect (default the best)."""
    s = score if score is not None else (diag.best or (diag.ranking[0] if diag.ranking else None))
    c = diag.comparison
    e = c.eq.e
    fig = new_figure(9.0, 1.2 + 2.0 * e.shape[1])
    axes = fig.subplots(e.shape[1], 1, sharex=True, squeeze=False)[:, 0]
    t = c.eq.motion.t[c.eq.rows]
    for j, ax in enumerate(axes):
        ax.plot(t, e[:, j], color="k", lw=0.7, label="equation error")
        if s is not None and s.fit.delta is not None:
            ax.plot(t, -s.fit.delta[:, j], color=_MODEL, lw=1.2, label=f"{s.label} (fitted)")
        name = c.eq.coordinates[j]
        # contact-mode equations are the GRF channels themselves; otherwise generalized forces
        ax.set_title(name if c.mode == "contact" else moment_channel(name), fontsize=9, loc="left")
        ax.set_ylabel(_eq_unit(c, name), fontsize=8)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    axes[-1].set_xlabel("time (s)")
    if path is not None:
        save_figure(fig, path)
    return fig


def _eq_unit(c, name: str) -> str:
    """Unit of the equation error of coordinate (or contact channel) ``name``."""
    if c.mode == "contact":
        return "m" if name[-3:-1] == "_p" else "N"
    try:
        from ..effects._base import is_prismatic

        return "N" if is_prismatic(c.model, name) else "N m"
    except Exception:
        return "N m"


def save_diagnosis_figures(run, out_dir) -> dict[str, Path]:
    """All diagnosis figures of a run (or one Diagnosis) as PNGs in ``out_dir``; name -> path."""
    out_dir = Path(out_dir)
    steps = run.steps if hasattr(run, "steps") else [run]
    first, last = steps[0], steps[-1]
    paths = {
        "comparison_before": save_figure(plot_comparison(first, title="before: " + _title(first)),
                                         out_dir / "comparison_before.png"),
        "residual_heatmap": save_figure(plot_residual_heatmap(first), out_dir / "residual_heatmap.png"),
        "ranking": save_figure(plot_ranking(first), out_dir / "ranking.png"),
        "effect_contribution": save_figure(plot_effect_contribution(first), out_dir / "effect_contribution.png"),
    }
    if len(steps) > 1:
        paths["comparison_after"] = save_figure(plot_comparison(last, title="after: " + _title(last)),
                                                out_dir / "comparison_after.png")
        paths["error_steps"] = save_figure(plot_error_steps(run), out_dir / "error_steps.png")
    return paths


def _short(text: str, n: int = 70) -> str:
    return text if len(text) <= n else text[: n - 3] + "..."


def _title(d) -> str:
    eff = ", ".join(x.label for x in d.model.components) or "no effects"
    return f"{d.model.name} ({eff}), {d.verdict}"


def contact_fit_figures(fit, out_dir) -> list[Path]:
    """A fitted :class:`~pinmsk.contact.ContactFit`: GRF (vertical, horizontal) and COP against the
    measurement, as PNGs in ``out_dir``; the paths written."""
    out_dir = Path(out_dir)
    prob, gr = fit.problem_, fit.reaction_
    t = prob.t
    title = f"{fit.contact}{' relaxed' if fit.relax else ''}"
    fig = new_figure(6, 5.5)
    ax = fig.subplots(2, 1, sharex=True)
    ax[0].plot(t, prob.meas[0], "k", label="measured")
    ax[0].plot(t, gr.normal, "C3", label="model")
    for o, s in zip(fit.outputs_, SITES):
        ax[0].plot(t, o.normal, lw=0.8, ls="--", label=s)
    ax[0].set_ylabel("vertical GRF (N)")
    ax[0].legend(fontsize=7)
    ax[0].set_title(f"{title}: J = {fit.objective_:.4f}")
    ax[1].plot(t, prob.meas[1], "k", label="measured")
    ax[1].plot(t, gr.friction, "C3", label="model")
    ax[1].set_ylabel("horizontal GRF (N)")
    ax[1].set_xlabel("time (s)")
    p1 = out_dir / f"grf_{fit.contact}{'_relaxed' if fit.relax else ''}.png"
    save_figure(fig, p1, dpi=110)
    fig = new_figure(6, 3.2)
    ax = fig.subplots()
    m = prob.cop_mask
    ax.plot(t[m], prob.meas[2][m], "k.", ms=3, label="measured")
    ax.plot(t[m], gr.cop[m, 0], "C3", label="model")
    ax.set_ylabel("COP x (m)")
    ax.set_xlabel("time (s)")
    ax.set_title(title)
    ax.legend(fontsize=7)
    p2 = out_dir / f"cop_{fit.contact}{'_relaxed' if fit.relax else ''}.png"
    save_figure(fig, p2, dpi=110)
    return [p1, p2]
