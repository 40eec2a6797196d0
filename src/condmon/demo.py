"""The built-in demonstration: the reference paper's experiments, end to end.

For each experiment of ``condmon/data/demo.toml`` (friction, resistance,
inductance-and-resistance): simulate healthy baseline tests and the faulty
tests on the test-bed with its nonlinear effects on, store them in a local
SQLite history, check each test against the baseline (symptoms, diagnosis) and
write an HTML report with figures. Everything ``condmon demo`` prints comes
from :func:`run_demo`.
"""

from __future__ import annotations

import dataclasses
import html
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from condmon.errors import ConfigError
from condmon.io.config import load_default, load_toml
from condmon.monitor.workflow import CheckResult, add_baseline_tests, check_test
from condmon.report.html import write_report
from condmon.simulate.actuator import ActuatorRig, load_actuator_rig, simulate_actuator
from condmon.simulate.faults import parse_fault
from condmon.store.db import HistoryStore, open_store

__all__ = ["DemoCheck", "DemoResult", "run_demo", "load_demo_config"]

Progress = Callable[[int, int, str], None]


@dataclass(frozen=True)
class DemoCheck:
    """One checked test of an experiment.

    Attributes
    ----------
    unit : str
    title : str
        The experiment's title.
    label : str
        The test's label.
    faults : tuple of str
        Faults injected in the simulated test.
    truth_change : dict of str to float
        True percent change of each parameter. [%]
    result : CheckResult
    """

    unit: str
    title: str
    label: str
    faults: tuple[str, ...]
    truth_change: dict[str, float]
    result: CheckResult

    @property
    def top_fault(self) -> str:
        """Name of the highest-degree fault, or "no fault"."""
        d = self.result.diagnosis
        return d.faults[0].name if d is not None and d.faults else "no fault"

    @property
    def cross_coupling_ratio(self) -> float:
        """Largest |estimated change| of an unchanged parameter divided by the
        smallest |true change| of a changed one (0 for a healthy test)."""
        changed = {k: v for k, v in self.truth_change.items() if abs(v) > 1e-9}
        if not changed:
            return 0.0
        others = [abs(v) for k, v in self.result.percent_change.items() if k not in changed]
        return max(others, default=0.0) / min(abs(v) for v in changed.values())


@dataclass(frozen=True)
class DemoResult:
    """Everything the demo produced.

    Attributes
    ----------
    checks : tuple of DemoCheck
    database : Path
    report : Path
        The index page linking each unit's report.
    """

    checks: tuple[DemoCheck, ...]
    database: Path
    report: Path


def load_demo_config(path: str | Path | None = None) -> dict[str, Any]:
    """The demo's experiments (shipped defaults, or a file in the same format)."""
    cfg = load_toml(path) if path is not None else load_default("demo.toml")
    if not cfg.get("experiment"):
        raise ConfigError(f"{path or 'demo.toml'}: no [[experiment]]")
    return cfg


def _truth_change(rig: ActuatorRig, faulty: ActuatorRig) -> dict[str, float]:
    h, f = rig.physical(), faulty.physical()
    return {k: 100.0 * (f[k] - h[k]) / h[k] for k in h}


def run_demo(out_dir: str | Path = "condmon-demo", config: str | Path | None = None,
             progress: Progress | None = None) -> DemoResult:
    """Run the paper's experiments on the simulated test-bed and write the report.

    Parameters
    ----------
    out_dir : str or Path
        Folder for ``condmon.db`` (recreated) and the HTML report.
    config : str or Path, optional
        Experiments file (default ``condmon/data/demo.toml``).
    progress : callable, optional
        ``progress(done, total, label)``.

    Returns
    -------
    DemoResult
    """
    cfg = load_demo_config(config)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    db = out / "condmon.db"
    if db.exists():
        db.unlink()  # the demo always starts from an empty history
    with open_store(db) as store:
        return _run(store, cfg, out, db, progress)


def _run(store: HistoryStore, cfg: dict[str, Any], out: Path, db: Path,
         progress: Progress | None) -> DemoResult:
    base_rig = dataclasses.replace(load_actuator_rig(), **cfg.get("rig", {}))
    n_base = int(cfg.get("baseline_tests", 5))
    seed = int(cfg.get("seed", 1))
    experiments = cfg["experiment"]
    total = sum(n_base + len(e["tests"]) for e in experiments)
    done = 0
    checks: list[DemoCheck] = []
    pages = []
    for ei, exp in enumerate(experiments):
        unit = str(exp["unit"])
        for faults in exp["tests"]:
            for f in faults:
                parse_fault(f)  # refuse a bad experiment before simulating anything
        healthy = []
        for i in range(n_base):
            rec = simulate_actuator(base_rig, seed=seed + 1000 * ei + i)
            rec.attrs["source"] = f"{unit} baseline {i + 1}"
            healthy.append(rec)
        add_baseline_tests(store, unit, healthy)
        done += n_base
        if progress is not None:
            progress(done, total, unit)
        labels = list(exp.get("labels", []))
        for ti, faults in enumerate(exp["tests"]):
            rig = base_rig.with_faults(faults)
            rec = simulate_actuator(rig, seed=seed + 1000 * ei + 100 + ti)
            label = labels[ti] if ti < len(labels) else (", ".join(faults) or "healthy")
            rec.attrs["source"] = f"{unit} test {ti + 1} ({label})"
            res = check_test(store, unit, rec)
            checks.append(DemoCheck(unit, str(exp.get("title", unit)), label, tuple(faults),
                                    _truth_change(base_rig, rig), res))
            done += 1
            if progress is not None:
                progress(done, total, unit)
        files = write_report(store, unit, out)
        pages.append((unit, str(exp.get("title", "")), files.html.name))
    index = out / "index.html"
    links = "".join(f"<li><a href='{html.escape(p)}'>{html.escape(u)}</a> — {html.escape(t)}</li>"
                    for u, t, p in pages)
    index.write_text("<!doctype html><html><head><meta charset='utf-8'><title>condmon demo</title>"
                     "<style>body{font-family:system-ui,sans-serif;margin:2em}</style></head><body>"
                     "<h1>condmon demo: the reference experiments</h1>"
                     f"<ul>{links}</ul></body></html>", encoding="utf-8")
    return DemoResult(tuple(checks), db, index)
