"""``pinmsk demo``: the whole diagnosis loop on a shipped forearm trial (a workflow).

It runs the analyses (:mod:`pinmsk.diagnose`) and hands their results to
:mod:`pinmsk.presentation` for the figures and the report.
"""
from __future__ import annotations

from pathlib import Path

from .diagnose.diagnosis import diagnose, run
from .io.shared_data import shipped_trial
from .io.tables import read_trial
from .model import load_model
from .presentation import plots
from .presentation.report import save_diagnosis

__all__ = ["demo", "DEMO_TRIAL"]

DEMO_TRIAL = "forearm_payload.csv"


def demo(out_dir, *, trial: str = DEMO_TRIAL, echo=print):
    """Diagnose the shipped forearm trial, add the winner, and write figures and a report to ``out_dir``.

    Prints where the base model fails, the ranking, the effect added and the
    error before and after.  Writes ``before.png`` / ``after.png`` (model vs
    measurement), the ranking, residual and error-step figures, ``report.html``
    and ``diagnosis.json``.  Returns the :class:`~pinmsk.diagnose.DiagnosisRun`.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    model = load_model("forearm")
    path = shipped_trial(trial)
    data = read_trial(path)
    echo(f"== pinmsk demo: model 'forearm' against {path.name} (a trial with a hidden effect) ==")
    first = diagnose(model, data)
    echo(first.summary_text())
    if first.best is None:
        echo("nothing to add: the base model is at the noise floor")
        result = run(model, data, first=first)
        save_diagnosis(result, json_path=out / "diagnosis.json", report_path=out / "report.html", plot_dir=out)
        return result
    label = first.best.label
    echo("")
    echo(f"== adding {label} and diagnosing again ==")
    result = run(model, data, add=[label], first=first)
    save_diagnosis(result, json_path=out / "diagnosis.json", report_path=out / "report.html", plot_dir=out)
    after = result.final
    echo(after.summary_text(header=False))
    echo("")
    echo(f"total rmse before {first.rmse['total']:.4g} -> after {after.rmse['total']:.4g} "
         f"(noise floor {after.noise_floor['total']:.4g}); verdict {after.verdict}")
    plots.plot_comparison(first, out / "before.png", title="before: base model")
    plots.plot_comparison(after, out / "after.png", title=f"after: + {label}")
    echo(f"wrote {out / 'before.png'}, {out / 'after.png'}, {out / 'report.html'}, {out / 'diagnosis.json'}")
    return result
