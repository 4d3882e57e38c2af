"""Figures and the HTML report of a gait validation (:func:`pinmsk.gait_validation.validate_gait`).

The figures follow thesis Figs. 5.7-5.9: :func:`activation_figure` (simulated activations against the
EMG envelopes, Fig. 5.7), :func:`angle_figure` (hip extension, knee flexion, ankle plantarflexion
against the references, Fig. 5.8), :func:`grf_figure` (vertical and fore-aft ground reactions in % body
weight against the measured walk, with the double-hump peaks marked; Fig. 5.9 a, b).  All take the
:class:`~pinmsk.gait_validation.GaitValidation` (read by attribute: this layer does not import it).
:func:`write_gait_report` writes one self-contained HTML file (figures embedded) and, with
``figures_dir``, the PNGs beside it.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .plots import save_figure
from .report import _CSS, _atomic_write, _e, _g, _img_any, _table
from .shown_paths import portable_text

__all__ = ["angle_figure", "grf_figure", "activation_figure", "gait_figures", "write_gait_report",
           "render_gait_report"]

_STYLE = {"winter": dict(color="0.45", lw=1.4, ls="--"), "measured_walk": dict(color="tab:green", lw=1.4)}
_TITLES = {"hip": "hip (+ extension)", "knee": "knee (+ flexion)", "ankle": "ankle (+ plantarflexion)"}
_MUSCLES = ("glutei", "iliopsoas", "hamstrings", "rectus_femoris", "vasti", "gastrocnemius", "soleus",
            "tibialis_anterior")


def _plt():
    import matplotlib.pyplot as plt
    return plt


def _panels(v, n: int, size):
    """(simulated cycle, % stride, figure, axes) of a row of ``n`` panels sharing the stride axis."""
    fig, axes = _plt().subplots(1, n, figsize=size, sharex=True)
    return v.simulation, v.simulation.percent, fig, axes


def angle_figure(v):
    """Fig. 5.8: the simulated right (solid) and left (thin) joint angles against each reference."""
    sim, p, fig, axes = _panels(v, 3, (12, 3.6))
    for ax, j in zip(axes, ("hip", "knee", "ankle")):
        for key, ref in v.references.items():
            if f"{j}_r" in ref.angles:
                ax.plot(p, ref.angles[f"{j}_r"], label=ref.label, **_STYLE.get(key, {}))
        ax.plot(p, sim.angles[f"{j}_r"], color="tab:blue", lw=2, label=f"{sim.label} (right)")
        ax.plot(p, sim.angles[f"{j}_l"], color="tab:blue", lw=0.8, alpha=0.6, label=f"{sim.label} (left)")
        ax.set_title(_TITLES[j], fontsize=10)
        ax.set_xlabel("% stride (from heel strike)")
        ax.set_ylabel("deg")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    return fig


def grf_figure(v):
    """Fig. 5.9 a, b: vertical and fore-aft GRF (% body weight) over each side's stride; peaks marked."""
    sim, p, fig, axes = _panels(v, 2, (11, 3.8))
    meas = v.references.get("measured_walk")
    for ax, a, name in zip(axes, "yx", ("vertical", "fore-aft")):
        if meas is not None:
            for s, ls in (("r", "-"), ("l", ":")):
                ax.plot(p, meas.grf[f"{s}_v{a}"], color="tab:green", ls=ls, lw=1.3,
                        label=f"{meas.label} ({'right' if s == 'r' else 'left'})")
        for s, lw in (("r", 2.0), ("l", 0.9)):
            if f"{s}_v{a}" in sim.grf:
                ax.plot(p, sim.grf[f"{s}_v{a}"], color="tab:blue", lw=lw,
                        label=f"{sim.label} ({'right' if s == 'r' else 'left'})")
        ax.set_title(f"{name} GRF", fontsize=10)
        ax.set_xlabel("% stride (from that side's heel strike)")
        ax.set_ylabel("% body weight")
    for who, color in (("simulation", "tab:blue"), ("measured_walk", "tab:green")):
        h = v.numbers.get("grf", {}).get(who, {}).get("r")
        if h:
            axes[0].plot([h["first_peak_at_pct"], h["valley_at_pct"], h["second_peak_at_pct"]],
                         [h["first_peak_bw_pct"], h["valley_bw_pct"], h["second_peak_bw_pct"]], "o", color=color,
                         ms=5)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    return fig


def activation_figure(v):
    """Fig. 5.7: simulated activations (right solid, left thin) and the EMG envelope scaled to the
    right activation's peak (dashed; the envelopes are scaled to max 1, their absolute level is unknown)."""
    plt = _plt()
    sim = v.simulation
    p = sim.percent
    meas = v.references.get("measured_walk")
    groups = [g for g in _MUSCLES if f"{g}_r" in sim.muscles]
    if not groups:
        return None
    n = len(groups)
    cols = 4 if n > 4 else n
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.6 * rows), sharex=True, squeeze=False)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    for ax, g in zip(axes.flat, groups):
        a = sim.muscles[f"{g}_r"]
        ax.plot(p, a, color="tab:red", lw=2, label="activation (right)")
        if f"{g}_l" in sim.muscles:
            ax.plot(p, sim.muscles[f"{g}_l"], color="tab:red", lw=0.8, alpha=0.6, label="activation (left)")
        if meas is not None and f"{g}_r" in meas.muscles:
            e = meas.muscles[f"{g}_r"]
            scale = np.nanmax(a) / np.nanmax(e) if np.nanmax(e) > 0 else 1.0
            ax.plot(p, e * scale, color="k", ls="--", lw=1.2, label="EMG (scaled)")
        ax.set_title(g, fontsize=9)
        ax.set_ylim(bottom=0)
    axes.flat[0].legend(fontsize=6)
    for ax in axes[-1]:
        ax.set_xlabel("% stride")
    fig.tight_layout()
    return fig


