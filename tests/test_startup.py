"""Start-up cost: what each command imports (not timed: which modules load).

Each check runs in a fresh interpreter and lists the heavy packages found in
``sys.modules`` afterwards. ``benchmarks/bench_startup.py`` measures the times.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from condmon.diagnose import suspects
from condmon.diagnose.suspects import Outcome, SuspectTask, run_suspects

#: Never needed to print help or to estimate a record.
NEVER = ("sqlalchemy", "matplotlib", "sklearn", "faultdiagnosistoolbox")


#: Heavy subpackages reported by name (``numpy.ma``: np.unique and np.median import it).
SUBPACKAGES = ("scipy.signal", "scipy.stats", "numpy.ma")

#: scipy's C filter routine, loaded on its own (about 1 ms, no scipy package):
#: not counted as scipy.
ALONE = "scipy.signal._sigtools"


def _loaded(code: str, cache: Path, *, check: bool = True) -> set[str]:
    """Top-level packages of NEVER (and scipy, sympy, pandas, scikit-fuzzy)
    imported by ``code``, and the heavy subpackages of SUBPACKAGES."""
    probe = (f"{code}\nimport json, sys\n"
             f"print(json.dumps(sorted({{m.split('.')[0] for m in sys.modules if m != {ALONE!r}}}\n"
             f"    | {{m for m in sys.modules if m in {SUBPACKAGES!r}}})))")
    env = {**os.environ, "CONDMON_CACHE_DIR": str(cache)}
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                          env=env, check=False)
    if check:
        assert done.returncode == 0, done.stderr
    return set(json.loads(done.stdout.strip().splitlines()[-1])) & {
        *NEVER, "scipy", "sympy", "pandas", "skfuzzy", *SUBPACKAGES}


def _command(*args: str) -> str:
    """Code running ``condmon ARGS`` in-process, its output swallowed."""
    return ("from condmon.cli.main import main\n"
            "import contextlib, io\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            f"    assert main({list(args)!r}) == 0")


@pytest.fixture(scope="module")
def record(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from condmon.io.records import write_record
    from condmon.simulate import simulate_actuator

    path = tmp_path_factory.mktemp("startup") / "act.csv"
    write_record(simulate_actuator(seed=3), path)
    return path


@pytest.fixture(scope="module")
def warm_cache(tmp_path_factory: pytest.TempPathFactory, record: Path) -> Path:
    """A cache folder holding the dc-motor's derived structure."""
    cache = tmp_path_factory.mktemp("cache")
    _loaded(f"import condmon\ncondmon.estimate(condmon.read_record({str(record)!r}))", cache)
    return cache


def test_help_imports_no_library(tmp_path: Path) -> None:
    code = ("from condmon.cli.main import main\n"
            "import contextlib, io\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    assert main(['--help']) == 0")
    assert _loaded(code, tmp_path) == set()


def test_importing_the_command_line_imports_no_library(tmp_path: Path) -> None:
    assert _loaded("import condmon.cli.main, condmon", tmp_path) == set()


def test_estimating_a_record_imports_neither_store_nor_plots(record: Path,
                                                             warm_cache: Path) -> None:
    """The library's estimate path; with the dc-motor's structure cached, no sympy."""
    code = f"import condmon\ncondmon.estimate(condmon.read_record({str(record)!r}))"
    assert not _loaded(code, warm_cache) & {*NEVER, "sympy"}


