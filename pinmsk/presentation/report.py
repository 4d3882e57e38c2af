"""One self-contained HTML report of a diagnosis (figures embedded, no network).

:func:`write_report` takes a :class:`~pinmsk.diagnose.DiagnosisRun` (or one
:class:`~pinmsk.diagnose.Diagnosis`) and writes a single HTML file: the
model, the data, how the noise floor was estimated, the error per channel at
each step, the floating-base residuals at each step (mean, RMS and peak in N,
N m and percent of body weight, against OpenSim's limits), the worst windows, the ranked effects with parameters and
uncertainties, the effects added, the verdict, and the figures as
base64-embedded PNGs.  No scripts, stylesheets or fonts are fetched.
"""
from __future__ import annotations

import base64
import html
from pathlib import Path

import numpy as np

from ..io.output_files import atomic_write
from ..signals.sampling import median_step
from ..solvers.static import STATUS
from . import plots
from .plots import figure_png, muscle_group, muscles_in
from .shown_paths import portable_text, shown_path

__all__ = ["write_report", "render_report", "write_results_report", "render_results_report"]

_CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}
h1{font-size:1.5em}h2{font-size:1.15em;border-bottom:1px solid #ddd;padding-bottom:.2em;margin-top:1.6em}
table{border-collapse:collapse;margin:.5em 0;font-size:.9em}td,th{border:1px solid #ccc;padding:.25em .6em;text-align:right}
th{background:#f3f3f3}td.l,th.l{text-align:left}pre{background:#f7f7f7;padding:.8em;overflow-x:auto;font-size:.8em;white-space:pre-wrap;overflow-wrap:anywhere}
summary{cursor:pointer;color:#245;margin:.4em 0}
.v-missing_effect{color:#b03a2e;font-weight:bold}.v-at_noise_floor{color:#1e8449;font-weight:bold}
img{max-width:100%;border:1px solid #eee;margin:.4em 0}.small{color:#666;font-size:.85em}
"""


def _e(x) -> str:
    return html.escape(str(x))


def _img(fig) -> str:
    data = base64.b64encode(figure_png(fig)).decode("ascii")
    return f'<img alt="figure" src="data:image/png;base64,{data}">'


def _table(header, rows, left=1) -> str:
    """An HTML table; columns ``< left`` (or in the set ``left``) are left-aligned, others right."""
    is_left = (lambda i: i in left) if isinstance(left, (set, frozenset)) else (lambda i: i < left)
    out = ["<table><tr>" + "".join(f'<th class="{"l" if is_left(i) else ""}">{_e(h)}</th>'
                                   for i, h in enumerate(header)) + "</tr>"]
    for r in rows:
        out.append("<tr>" + "".join(f'<td class="{"l" if is_left(i) else ""}">{_e(v)}</td>'
                                    for i, v in enumerate(r)) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def _g(x) -> str:
    return "–" if x is None or not np.isfinite(x) else f"{x:.4g}"


def render_report(run, *, title: str | None = None) -> str:
    """The report as an HTML string."""
    steps = run.steps if hasattr(run, "steps") else [run]
    added = list(getattr(run, "added", []))
    gone = {r["removed"] for r in getattr(run, "removed", [])}
    labels = getattr(run, "step_labels", None) or ["model"] + [f"+ {a.effect.label}" for a in added]
    first, last = steps[0], steps[-1]
    c = first.comparison
    trial = c.trial
    src = shown_path(trial.meta.get("source") or "trial")
    title = title or f"pinmsk diagnosis: {first.model.name} vs {Path(str(src)).name}"
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{_e(title)}</title>"
             f"<style>{_CSS}</style></head><body>", f"<h1>{_e(title)}</h1>"]
    parts.append(f'<p>Verdict: <span class="v-{last.verdict}">{_e(last.verdict)}</span> — '
                 f"{_e(last.verdict_line().split(' -- ', 1)[-1])}</p>")

    parts.append("<h2>Model</h2><pre>" + _e(first.model.describe()) + "</pre>")
    t = np.asarray(trial.time)
    dt = median_step(t)
    parts.append("<h2>Data</h2>")
    parts.append(_table(["item", "value"], [
        ("source", src), ("frames", trial.n_frames), ("duration (s)", f"{t[-1] - t[0]:.3f}"),
        ("rate (Hz)", f"{1 / dt:.4g}"), ("channels", ", ".join(trial.names)),
        ("comparison", f"{c.mode} level on {', '.join(c.channels)}"),
        ("kinematics", f"low-pass {c.cutoff} Hz, quintic-spline derivatives; analysed "
                       f"{c.time[0]:.3f}-{c.time[-1]:.3f} s"),
        ("noise floor", c.noise.method),
    ], left=2))

    parts.append("<h2>Error per channel</h2>")
    header = ["channel", "noise floor"] + labels
    rows = []
    for ch in list(c.channels) + ["total"]:
        rows.append([ch, _g(last.noise_floor[ch])] + [_g(s.rmse[ch]) for s in steps])
    rows.append(["rmse / floor (RMS over channels)", ""] + [f"{s.ratio:.2f}" for s in steps])
    parts.append(_table(header, rows))
    parts += _residual_section(run)
    if added:
        parts.append("<h2>Effects added</h2>")
        rows = []
        # their values in the final model: each add refits the earlier effects jointly
        final = run.final_effects() if hasattr(run, "final_effects") and last.comparison.mode != "contact" else None
        kept = [a for a in added if a.effect.label not in gone]      # a removed effect is not in the final model
        for a, comp in zip(kept, final or [None] * len(kept)):
            for k, v in a.params.items():
                se = a.stderr.get(k)
                if comp is not None:
                    v, se = comp.params[k].value, comp.params[k].stderr
                rows.append([a.effect.label, k, _g(v), _g(se), a.effect.params[k].unit])
        parts.append(_table(["effect", "parameter", "value", "std. error", "unit"], rows, left=2))

    for k, d in enumerate(steps):
        label = ("model as given" if k == 0 else f"after adding {labels[k][2:]}" if labels[k].startswith("+")
                 else f"after removing {labels[k][2:]}")
        parts.append(f"<h2>Diagnosis: {_e(label)}</h2>")
        parts.append(f'<p>Verdict: <span class="v-{d.verdict}">{_e(d.verdict)}</span>; error '
                     f"{d.ratio:.2f}× the noise floor.</p>")
        if d.worst_windows:
            parts.append("<p>Worst windows:</p>")
            parts.append(_table(["channel", "start (s)", "end (s)", "rmse", "× floor"],
                                [[w["channel"], f"{w['start']:.2f}", f"{w['end']:.2f}", _g(w["rmse"]),
                                  f"{w['rmse'] / d.noise_floor[w['channel']]:.1f}"] for w in d.worst_windows]))
        if d.correlations and d.verdict == "missing_effect":
            parts.append("<p>States the residual follows (correlation):</p>")
            parts.append(_table(["channel", "states"], [[ch, ", ".join(f"{s} ({r:+.2f})" for s, r in cors[:3])]
                                                        for ch, cors in d.correlations.items()], left=2))
        if d.ranking:
            how = ("contact models scored by BIC with the noise floor as sigma; explained = 1 - chi2 after / before"
                   if d.comparison.mode == "contact" else
                   "blocked cross-validation; explained = held-out share; \"yes (mean)\": significant by the "
                   "held-out test of the residual's systematic mean")
            parts.append(f"<p>Ranked effects ({how}):</p>")
            parts.append(_table(["#", "effect", "explained", "rmse after", "significant", "parameters"],
                                [[i + 1, s.label, f"{100 * s.explained_fraction:.1f}%", _g(s.rmse_after["total"]),
                                  ("yes (mean)" if s.test.get("passes_by") == "mean" else "yes") if s.significant else "no",
                                  s.describe_params()]
                                 for i, s in enumerate(d.ranking)], left={1, 5}))
        parts.append(_img(plots.plot_comparison(d)))
        if k == 0:
            parts.append(_img(plots.plot_residual_heatmap(d)))
            parts.append(_img(plots.plot_ranking(d)))
            if d.ranking:
                parts.append(_img(plots.plot_effect_contribution(d)))
    if len(steps) > 1:
        parts.append("<h2>Error after each step</h2>" + _img(plots.plot_error_steps(run)))
    parts.append("<h2>Summary text</h2><pre>" + _e(run.summary_text()) + "</pre>")
    parts.append('<p class="small">Generated by pinmsk. Figures are embedded PNGs; this file needs no network.</p>')
    parts.append("</body></html>")
    return portable_text("\n".join(parts))


def _residual_section(run) -> list[str]:
    """The floating-base residual report (:meth:`~pinmsk.diagnose.DiagnosisRun.residual_report`): per
    coordinate, the mean, RMS and peak at each step, in N (N m) and percent, with OpenSim's verdict."""
    rep = run.residual_report() if hasattr(run, "residual_report") else None
    if not rep:
        return []
    out = ["<h2>Floating-base residuals</h2>",
           f"<p>What inverse dynamics leaves at the floating base, over the analysed frames, before and after "
           f"each added effect. Forces in N and % of body weight ({rep['body_weight_N']:.4g} N: "
           f"{_e(rep['body_weight_from'])}); moments in N m and % of body weight × height "
           f"({rep['height_m']:.3g} m: {_e(rep['height_from'])}). Verdict by OpenSim's checklist for RRA "
           "results: forces peak ≤ 10–25 N and RMS ≤ 5–15 N, moments peak ≤ 75 N m and RMS ≤ 50 N m "
           "(ok within the first limits, marginal within the second).</p>"]
    coords = list(rep["steps"][0]["coordinates"])
    rows = []
    for c in coords:
        for st in rep["steps"]:
            r = st["coordinates"].get(c)
            if r is None:
                continue
            u = "N m" if r["unit"] == "N*m" else "N"
            rows.append([c, "model as given" if st["step"] == 0 else st["model"], u,
                         _g(r["mean"]), _pct(r["mean_percent"]), _g(r["rms"]), _pct(r["rms_percent"]),
                         _g(r["peak"]), _pct(r["peak_percent"]), r["status"]])
    out.append(_table(["coordinate", "model", "unit", "mean", "mean %", "RMS", "RMS %", "peak", "peak %",
                       "verdict"], rows, left={0, 1, 2, 9}))
    return out


def _pct(x) -> str:
    return "–" if x is None or not np.isfinite(x) else f"{x:.2f} %"


def write_report(run, path, *, title: str | None = None) -> Path:
    """Write the HTML report of a diagnosis run (or one Diagnosis) to ``path``."""
    return _atomic_write(Path(path), render_report(run, title=title))


def write_failure_report(path, model, trial, error, *, title: str | None = None) -> Path:
    """Write the report page of a diagnosis that could not run: why, the model and the trial's channels."""
    return _atomic_write(Path(path), _failure_page(model, trial, error, title))


def save_diagnosis(run, *, json_path=None, report_path=None, plot_dir=None) -> list[Path]:
    """Write what was asked of a diagnosis run: JSON summary, HTML report, PNG figures; the paths written."""
    written = []
    if plot_dir is not None:
        plots.save_diagnosis_figures(run, plot_dir)
    if json_path is not None:
        written.append(run.write_json(json_path))
    if report_path is not None:
        written.append(write_report(run, report_path))
    return written


def _failure_page(model, trial, exc, title) -> str:
    title = title or f"pinmsk diagnosis: {model.name}"
    fig = plots.new_figure(9.0, 1.5 + 1.2 * min(len(trial.names), 8))
    names = list(trial.names)[:8]
    axes = fig.subplots(max(len(names), 1), 1, sharex=True, squeeze=False)[:, 0]
    for ax, c in zip(axes, names):
        ax.plot(trial.time, trial[c], lw=0.8)
        ax.set_title(c, fontsize=8, loc="left")
    axes[-1].set_xlabel("time (s)")
    return portable_text(
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{_e(title)}</title>"
        f"<style>{_CSS}</style></head><body><h1>{_e(title)}</h1>"
        f'<p class="v-missing_effect">The diagnosis could not run: {_e(exc)}</p>'
        "<h2>Model</h2><pre>" + _e(model.describe()) + "</pre><h2>Data</h2>"
        + _table(["item", "value"], [("frames", trial.n_frames), ("channels", ", ".join(trial.names))])
        + _img(fig) + "</body></html>")


# -- results (SO, FSO, any Trial of muscle forces) --------------------------------------------

def _atomic_write(path, text: str) -> Path:
    """Write ``text`` to ``path`` (parent folders created) atomically: :func:`pinmsk.io.output_files.atomic_write`."""
    return atomic_write(path, lambda fh: fh.write(text), parents=True)


def _img_any(fig, caption: str) -> str:
    """A Figure, PNG bytes or a PNG file path as an embedded <figure>."""
    if isinstance(fig, (bytes, bytearray)):
        data = bytes(fig)
    elif isinstance(fig, (str, Path)):
        data = Path(fig).read_bytes()
    else:
        data = figure_png(fig)
    b64 = base64.b64encode(data).decode("ascii")
    return (f'<figure><img alt="{_e(caption)}" src="data:image/png;base64,{b64}">'
            f"<figcaption class='small'>{_e(caption)}</figcaption></figure>")


def channel_stats(trial) -> list[list]:
    """Rows ``[channel, unit, min, max, mean, RMS]`` of every channel of a Trial."""
    v = np.asarray(trial.values, dtype=float)
    rows = []
    for j, c in enumerate(trial.names):
        x = v[:, j]
        rows.append([c, trial.units.get(c, ""), float(np.min(x)), float(np.max(x)), float(np.mean(x)),
                     float(np.sqrt(np.mean(x * x)))])
    return rows


def muscle_stats(results) -> list[list]:
    """Rows ``[muscle, peak force (N), time of peak (s), mean force (N), mean activation, peak activation]``
    (means over frames; NaN where the channel is missing)."""
    mus = list(dict.fromkeys(muscles_in(results, "force") + muscles_in(results, "activation")))
    t = np.asarray(results.time)
    nan = float("nan")
    rows = []
    for m in mus:
        f = np.asarray(results[f"{m}_force"]) if f"{m}_force" in results else None
        a = np.asarray(results[f"{m}_activation"]) if f"{m}_activation" in results else None
        rows.append([m,
                     float(np.max(f)) if f is not None else nan,
                     float(t[np.argmax(f)]) if f is not None else nan,
                     float(np.mean(f)) if f is not None else nan,
                     float(np.mean(a)) if a is not None else nan,
                     float(np.max(a)) if a is not None else nan])
    return rows


def status_counts(results) -> list[list]:
    """Rows ``[code, frames, meaning]`` of the ``status`` channel (empty without one)."""
    if "status" not in results:
        return []
    codes, counts = np.unique(np.asarray(results["status"]), return_counts=True)
    meaning = {}
    if results.meta.get("analysis") == "static_optimization":
        meaning = STATUS
    return [[f"{c:g}", int(n), meaning.get(int(c), "") if float(c).is_integer() else ""]
            for c, n in zip(codes, counts)]


#: Tables and lists longer than this are collapsed (<details>) below the summary.
SHOWN_ROWS = 20
#: Peak activation below which a muscle counts as silent: its correlation with EMG says nothing.
SILENT_PEAK = 0.02
#: Frames listed as the worst in the summary.
WORST_FRAMES = 5


def _collapsed(summary: str, body: str, collapse: bool) -> str:
    """``body`` (HTML) inside a closed <details> titled ``summary`` when ``collapse``, else as is."""
    return f"<details><summary>{_e(summary)}</summary>{body}</details>" if collapse else body


def _unmet_channels(results) -> list[str]:
    """The channels of what the muscles did not supply: reserves, residuals, other actuators' forces."""
    units = dict(results.units)
    muscles = set(muscles_in(results, "force"))
    return [n for n in results.names
            if n.endswith(("_reserve", "_residual"))
            or (n.endswith("_force") and n[:-len("_force")] not in muscles and units.get(n))]


def _summary_section(results) -> list[str]:
    """The answer first: frames not solved, the worst frames, the reserves and residuals, the
    activations by muscle group."""
    out = ["<h2>Summary</h2>"]
    t = np.asarray(results.time, dtype=float)
    rows = [("frames", results.n_frames), ("time (s)", f"{t[0]:.4g} to {t[-1]:.4g}")]
    if "status" in results:
        st = np.asarray(results["status"], dtype=float)
        rows.append(("frames not solved to optimality", f"{int(np.sum(st != 0))} of {st.size}"))
    out.append(_table(["item", "value"], rows, left=2))
    unmet = _unmet_channels(results)
    units = dict(results.units)
    if unmet:
        X = np.abs(np.column_stack([np.asarray(results[n], dtype=float) for n in unmet]))
        peak_i = np.nanargmax(np.where(np.isfinite(X), X, -np.inf), axis=0)
        table = sorted(([n, units.get(n, ""), float(X[i, j]), float(t[i]), float(np.sqrt(np.nanmean(X[:, j] ** 2)))]
                        for j, (n, i) in enumerate(zip(unmet, peak_i))), key=lambda r: -r[2])
        out.append("<p>Reserves and residuals (what the muscles did not supply), the largest first:</p>")
        body = [[r[0], r[1], _g(r[2]), _g(r[3]), _g(r[4])] for r in table]
        head = ["channel", "unit", "peak |value|", "time of peak (s)", "RMS"]
        out.append(_table(head, body[:10], left=2))
        if len(body) > 10:
            out.append(_collapsed(f"{len(body) - 10} more", _table(head, body[10:], left=2), True))
        # the worst frames: the largest reserve or residual in units of its own RMS over the trial
        rms = np.array([r[4] for r in sorted(table, key=lambda r: unmet.index(r[0]))])
        score = np.nanmax(X / np.where(rms > 0, rms, 1.0), axis=1)
        worst = np.argsort(-np.nan_to_num(score, nan=-np.inf))[:WORST_FRAMES]
        out.append("<p>Worst frames (largest reserve or residual):</p>")
        wrows = []
        for i in sorted(worst, key=lambda i: -score[i]):
            j = int(np.nanargmax(X[i]))
            wrows.append([int(i), _g(float(t[i])), unmet[j], f"{_g(float(X[i, j]))} {units.get(unmet[j], '')}".strip()])
        out.append(_table(["frame", "time (s)", "largest", "|value|"], wrows, left={2}))
    acts = muscles_in(results, "activation")
    if acts:
        groups: dict[str, list[str]] = {}
        for m in acts:
            groups.setdefault(muscle_group(m), []).append(m)
        A = {g: np.column_stack([np.asarray(results[f"{m}_activation"], dtype=float) for m in ms])
             for g, ms in groups.items()}
        grows = sorted(([g, len(groups[g]), float(np.nanmax(a)), float(t[int(np.nanargmax(np.nanmax(a, axis=1)))]),
                         float(np.nanmean(a))] for g, a in A.items()), key=lambda r: -r[2])
        out.append(f"<p>Activations by muscle group ({len(acts)} muscles in {len(groups)} groups), "
                   "the most active first:</p>")
        head = ["group", "muscles", "peak activation", "time of peak (s)", "mean activation"]
        body = [[r[0], r[1], _g(r[2]), _g(r[3]), _g(r[4])] for r in grows]
        out.append(_table(head, body[:SHOWN_ROWS]))
        if len(body) > SHOWN_ROWS:
            out.append(_collapsed(f"{len(body) - SHOWN_ROWS} more groups", _table(head, body[SHOWN_ROWS:]), True))
    return out


def render_results_report(*, model, trial, results, title: str | None = None, text: str | None = None,
                          tables=None, extra_figures=None, emg=None, figures=None) -> str:
    """The results report as an HTML string (see :func:`write_results_report`)."""
    title = title or f"pinmsk results: {model.name}"
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{_e(title)}</title>"
             f"<style>{_CSS}</style></head><body>", f"<h1>{_e(title)}</h1>"]
    parts += _summary_section(results)
    parts.append("<h2>Model</h2><pre>" + _e(model.describe()) + "</pre>")
    parts.append("<h2>Data</h2>")
    for label, tr in (("trial", trial), ("results", results)):
        if tr is None:
            continue
        t = np.asarray(tr.time)
        rate = (tr.n_frames - 1) / (t[-1] - t[0]) if tr.n_frames > 1 and t[-1] > t[0] else float("nan")
        parts.append(f"<p><b>{label}</b></p>")
        parts.append(_table(["item", "value"], [
            ("source", shown_path(tr.meta.get("source") or tr.meta.get("analysis") or "-")),
            ("frames", tr.n_frames), ("duration (s)", f"{tr.duration:.4g}"),
            ("time (s)", f"{t[0]:.4g} to {t[-1]:.4g}"), ("rate (Hz)", _g(rate)),
        ], left=2))
        parts.append(_collapsed(f"{tr.n_channels} channels", _e(", ".join(tr.names)), tr.n_channels > SHOWN_ROWS))
    if emg is None:
        emg = plots.find_emg(results, trial)
    figs = (plots.results_figures(results, trial=trial, emg=emg, coordinates=model.coordinates)
            if figures is None else dict(figures))
    captions = {"moments": "joint moments", "forces": "muscle forces", "activations": "muscle activations",
                "activations_vs_emg": "activations vs EMG", "forces_vs_emg": "forces vs EMG"}
    parts.append("<h2>Figures</h2>")
    for name, fig in figs.items():
        parts.append(_img_any(fig, captions.get(name, name)))
    for cap, fig in dict(extra_figures or {}).items():
        parts.append(_img_any(fig, cap))
    parts.append("<h2>Muscles</h2>")
    rows = muscle_stats(results)
    if rows:
        parts.append(_collapsed(f"{len(rows)} muscles", _table(
            ["muscle", "peak force (N)", "time of peak (s)", "mean force (N)", "mean activation",
             "peak activation"], [[r[0]] + [_g(x) for x in r[1:]] for r in rows]), len(rows) > SHOWN_ROWS))
    else:
        parts.append("<p>No muscle force or activation channels in the results.</p>")
    if emg is not None:
        q = "activation" if plots.muscles_in(results, "activation") else "force"
        r = plots.emg_correlations(results, emg, quantity=q)
        if r:
            # shapes are compared (r does not see scale); a muscle the solution leaves nearly silent
            # has no shape to compare, whatever its r
            parts.append(f"<p>Correlation of {q} with EMG (Pearson r of the shapes; a muscle whose peak "
                         f"activation is below {SILENT_PEAK:g} is marked silent):</p>")
            peaks = {m: float(np.nanmax(np.asarray(results[f"{m}_activation"], dtype=float)))
                     for m in r if f"{m}_activation" in results}
            parts.append(_table(["muscle", "r", "peak activation", "note"],
                                [[m, _g(v), _g(peaks.get(m)),
                                  "silent" if peaks.get(m, 1.0) < SILENT_PEAK else ""] for m, v in r.items()],
                                left={0, 3}))
    st = status_counts(results)
    if st:
        parts.append("<h2>Solver status</h2>")
        parts.append(_table(["status", "frames", "meaning"], st, left={0, 2}))
    parts.append("<h2>Result channels</h2>")
    stats = channel_stats(results)
    parts.append(_collapsed(f"{len(stats)} channels", _table(
        ["channel", "unit", "min", "max", "mean", "RMS"], [r[:2] + [_g(x) for x in r[2:]] for r in stats],
        left=2), len(stats) > SHOWN_ROWS))
    for cap, tab in dict(tables or {}).items():
        header, trows = tab
        parts.append(f"<h2>{_e(cap)}</h2>")
        parts.append(_table(list(header), [[_g(x) if isinstance(x, float) else x for x in r] for r in trows]))
    if text:
        parts.append("<h2>Solver report</h2><pre>" + _e(text) + "</pre>")
    parts.append('<p class="small">Generated by pinmsk. Figures are embedded PNGs; this file needs no network.</p>')
    parts.append("</body></html>")
    return portable_text("\n".join(parts))


def write_results_report(path, *, model, trial, results, title: str | None = None, text: str | None = None,
                         tables=None, extra_figures=None, emg=None, figures=None) -> Path:
    """Write one self-contained HTML report of a result (SO, FSO, ...) to ``path``; returns the path.

    Sections: model (``model.describe()``), data (frames, duration, rate,
    channels of ``trial`` and ``results``), figures (:func:`pinmsk.presentation.plots.results_figures`:
    moments when ``<coord>_moment`` channels exist, muscle forces and
    activations, vs EMG when ``<muscle>_emg`` channels are in ``results`` or
    ``trial`` or ``emg`` -- True or an EMG Trial -- is given), then
    ``extra_figures`` (``{caption: Figure | PNG bytes | PNG path}``); ``figures`` (the same form,
    keyed by :func:`~pinmsk.presentation.plots.results_figures`' names) in place of drawing them again,
    e.g. the PNGs :func:`~pinmsk.presentation.plots.save_results_figures` wrote; tables:
    per muscle peak force, its time, mean force, mean and peak activation; EMG
    correlation; solver status counts (``status`` channel); per channel
    min/max/mean/RMS; ``tables`` (``{caption: (header, rows)}``); ``text``
    (e.g. a solver's ``report()``) in a <pre>.  PNGs are base64-embedded; the
    file is written to a temporary file and moved into place (os.replace).
    """
    return _atomic_write(path, render_results_report(model=model, trial=trial, results=results, title=title,
                                                     text=text, tables=tables, extra_figures=extra_figures,
                                                     emg=emg, figures=figures))
