"""Figures (matplotlib, headless): trials and the diagnosis.

Every function builds a :class:`matplotlib.figure.Figure` on the Agg canvas
directly -- no pyplot, no global backend switch, no display -- and either
returns it or saves it as PNG.  Diagnosis figures:

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

__all__ = ["new_figure", "figure_png", "save_figure", "save_channels", "plot_comparison",
           "plot_residual_heatmap", "plot_ranking", "plot_error_steps", "plot_effect_contribution",
           "save_diagnosis_figures"]

_MEASURED = "0.35"
_MODEL = "#c0392b"
_BAND = "#f5b7b1"
_SIG = "#1f77b4"
_NOT = "0.7"


def new_figure(width: float = 8.0, height: float = 4.0) -> Figure:
    """A Figure on its own Agg canvas."""
    fig = Figure(figsize=(width, height), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def figure_png(fig: Figure) -> bytes:
    """PNG bytes of a figure."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def save_figure(fig: Figure, path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, format="png")
    return path


# -- trials ----------------------------------------------------------------------------------

def save_channels(trial, channels: Sequence[str], out_dir, *, stem: str = "channels",
                  ylabel: str = "", per_figure: int = 8) -> list[Path]:
    """Plot ``channels`` of a Trial against time; one PNG per ``per_figure`` channels."""
    chans = [c for c in channels if c in trial]
    out = []
    t = np.asarray(trial.time)
    for k in range(0, max(len(chans), 1), per_figure):
        group = chans[k:k + per_figure]
        if not group:
            break
        fig = new_figure(8.0, 1.6 + 1.4 * len(group))
        axes = fig.subplots(len(group), 1, sharex=True, squeeze=False)[:, 0]
        for ax, c in zip(axes, group):
            ax.plot(t, trial[c], lw=1.0, color=_SIG)
            ax.set_ylabel(ylabel or c, fontsize=8)
            ax.set_title(c, fontsize=9, loc="left")
            ax.grid(alpha=0.3)
        axes[-1].set_xlabel("time (s)")
        name = f"{stem}.png" if len(chans) <= per_figure else f"{stem}_{k // per_figure + 1}.png"
        out.append(save_figure(fig, Path(out_dir) / name))
    return out


# -- diagnosis -------------------------------------------------------------------------------

def _channels(c, max_channels):
    """The channels worth showing: the largest ratios first, at most ``max_channels``, in order."""
    r = np.sqrt(np.mean(c.residual ** 2, axis=0)) / c.noise.sigma
    keep = sorted(np.argsort(-r)[:max_channels])
    return keep


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
        ax.grid(alpha=0.3)
        axr.axhspan(-sig, sig, color=_BAND, lw=0)
        axr.plot(t, c.residual[:, j], color="k", lw=0.7)
        axr.set_ylabel("residual", fontsize=8)
        axr.grid(alpha=0.3)
        if k == 0:
            ax.legend(fontsize=7, loc="upper right", ncol=3)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(title or f"{diag.model.name}: {c.mode}-level comparison ({diag.verdict})", fontsize=10)
    if path is not None:
        save_figure(fig, path)
    return fig


def plot_residual_heatmap(diag, path=None, *, clip: float = 5.0) -> Figure:
    """Residual divided by the noise floor, time x channel (clipped at ``clip``)."""
    c = diag.comparison
    z = np.clip(c.residual / c.noise.sigma, -clip, clip)
    fig = new_figure(9.0, 1.5 + 0.35 * len(c.channels))
    ax = fig.subplots()
    im = ax.imshow(z.T, aspect="auto", cmap="RdBu_r", vmin=-clip, vmax=clip, interpolation="nearest",
                   extent=[c.time[0], c.time[-1], len(c.channels) - 0.5, -0.5])
    ax.set_yticks(range(len(c.channels)))
    ax.set_yticklabels(c.channels, fontsize=7)
    ax.set_xlabel("time (s)")
    ax.set_title("residual / noise floor", fontsize=9, loc="left")
    fig.colorbar(im, ax=ax, label="residual / floor")
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
    labels = ["model"] + [f"+ {a.effect.label}" for a in getattr(run, "added", [])]
    fig = new_figure(max(5.0, 1.8 * len(steps) + 3), 3.6)
    ax = fig.subplots()
    x = np.arange(len(steps))
    ax.bar(x, [s.ratio for s in steps], color=_SIG, width=0.55, label="total (RMS of channel ratios)")
    chans = steps[0].comparison.channels
    if len(chans) > 1:
        for ch in chans[:8]:
            ax.plot(x, [s.rmse[ch] / s.noise_floor[ch] for s in steps], marker="o", lw=0.8, label=ch)
    ax.axhline(1.0, color="k", lw=0.8, ls="--", label="noise floor")
    ax.axhline(steps[-1].settings["at_floor"], color="0.5", lw=0.8, ls=":", label="at_noise_floor limit")
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
        ax.set_title(f"{c.eq.coordinates[j]}_moment", fontsize=9, loc="left")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    axes[-1].set_xlabel("time (s)")
    if path is not None:
        save_figure(fig, path)
    return fig


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
