"""The README's Python examples run as written, so they cannot rot.

Each ```python block is executed in a fresh folder holding the record files
it names (simulated actuator records: healthy ones, and a pre-flight check).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from condmon.simulate import simulate_actuator

README = Path(__file__).resolve().parents[1] / "README.md"
BLOCKS = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), re.S)


def test_the_readme_has_python_examples() -> None:
    assert len(BLOCKS) >= 3


@pytest.mark.parametrize("code", BLOCKS, ids=[f"block{i + 1}" for i in range(len(BLOCKS))])
def test_a_readme_python_example_runs(code: str, tmp_path: Path,
                                      monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    for i, name in enumerate(("healthy.csv", "h1.csv", "h2.csv", "h3.csv", "preflight.csv")):
        simulate_actuator(seed=11 + i).to_csv(tmp_path / name, index=False)
    exec(compile(code, "README.md python block", "exec"), {"__name__": "readme"})
