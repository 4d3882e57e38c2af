"""The HTML summary of a batch (:func:`pinmsk.pipeline.batch`): one table of its trials.

One row per trial: its status (``ok``, ``skipped (done)`` for a trial a rerun found
complete, or the failure), the time it took, its frames, the peak joint moments and
torso residuals of ``summary.csv``, and links to the files in the trial's folder
(relative links, so the output folder can be moved or shared as a whole: the
figures ``moments.png`` and ``residuals.png`` among them).  No scripts,
stylesheets or fonts are fetched.
"""
from __future__ import annotations

import html
from pathlib import Path
from typing import Sequence
from urllib.parse import quote

from ..io.output_files import atomic_write

__all__ = ["render_batch_report", "write_batch_report"]

_CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;max-width:1400px;margin:2em auto;padding:0 1em;color:#222}
h1{font-size:1.5em}table{border-collapse:collapse;margin:.5em 0;font-size:.9em}
td,th{border:1px solid #ccc;padding:.3em .6em;text-align:right;vertical-align:top}th{background:#f3f3f3}
td.l,th.l{text-align:left}.ok{color:#1e8449}.skipped{color:#566573}.failed{color:#b03a2e;font-weight:bold}
.files{font-size:.85em}.files a{display:block;white-space:nowrap}.status{max-width:18em}
.small{color:#666;font-size:.85em}
"""


def _e(x) -> str:
    return html.escape(str(x))


def _num(x, fmt="{:.3g}") -> str:
    return fmt.format(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else "–"


def _status(row) -> tuple[str, str]:
    status = str(row.get("status", "failed"))
    if not status.startswith("ok"):
        return "failed", status.removeprefix("failed: ")
    return ("skipped", "skipped (done)") if row.get("skipped") else ("ok", "ok")


def render_batch_report(rows: Sequence[dict], out, *, title: str = "pinmsk batch", model=None) -> str:
    """The report of ``rows`` (:func:`pinmsk.pipeline.batch`'s) whose trial folders are in ``out``."""
    out = Path(out)
    counts = {"ok": 0, "skipped": 0, "failed": 0}
    for r in rows:
        counts[_status(r)[0]] += 1
    moments = list(dict.fromkeys(k for r in rows for k in r if k.endswith("_peak_abs_nm_per_kg")))
    moments += list(dict.fromkeys(k for r in rows for k in r if k.endswith("_peak_abs_nm")))
    forces = list(dict.fromkeys(k for r in rows for k in r if k.endswith("_residual_rms_n")))
    torques = list(dict.fromkeys(k for r in rows for k in r if k.endswith("_residual_rms_nm")))
    residuals = forces + torques
    per_kg = [k for k in moments if k.endswith("_per_kg")]
    groups = [("", 5), ("peak |joint moment| (N m/kg)", len(per_kg)),
              ("peak |joint moment| (N m)", len(moments) - len(per_kg)),
              ("residual force RMS (N)", len(forces)), ("residual moment RMS (N m)", len(torques))]
    names = (["trial", "status", "time (s)", "frames", "files"]
             + [k.removesuffix("_peak_abs_nm_per_kg").removesuffix("_peak_abs_nm") for k in moments]
             + [k.removesuffix("_residual_rms_n") for k in forces]
             + [k.removesuffix("_residual_rms_nm") for k in torques])
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{_e(title)}</title>"
             f"<style>{_CSS}</style></head><body><h1>{_e(title)}</h1>",
             f"<p>{len(rows)} trials{f' of model {_e(model)}' if model is not None else ''}: "
             f"<span class='ok'>{counts['ok']} run</span>, "
             f"<span class='skipped'>{counts['skipped']} skipped (done before, same inputs and options)</span>, "
             f"<span class='failed'>{counts['failed']} failed</span>. "
             "The table of numbers is <a href='summary.csv'>summary.csv</a>.</p>",
             "<table><tr>" + "".join(f"<th colspan='{c}'>{_e(g)}</th>" for g, c in groups if c) + "</tr>",
             "<tr>" + "".join(f"<th class='{'l' if h in ('trial', 'status', 'files') else ''}'>{_e(h)}</th>"
                              for h in names) + "</tr>"]
    for r in rows:
        cls, text = _status(r)
        name = str(r.get("name"))
        folder = out / name
        files = sorted(p.name for p in folder.iterdir() if p.is_file()) if folder.is_dir() else []
        links = "".join(f"<a href='{quote(name)}/{quote(f)}'>{_e(f)}</a>" for f in files if f != "done.json")
        cells = ([f"<td class='l'>{_e(name)}<br><span class='small'>{_e(r.get('kind', ''))}</span></td>",
                  f"<td class='l status {cls}'>{_e(text)}</td>",
                  f"<td>{_num(r.get('time_total_s'), '{:.2f}')}</td>", f"<td>{_num(r.get('frames'), '{:d}')}</td>",
                  f"<td class='l files'>{links or '–'}</td>"]
                 + [f"<td>{_num(r.get(k))}</td>" for k in moments + residuals])
        parts.append("<tr>" + "".join(cells) + "</tr>")
    parts.append("</table><p class='small'>time: the trial's own run (for a skipped trial, the run that "
                 "wrote its folder).</p></body></html>")
    return "\n".join(parts)


def write_batch_report(path, rows: Sequence[dict], out=None, **kw) -> Path:
    """Write :func:`render_batch_report` to ``path`` atomically (``out`` defaults to its folder)."""
    path = Path(path)
    text = render_batch_report(rows, path.parent if out is None else out, **kw)
    return atomic_write(path, lambda fh: fh.write(text))