def gait_figures(v) -> dict:
    """``{name: Figure}`` of the figures that have data (angles, grf, activations)."""
    out = {"angles": angle_figure(v)}
    if v.simulation.grf:
        out["grf"] = grf_figure(v)
    f = activation_figure(v)
    if f is not None:
        out["activations"] = f
    return out


_CAPTIONS = {"angles": "Joint angles against Winter's Table A.1 and the measured walk (cf. thesis Fig. 5.8)",
             "grf": "Ground reaction forces in % body weight, peaks and valley marked (cf. thesis Fig. 5.9 a, b)",
             "activations": "Activations against the EMG envelopes (cf. thesis Fig. 5.7)"}


def render_gait_report(v, *, title: str | None = None, figures: dict | None = None) -> str:
    """The validation report as an HTML string."""
    n = v.numbers
    title = title or f"pinmsk gait validation: {n['label']}"
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{_e(title)}</title>"
             f"<style>{_CSS}</style></head><body>", f"<h1>{_e(title)}</h1>"]
    parts.append("<h2>Stride</h2>")
    parts.append(_table(["item", "simulation"] + [r["label"] for r in n["references"].values()], [
        ["stride time (s)", _g(n["stride_time_s"])] + [_g(r["stride_time_s"]) for r in n["references"].values()],
        ["cadence (steps/min)", _g(n["spatiotemporal"]["cadence_steps_per_min"]["value"])]
        + [_g(r["cadence_steps_per_min"]) for r in n["references"].values()],
        ["speed (m/s)", _g(n["speed_m_per_s"])] + [_g(r["speed_m_per_s"]) for r in n["references"].values()],
        ["stride length (m)", _g(n["spatiotemporal"]["stride_length_m"]["value"])]
        + [_g(r["stride_length_m"]) for r in n["references"].values()],
        ["body weight (N)", _g(n["body_weight_n"])] + [_g(r["body_weight_n"]) for r in n["references"].values()],
    ]))
    parts.append("<h2>Against published values</h2>")
    parts.append(_table(["quantity", "simulation", "published range", "within", "source"], [
        [k, _g(b["value"]), f"{b['published_range'][0]:g}-{b['published_range'][1]:g}",
         "-" if b["within"] is None else ("yes" if b["within"] else "no"), b["source"]]
        for k, b in n["spatiotemporal"].items()], left={0, 4}))
    parts.append("<h2>Joint angles</h2>")
    rows = [[ref, j, _g(x["rms_deg"]), _g(x["correlation"])]
            for ref, d in n["joint_angles"].items() for j, x in d.items()]
    parts.append(_table(["reference", "joint", "RMS (deg)", "correlation"], rows, left=2))
    g = n.get("grf", {})
    if g.get("simulation"):
        parts.append("<h2>Vertical GRF double hump</h2>")
        keys = ["first_peak_bw_pct", "first_peak_at_pct", "valley_bw_pct", "valley_at_pct", "second_peak_bw_pct",
                "second_peak_at_pct", "stance_pct"]
        heads = ["1st peak (% BW)", "at (% stride)", "valley (% BW)", "at", "2nd peak (% BW)", "at", "stance (%)"]
        rows = [[who, s] + [_g(h[k]) for k in keys]
                for who in ("simulation", "measured_walk") for s, h in g.get(who, {}).items()]
        parts.append(_table(["source", "side"] + heads, rows, left=2))
        if g.get("rms_bw_pct"):
            parts.append("<p>GRF RMS against the measured walk (% body weight):</p>")
            parts.append(_table(["channel", "RMS (% BW)"], [[k, _g(x)] for k, x in g["rms_bw_pct"].items()]))
    if n.get("emg"):
        parts.append("<h2>Activations against EMG</h2>")
        parts.append(_table(["muscle group", "r (right)", "r (left vs the same EMG)"],
                            [[m, _g(x.get("correlation_r")), _g(x.get("correlation_l"))]
                             for m, x in n["emg"].items()]))
    parts.append("<h2>Figures</h2>")
    for name, fig in (figures if figures is not None else gait_figures(v)).items():
        parts.append(_img_any(fig, _CAPTIONS.get(name, name)))
    parts.append("<h2>Notes</h2><ul>" + "".join(f"<li>{_e(x)}</li>" for x in n["notes"]) + "".join(
        f"<li>{_e(r['label'])}: {_e(t)}</li>" for r in n["references"].values() for t in r["notes"]) + "</ul>")
    parts.append('<p class="small">Generated by pinmsk. Figures are embedded PNGs; this file needs no network.</p>')
    parts.append("</body></html>")
    return portable_text("\n".join(parts))


def write_gait_report(v, path, *, figures_dir=None, title: str | None = None) -> Path:
    """Write the HTML report to ``path`` (and ``gait_<name>.png`` into ``figures_dir`` if given)."""
    plt = _plt()
    figs = gait_figures(v)
    try:
        if figures_dir is not None:
            for name, fig in figs.items():
                save_figure(fig, Path(figures_dir) / f"gait_{name}.png", dpi=110)
        return _atomic_write(path, render_gait_report(v, title=title, figures=figs))
    finally:
        for fig in figs.values():
            plt.close(fig)
