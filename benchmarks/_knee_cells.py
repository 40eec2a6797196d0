"""Six simulated cells whose fade bends into a knee, for
``bench_prognostics_real.py --data DIR --level 0.88``: wear of another
shape than NASA's cells, where a unit's own series cannot show what is ahead.

    python benchmarks/_knee_cells.py DIR
    python benchmarks/bench_prognostics_real.py --data DIR --level 0.88 --no-progpy --every 25

Each cell: 1.1 Ah; a slow linear fade (0.08-0.16 mAh a cycle) that bends,
around a cycle drawn between 250 and 450, into a fast one (0.6-1.4 mAh a
cycle more; a softplus 40 cycles wide); a recovery of 5-20 mAh every 30th
cycle (a rest) fading back at 0.8 a cycle; reading noise 3 mAh (sd). Written
until 10 cycles past the first reading below 0.88 Ah (80 %), ``cycle,capacity``.
Simulated: these figures say how the forecast meets the shape, not how it
does on real cells.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

RATED = 1.1          # [Ah]
END = 0.88           # [Ah], 80 % of rated
CYCLES = 900


def knee_cell(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One cell's cycles and capacity [-, Ah], up to 10 cycles past its end."""
    c = np.arange(1, CYCLES + 1, dtype=np.float64)
    early = rng.uniform(0.8e-4, 1.6e-4)
    knee = rng.uniform(250.0, 450.0)
    late = rng.uniform(0.6e-3, 1.4e-3)
    fade = early * c + late * 40.0 * np.logaddexp(0.0, (c - knee) / 40.0)
    recovery = np.zeros(CYCLES)
    for k in range(1, CYCLES):
        rest = rng.uniform(0.005, 0.02) if k % 30 == 0 else 0.0
        recovery[k] = 0.8 * recovery[k - 1] + rest
    capacity = RATED - fade + recovery + rng.normal(0.0, 0.003, CYCLES)
    stop = min(CYCLES, int(np.argmax(capacity < END)) + 10)
    return c[:stop], capacity[:stop]


def main() -> None:
    if len(sys.argv) != 2:
        sys.exit("usage: python benchmarks/_knee_cells.py DIR")
    out = Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(20261207)
    for i in range(6):
        cycle, capacity = knee_cell(rng)
        lines = ["cycle,capacity"] + [f"{c:g},{q:.5f}" for c, q in zip(cycle, capacity)]
        (out / f"S{i}.csv").write_text("\n".join(lines) + "\n")
        print(f"{out / f'S{i}.csv'}: {cycle.size} cycles")


if __name__ == "__main__":
    main()
