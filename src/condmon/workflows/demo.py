"""The built-in demonstration: the reference papers' experiments, end to end.

For each actuator experiment of ``condmon/data/demo.toml`` (friction,
resistance, inductance-and-resistance): simulate healthy baseline tests and the
faulty tests on the test-bed with its nonlinear effects on, store them in a
local SQLite history, check each test against the baseline (symptoms,
diagnosis) and write an HTML report with figures. Then, for the hydrostatic
transmission, isolate each listed fault and write the residual and model-error
figures. Everything ``condmon demo`` prints comes from :func:`run_demo`.
"""

from __future__ import annotations

import dataclasses
import html
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from condmon.diagnose.isolation import IsolationResult, healthy_normalisation, isolate
from condmon.errors import ConfigError
from condmon.models.registry import load_plant_model
from condmon.io.config import load_default, load_toml
from condmon.workflows.isolation import store_isolation
from condmon.workflows.checks import CheckResult, check_test
from condmon.workflows.monitoring import add_baseline_tests
from condmon.report.html import write_fleet_report
from condmon.report.names import page_name
from condmon.report.isolation_figures import write_isolation_figures
from condmon.simulate.actuator import ActuatorRig, load_actuator_rig, simulate_actuator
from condmon.simulate.faults import parse_fault
from condmon.simulate.plant import parameter_steps, simulate_plant
from condmon.store.db import HistoryStore, open_store

__all__ = ["DemoCheck", "DemoIsolation", "DemoResult", "run_demo", "load_demo_config"]

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
        """Name of the highest-degree fault, else of the strongest tendency to
        watch (a developing fault below advisory level), else "no fault"."""
        d = self.result.diagnosis
        listed = (*d.faults, *d.watch) if d is not None else ()
        return listed[0].name if listed else "no fault"

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
class DemoIsolation:
    """One hydrostatic-transmission fault of the demo.

    Attributes
    ----------
    fault : str
        The injected fault, e.g. ``Rv=+25%@10s``.
    parameter : str
        The truly faulty parameter.
    true_value : float
        Its faulty value. [parameter unit]
    result : IsolationResult
    figures : tuple of Path
    """

    fault: str
    parameter: str
    true_value: float
    result: IsolationResult
    figures: tuple[Path, ...]


@dataclass(frozen=True)
class DemoResult:
    """Everything the demo produced.

    Attributes
    ----------
    checks : tuple of DemoCheck
    database : Path
    report : Path
        The index page linking each unit's report.
    isolations : tuple of DemoIsolation
        The hydrostatic transmission's faults.
    """

    checks: tuple[DemoCheck, ...]
    database: Path
    report: Path
    isolations: tuple[DemoIsolation, ...] = ()


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
        pages.append((unit, str(exp.get("title", ""))))
    isolations = _run_hst(cfg.get("hst"), out, progress, store)
    titles = "".join(f"<li><a href='{html.escape(page_name(u))}.html'>{html.escape(u)}</a> — "
                     f"{html.escape(t)}</li>" for u, t in pages)
    index = write_fleet_report(  # every unit's page (the HST units' too) and the index
        store, out, title="condmon demo: the reference experiments",
        extra="<h2>Electromechanical actuator: parameter estimation and fuzzy diagnosis</h2>"
              f"<ul>{titles}</ul>{_hst_section(isolations)}").index
    return DemoResult(tuple(checks), db, index, isolations)


def _run_hst(cfg: dict[str, Any] | None, out: Path, progress: Progress | None,
             store: HistoryStore | None = None) -> tuple[DemoIsolation, ...]:
    """The HST experiments; each fault's isolation is kept in the history of a
    unit named after the faulty parameter (``HST-Rv``, ...)."""
    if not cfg:
        return ()
    model = load_plant_model(str(cfg.get("model", "hst")))
    faults = [str(f) for f in cfg.get("faults", [])]
    steps = [parameter_steps(model, [f])[0] for f in faults]  # refuse a bad fault first
    n = int(cfg.get("healthy", 5))
    total = n + len(faults)
    norm = healthy_normalisation(model, [simulate_plant(model, seed=9000 + i) for i in range(n)])
    if progress is not None:
        progress(n, total, "HST healthy records")
    done = []
    for k, (fault, step) in enumerate(zip(faults, steps)):
        rec = simulate_plant(model, [fault], seed=9100 + k)
        rec.attrs["source"] = f"HST {fault}"
        res = isolate(rec, model, normalisation=norm, source=fault)
        if store is not None:
            store_isolation(store, f"HST-{step.name}", res, rec, None,
                            str(cfg.get("model", "hst")))
        folder = out / "hst" / f"{k + 1}-{step.name}"
        figs = write_isolation_figures(res, model, rec[list(model.sensor_names)].to_numpy(),
                                       folder)
        done.append(DemoIsolation(fault, step.name, step.value, res, tuple(figs)))
        if progress is not None:
            progress(n + k + 1, total, f"HST {fault}")
    return tuple(done)


def _hst_section(isolations: tuple[DemoIsolation, ...]) -> str:
    if not isolations:
        return ""
    rows = []
    for d in isolations:
        r = d.result
        est = r.estimates.get(d.parameter)
        estimate = f"{est.value:.5g} (true {d.true_value:.5g})" if est is not None else "—"
        when = f"{r.detection_time:.2f} s" if r.detection_time is not None else "not detected"
        figs = " ".join(f"<a href='{html.escape(str(f.relative_to(f.parents[2])))}'>"
                        f"{html.escape(f.stem)}</a>" for f in d.figures)
        rows.append(f"<tr><td>{html.escape(d.fault)}</td><td>{when}</td>"
                    f"<td>{html.escape(', '.join(r.isolated) or '—')}</td>"
                    f"<td>{html.escape(estimate)}</td><td>{html.escape(r.statement)}</td>"
                    f"<td>{figs}</td></tr>")
    return ("<h2>Hydrostatic transmission: residuals and parallel multi-model isolation</h2>"
            "<table><tr><th>fault</th><th>detected</th><th>isolated</th><th>estimate</th>"
            f"<th>conclusion</th><th>figures</th></tr>{''.join(rows)}</table>")
