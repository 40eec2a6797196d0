"""Sensor offsets as candidate faults: what the shipped HST and the declaration
with an offset per sensor (examples/hst-sensor-offsets) name for a drifting
sensor, for a machine fault, and for a healthy record.

    python benchmarks/bench_sensor_offsets.py [--seeds 6] [--healthy 20]

Each record is simulated with the offsets' declaration (the built-in 30 s test,
seeds 3, 4, 5, ...) and isolated with both. An ambiguity set that holds the
truth (``bPs,Tld``) is an honest answer, counted apart from a wrong one. Prints the table of the example's
README and writes results/sensor_offsets.json. An answer that came with the F
test's warning (the best model leaves more error than noise reaches) is
counted apart: it is a machine fault named, with a doubt. The shipped HST
has no offset parameters; its own sensor candidates (a gain and an offset per
sensor, ``condmon/diagnose/sensor_faults.py``) are its right answer for an
offset: "Ps sensor offset" for ``bPs``, "omega_m sensor offset" for ``bw``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import collections  # noqa: E402
import sys  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

from _common import table, write_json  # noqa: E402
from condmon.diagnose.isolation import isolate  # noqa: E402
from condmon.errors import DataWarning  # noqa: E402
from condmon.models.registry import load_plant_model  # noqa: E402
from condmon.simulate.plant import simulate_plant  # noqa: E402

EXAMPLE = Path(__file__).parents[1] / "examples" / "hst-sensor-offsets" / "hst-sensor-offsets.toml"
FAULTS = ["bPs=+3e4@10s", "bPs=+1e5@10s", "bPs=-1e5@10s", "bPs=+5e5@10s", "bw=+0.15@10s",
          "bw=+0.5@10s", "bw=-1.5@10s", "Rv=+40%@10s", "Tld=+20@10s", "Dm=-25%@10s",
          "Rlkgm=-50%@10s"]


#: What the shipped HST (no offset parameters) names for an offset: its own
#: sensor candidate (condmon/diagnose/sensor_faults.py).
SENSOR_NAMED = {"bPs": "Ps sensor offset", "bw": "omega_m sensor offset"}


def _named(res) -> tuple[str, ...]:  # type: ignore[no-untyped-def]
    """The components isolated, then the sensor errors that explain the record as well."""
    return tuple(res.isolated) + tuple(f.name for f in res.sensor_faults)


def _answer(res) -> str:  # type: ignore[no-untyped-def]
    if not res.detected:
        return "no detection"
    named = ",".join(_named(res)) or "none"
    return named + ("*" if "but even" in res.statement or "but it still" in res.statement
                    else "")


def _tally(answers: list[str]) -> str:
    return ", ".join(f"{k} ×{n}" for k, n in collections.Counter(answers).items())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, default=6, help="records per fault (seeds 3, 4, ...)")
    ap.add_argument("--healthy", type=int, default=20, help="healthy records")
    args = ap.parse_args()
    warnings.simplefilter("ignore", DataWarning)
    stock, offsets = load_plant_model("hst"), load_plant_model(EXAMPLE)
    rows, right = [], {"hst": 0, "offsets": 0}
    among = {"hst": 0, "offsets": 0}   # the truth in an ambiguity set
    wrong = {"hst": 0, "offsets": 0}   # named, and the truth not among them
    for fault in FAULTS:
        truth = fault.split("=")[0]
        got: dict[str, list[str]] = {"hst": [], "offsets": []}
        for s in range(args.seeds):
            rec = simulate_plant(offsets, [fault], seed=3 + s)
            for key, m in (("hst", stock), ("offsets", offsets)):
                res = isolate(rec, m, workers=1)
                got[key].append(_answer(res))
                said = SENSOR_NAMED.get(truth, truth) if key == "hst" else truth
                named = _named(res)
                right[key] += named == (said,)
                among[key] += len(named) > 1 and said in named
                wrong[key] += bool(named) and said not in named
        rows.append({"fault": fault, "shipped hst": _tally(got["hst"]),
                     "with the offsets": _tally(got["offsets"])})
    healthy = {"hst": 0, "offsets": 0}
    for s in range(args.healthy):
        rec = simulate_plant(offsets, seed=500 + s)
        for key, m in (("hst", stock), ("offsets", offsets)):
            healthy[key] += isolate(rec, m, workers=1).detected
    print(table(rows, f"What each declaration names ({args.seeds} seeds; * with the F test's "
                      "warning)"))
    total = args.seeds * len(FAULTS)
    for what, count in (("named alone and right", right), ("an ambiguity set holding it", among),
                        ("named, and wrong", wrong)):
        print(f"{what}: shipped hst {count['hst']}/{total}, with the offsets "
              f"{count['offsets']}/{total}")
    print(f"healthy records detected: shipped hst {healthy['hst']}/{args.healthy}, with the "
          f"offsets {healthy['offsets']}/{args.healthy}")
    path = write_json("sensor_offsets", {"faults": rows, "right": right, "among": among,
                                         "wrong": wrong, "total": total,
                                         "healthy_detected": healthy,
                                         "healthy_records": args.healthy})
    print(f"\nwrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
