"""``pinmsk demo``: the whole diagnosis loop on a shipped forearm trial."""
from __future__ import annotations

from pathlib import Path

from ..errors import TrialError
from ..io.tables import read_trial
from ..model import load_model
from ..presentation import plots
from .diagnosis import diagnose, run

__all__ = ["demo", "shipped_trial", "shipped_trials", "DEMO_TRIAL"]

DEMO_TRIAL = "forearm_payload.csv"


def _data_dir() -> Path:
    try:
        import importlib.resources
        d = Path(str(importlib.resources.files("pinmsk._data")))
        if d.is_dir():
            return d
    except (ModuleNotFoundError, TypeError):
        pass
    return Path(__file__).resolve().parents[2] / "data"


def shipped_trials() -> list[str]:
    """Names of the hidden-effect trials shipped in ``data/``."""
    return sorted(p.name for p in _data_dir().glob("*.csv"))


def shipped_trial(name: str) -> Path:
    """Path of a shipped trial (see ``data/README.md`` for how each was made)."""
    p = _data_dir() / name
    if not p.exists():
        raise TrialError(f"no shipped trial '{name}'; shipped: {', '.join(shipped_trials()) or 'none'}")
    return p


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
        result = run(model, data, first=first, json_path=out / "diagnosis.json",
                     report_path=out / "report.html", plot_dir=out)
        return result
    label = first.best.label
    echo("")
    echo(f"== adding {label} and diagnosing again ==")
    result = run(model, data, add=[label], first=first, json_path=out / "diagnosis.json",
                 report_path=out / "report.html", plot_dir=out)
    after = result.final
    echo(after.summary_text(header=False))
    echo("")
    echo(f"total rmse before {first.rmse['total']:.4g} -> after {after.rmse['total']:.4g} "
         f"(noise floor {after.noise_floor['total']:.4g}); verdict {after.verdict}")
    plots.plot_comparison(first, out / "before.png", title="before: base model")
    plots.plot_comparison(after, out / "after.png", title=f"after: + {label}")
    echo(f"wrote {out / 'before.png'}, {out / 'after.png'}, {out / 'report.html'}, {out / 'diagnosis.json'}")
    return result
