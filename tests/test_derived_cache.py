"""The cache of derived structures: same results as deriving, and never in the way."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from condmon.models import derived_cache

# Estimates the dc-motor and isolates an HST fault; prints the results and
# whether sympy and the structural-analysis toolbox were imported.
_RUN = """
import json, sys
import condmon
from condmon.diagnose.isolation import isolate
from condmon.models.registry import load_plant_model
from condmon.simulate.plant import simulate_plant
res = condmon.estimate(condmon.simulate_actuator(seed=2))
hst = load_plant_model("hst")
iso = isolate(simulate_plant(hst, ["Rv=+40%@10s"], seed=3), hst, workers=1)
print(json.dumps({"estimate": res.to_dict(), "isolated": iso.isolated,
                  "fsm": iso.fsm.to_dict(),
                  "sympy": "sympy" in sys.modules,
                  "toolbox": "faultdiagnosistoolbox" in sys.modules}))
"""


def _run(cache: Path, **env: str) -> dict[str, object]:
    done = subprocess.run([sys.executable, "-c", _RUN], capture_output=True, text=True,
                          env={**os.environ, "CONDMON_CACHE_DIR": str(cache), **env},
                          check=False)
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""  # nothing printed about the cache
    doc = json.loads(done.stdout)
    assert isinstance(doc, dict)
    return doc


def _results(doc: dict[str, object]) -> tuple[object, ...]:
    return doc["estimate"], doc["isolated"], doc["fsm"]


@pytest.fixture(scope="module")
def filled(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, object]]:
    """A cache folder after a first run, and that run's results."""
    cache = tmp_path_factory.mktemp("cache")
    return cache, _run(cache)


@pytest.fixture(scope="module")
def derived(filled: tuple[Path, dict[str, object]]) -> dict[str, object]:
    """The results as derived: the first run found the cache empty and derived
    every structure (it imported sympy: asserted below)."""
    return filled[1]


def test_a_cached_structure_gives_the_derived_results_without_sympy(
        tmp_path: Path, filled: tuple[Path, dict[str, object]],
        derived: dict[str, object]) -> None:
    cache, first = filled
    assert first["sympy"] and first["toolbox"]  # derived, then kept
    for f in cache.glob("*.json"):
        shutil.copy(f, tmp_path)
    assert list(tmp_path.glob("*.json"))
    second = _run(tmp_path)
    assert not second["sympy"] and not second["toolbox"]
    assert _results(first) == _results(second) == _results(derived)


def test_a_damaged_or_foreign_cache_is_derived_again(tmp_path: Path,
                                                      filled: tuple[Path, dict[str, object]],
                                                      derived: dict[str, object]) -> None:
    for f in filled[0].glob("*.json"):
        shutil.copy(f, tmp_path)
    files = sorted(tmp_path.glob("*.json"))
    assert len(files) == 2  # dc-motor, hst
    files[0].write_text("{not json")
    for f in files[1:]:  # entries this code cannot use
        doc = json.loads(f.read_text())
        doc["items"] = {k: {"source": "def f(:", "name": "f", "globals": {}}
                        for k in doc["items"]}
        f.write_text(json.dumps(doc))
    assert _results(_run(tmp_path)) == _results(derived)
    assert not _run(tmp_path)["sympy"]  # and written again


def test_an_unwritable_cache_folder_is_no_error(tmp_path: Path,
                                                derived: dict[str, object]) -> None:
    blocked = tmp_path / "a-file"
    blocked.write_text("")
    assert _results(_run(blocked / "cache")) == _results(derived)


def test_only_functions_of_known_modules_are_kept() -> None:
    x = sp.Symbol("x", real=True)
    plain = sp.lambdify([x], [sp.exp(x), sp.Max(x, 0), sp.sign(x)], modules="numpy")
    data = derived_cache.portable(plain, 0.5)
    assert data is not None
    restored = derived_cache.restore_function(data)
    assert np.array_equal(restored(-0.25), plain(-0.25))
    custom = sp.lambdify([x], sp.Function("f")(x), modules=[{"f": lambda v: v}, "numpy"])
    assert derived_cache.portable(custom, 0.5) is None


def test_the_key_ignores_values_and_paths_not_equations() -> None:
    from condmon.models.registry import load_plant_model

    hst = load_plant_model("hst")
    assert derived_cache.plant_key(hst.with_parameters({"Rv": 3.0}, "elsewhere.toml")) \
        == derived_cache.plant_key(hst)
    states = (dataclasses.replace(hst.states[0], derivative="0"), *hst.states[1:])
    assert derived_cache.plant_key(dataclasses.replace(hst, states=states)) \
        != derived_cache.plant_key(hst)
