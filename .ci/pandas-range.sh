#!/usr/bin/env bash
# The table tests (pytest -m tables) on the oldest versions pyproject.toml allows
# (.ci/lowest.txt), in a virtualenv of their own; .ci/run's main run has the newest.
# Runs alone too: bash .ci/pandas-range.sh
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m venv --clear .ci/venv-lowest
source .ci/venv-lowest/bin/activate
python -m pip install -q --upgrade pip
pip install -q '.[test]' -c .ci/lowest.txt
python - <<'PY'
from importlib.metadata import version
print("oldest allowed:", ", ".join(f"{p} {version(p)}" for p in
      ("pandas", "numpy", "pyarrow", "sqlalchemy", "rich", "typer", "click")))
PY
pytest -m tables
