"""A simulated fleet inbox (``INBOX/UNIT/record files``) with known faults.

For trying :func:`condmon.workflows.fleet.run_fleet` and for its tests and
benchmarks: actuator units simulated on the closed-loop test-bed, plant-model
units (``hst``) by the declared-plant simulator, each unit healthy or with a
parameter fault from one of its records on.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

__all__ = ["SimulatedUnit", "simulated_inbox"]


@dataclass(frozen=True)
class SimulatedUnit:
    """One unit of a simulated inbox.

    Attributes
    ----------
    name : str
        Its folder's name.
    model : str
        ``dc-motor`` (the actuator test-bed) or a plant model (``hst``).
    records : int
        How many records.
    fault : str or None
        The fault of its later records: an actuator fault (``D=*7``,
        ``R=+40%``) or a plant step fault (``Dm=-25%@10s``).
    fault_from : int
        The first faulty record (1-based).
    duration : float or None
        Length of a plant record [s] (default: the declared test's).
    """

    name: str
    model: str = "dc-motor"
    records: int = 5
    fault: str | None = None
    fault_from: int = 4
    duration: float | None = None


def simulated_inbox(folder: str | Path, units: Sequence[SimulatedUnit], seed: int = 0,
                    suffix: str = ".csv") -> dict[str, list[Path]]:
    """Write each unit's records to ``folder/UNIT/rec-NN.csv``.

    A plant-model unit's folder gets a ``unit.toml`` naming its model. Every
    record has its own noise seed (``seed`` + a running number).

    Returns
    -------
    dict
        ``{unit: [record files in order]}``.

    Example
    -------
    >>> import tempfile
    >>> files = simulated_inbox(tempfile.mkdtemp(), [SimulatedUnit("EMA-1", records=2)])
    >>> [p.name for p in files["EMA-1"]]
    ['rec-01.csv', 'rec-02.csv']
    """
    from condmon.io.records import write_record
    from condmon.models.registry import load_plant_model
    from condmon.simulate.actuator import load_actuator_rig, simulate_actuator
    from condmon.simulate.plant import simulate_plant

    root = Path(folder)
    written: dict[str, list[Path]] = {}
    n = seed
    for unit in units:
        where = root / unit.name
        where.mkdir(parents=True, exist_ok=True)
        plant = None if unit.model == "dc-motor" else load_plant_model(unit.model)
        if plant is not None:
            (where / "unit.toml").write_text(f'model = "{unit.model}"\n', encoding="utf-8")
        healthy = load_actuator_rig() if plant is None else None
        faulty = (load_actuator_rig(None, [unit.fault])
                  if plant is None and unit.fault is not None else healthy)
        files = []
        for i in range(1, unit.records + 1):
            n += 1
            broken = unit.fault is not None and i >= unit.fault_from
            if plant is None:
                rec = simulate_actuator(faulty if broken else healthy, seed=n)
            else:
                rec = simulate_plant(plant, [unit.fault] if broken and unit.fault else [],
                                     seed=n, duration=unit.duration)
            path = where / f"rec-{i:02d}{suffix}"
            write_record(rec, path)
            files.append(path)
        written[unit.name] = files
    return written