def test_the_estimate_command_imports_neither_plots_nor_store(record: Path,
                                                             warm_cache: Path) -> None:
    code = ("from condmon.cli.main import main\n"
            "import contextlib, io\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            f"    assert main(['estimate', {str(record)!r}]) == 0")
    loaded = _loaded(code, warm_cache)
    assert not loaded & {"matplotlib", "sklearn", "faultdiagnosistoolbox", "sympy"}
    assert "sqlalchemy" not in loaded  # no database for an estimate
    assert "scipy.signal" not in loaded and "scipy.stats" not in loaded  # ~1 s of imports


def test_the_estimate_command_of_a_plain_csv_imports_neither_pandas_nor_scipy(
        record: Path, warm_cache: Path) -> None:
    """A plain CSV record is read with numpy: no pandas (0.3 s of imports), no
    scipy, not even numpy.ma."""
    assert _loaded(_command("estimate", str(record)), warm_cache) == set()


def test_a_record_pandas_must_read_still_estimates(record: Path, tmp_path: Path,
                                                   warm_cache: Path) -> None:
    """A semicolon file with decimal commas takes the pandas reader."""
    import pandas as pd

    frame = pd.read_csv(record)
    path = tmp_path / "comma.csv"
    frame.to_csv(path, sep=";", decimal=",", index=False)
    assert _loaded(_command("estimate", str(path)), warm_cache) & {"pandas", "scipy"} == {"pandas"}


@pytest.fixture(scope="module")
def history(tmp_path_factory: pytest.TempPathFactory, warm_cache: Path) -> tuple[Path, Path]:
    """A SQLite history whose unit u1 has a baseline, and a record to check."""
    from condmon.io.records import write_record
    from condmon.simulate import simulate_actuator

    from condmon import History

    folder = tmp_path_factory.mktemp("history")
    db = folder / "h.db"
    healthy = [write_record(simulate_actuator(seed=s), folder / f"h{s}.csv") for s in (4, 5, 6)]
    with History(db) as h:  # built in this process: only the probed check runs apart
        h.baseline_add("u1", healthy)
        for s in (8, 9, 10, 11, 12, 13):  # checks enough for an exponential to be fitted
            h.check("u1", write_record(simulate_actuator(seed=s), folder / f"c{s}.csv"))
    return db, write_record(simulate_actuator(seed=7), folder / "check.csv")


def test_the_check_command_imports_neither_scipy_nor_a_fuzzy_library(
        history: tuple[Path, Path], warm_cache: Path) -> None:
    """The status sets are evaluated with numpy (no scikit-fuzzy, nor the
    scipy.linalg and scipy.spatial it imports), the t and F tails and the
    forecast's bounded minimum in plain Python (no scipy.special, no
    scipy.optimize): a check loads no scipy at all."""
    db, record = history
    loaded = _loaded(_command("check", str(record), "--unit", "u1", "--db", str(db)),
                     warm_cache)
    assert not loaded & {"skfuzzy", "scipy", "matplotlib", "sklearn", "faultdiagnosistoolbox",
                         "sympy"}
    assert "sqlalchemy" in loaded  # the history: the probe sees what it must


def test_the_isolate_command_of_a_plain_csv_imports_neither_pandas_nor_sympy(
        tmp_path: Path, warm_cache: Path) -> None:
    """With the plant's compiled model cached (the first run), an isolation of a
    plain CSV record loads no pandas and no sympy: the solver's scipy only."""
    from condmon.io.records import write_record
    from condmon.models.registry import load_plant_model
    from condmon.simulate.plant import simulate_plant

    path = write_record(simulate_plant(load_plant_model("hst"), ["Rv=+40%@10s"], seed=1),
                        tmp_path / "hst.csv")
    code = _command("isolate", "hst", str(path))
    _loaded(code, warm_cache)  # fills the cache
    loaded = _loaded(code, warm_cache)
    assert not loaded & {"pandas", "sympy", "sqlalchemy", "matplotlib", "sklearn", "skfuzzy",
                         "scipy.signal", "scipy.stats"}
    assert "scipy" in loaded  # the solver: the probe sees what it must


# --- the process pool only when it pays --------------------------------------------


def test_a_pool_pays_only_for_long_serial_work(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    assert not suspects._pool_pays(3, 0.05)        # the HST's suspects: serial
    assert suspects._pool_pays(3, 1.0)
    assert not suspects._pool_pays(1, 10.0)        # one left: nothing to share
    monkeypatch.setattr(os, "cpu_count", lambda: 1)
    assert not suspects._pool_pays(8, 10.0)


def test_quick_suspects_run_without_a_pool_by_default(monkeypatch: pytest.MonkeyPatch) -> None:
    def no_pool(*args: object) -> list[Outcome]:
        raise AssertionError("a pool was started")

    monkeypatch.setattr(suspects, "_pooled", no_pool)
    monkeypatch.setattr(suspects, "_attempt", lambda task: Outcome(None, task.parameter))
    tasks = [SuspectTask(None, p, 1.0, 0.0, None, None)  # type: ignore[arg-type]
             for p in ("a", "b", "c")]
    assert [o.failure for o in run_suspects(tasks)] == ["a", "b", "c"]


def test_python_dash_m_runs_the_command_line(tmp_path: Path) -> None:
    """``python -m condmon`` is ``condmon`` (a virtualenv whose scripts are not on
    the PATH): help, and a bad option's one line with exit 2."""
    env = {**os.environ, "CONDMON_CACHE_DIR": str(tmp_path)}
    ok = subprocess.run([sys.executable, "-m", "condmon", "--help"], capture_output=True,
                        text=True, env=env, check=False)
    assert ok.returncode == 0 and "estimate" in ok.stdout, ok.stderr
    bad = subprocess.run([sys.executable, "-m", "condmon", "estimate", "--no-such-option"],
                         capture_output=True, text=True, env=env, check=False)
    assert bad.returncode == 2
