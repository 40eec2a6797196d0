"""Each suspect's model run, bounded, one after the other or in a process pool.

A suspect's run is a pure function of a small picklable task
(:func:`simulate_suspect`), so it can be shipped to a process pool, as here, or
to a distributed engine. Every run carries its own limits
(:class:`~condmon.simulate.plant.SimulationLimits`), checked inside the model's
right-hand side: a runaway integration stops itself in its worker, and its
suspect is reported as timed out while the others still decide. The pool is
waited on for no longer than the limits allow, then terminated.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from multiprocessing.pool import AsyncResult

import numpy as np
from numpy.typing import NDArray

from condmon.errors import CondmonError
from condmon.models.declared import Parameter, PlantModel
from condmon.simulate.plant import (
    ParameterStep, SimulationLimits, SimulationTimeout, integrate, sensor_readings,
)

__all__ = ["SuspectTask", "Outcome", "simulate_suspect", "run_suspects", "plausible_range"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SuspectTask:
    """One suspect's model run: ``parameter`` steps to ``value`` at ``at`` [s],
    on the grid ``t`` [s] with the inputs ``u``, within ``limits``."""

    model: PlantModel
    parameter: str
    value: float
    at: float
    t: FloatArray
    u: FloatArray
    limits: SimulationLimits = SimulationLimits()


@dataclass(frozen=True)
class Outcome:
    """A suspect run's sensor readings (n, n_sensors) [sensor units], or why there are none."""

    outputs: FloatArray | None
    failure: str | None = None


def simulate_suspect(task: SuspectTask) -> FloatArray:
    """Sensor readings of the model with the suspect's estimate, shape (n, n_sensors).

    A pure function of its task: safe to run in another process.

    Raises
    ------
    SimulationTimeout
        When the run goes beyond ``task.limits``.
    EstimationError
        When the solver fails.
    """
    compiled = task.model.compile()
    steps = (ParameterStep(task.parameter, task.at, task.value),)
    x = integrate(compiled, task.t, task.u, steps, limits=task.limits)
    return sensor_readings(compiled, x, task.u, steps, task.t)


def _attempt(task: SuspectTask) -> Outcome:
    """:func:`simulate_suspect` with every failure turned into a reason (never raises)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a worker must not write to the parent's console
            y = simulate_suspect(task)
    except SimulationTimeout as exc:
        return Outcome(None, f"timed out: {exc}")
    except CondmonError as exc:
        return Outcome(None, f"simulation failed: {exc}")
    except Exception as exc:  # noqa: BLE001 - reported as the suspect's failure
        return Outcome(None, f"simulation failed: {type(exc).__name__}: {exc}")
    if not np.all(np.isfinite(y)):
        return Outcome(None, "simulation failed: non-finite sensor readings")
    return Outcome(y)


def run_suspects(tasks: Sequence[SuspectTask], workers: int | None = None,
                 grace: float = 10.0) -> list[Outcome]:
    """Run every task; a failed or timed-out one never stops the others.

    Parameters
    ----------
    tasks : sequence of SuspectTask
    workers : int, optional
        Processes; 1 runs the tasks one after the other. Default: one after
        the other unless a pool pays (see :func:`_pool_pays`), then one
        process per remaining task, at most the number of CPUs.
    grace : float
        Extra wait for the pool beyond what the tasks' limits allow (start-up,
        transfer), after which unfinished tasks are reported and the pool is
        terminated. [s]

    Returns
    -------
    list of Outcome
        In the order of ``tasks``.
    """
    if workers is None:
        # Serial unless a pool pays: the first task is timed in this process,
        # and the rest go to a pool only when they would take long serially.
        if len(tasks) <= 1 or (os.cpu_count() or 1) <= 1:
            return [_attempt(task) for task in tasks]
        start = time.perf_counter()
        first = _attempt(tasks[0])
        if not _pool_pays(len(tasks) - 1, time.perf_counter() - start):
            return [first, *(_attempt(task) for task in tasks[1:])]
        return [first, *_pooled(tasks[1:], min(len(tasks) - 1, os.cpu_count() or 1), grace)]
    n = min(len(tasks), workers)
    if n <= 1:
        return [_attempt(task) for task in tasks]
    return _pooled(tasks, n, grace)


#: Serial time of the remaining suspects above which a process pool is used. [s]
#: Starting the pool, forking and shipping each task and its answer costs some
#: 0.1-0.3 s on a small machine; with a few suspects of tens of milliseconds
#: each (the HST's built-in test) the pool was measured slower than running
#: them one after the other (0.85x on 2 cores).
POOL_MIN_SERIAL = 2.0


def _pool_pays(remaining: int, seconds_each: float) -> bool:
    """Whether ``remaining`` tasks of ``seconds_each`` [s] are worth a process
    pool: more than one CPU and at least :data:`POOL_MIN_SERIAL` of serial work."""
    return (os.cpu_count() or 1) > 1 and remaining > 1 \
        and remaining * seconds_each >= POOL_MIN_SERIAL


def _pooled(tasks: Sequence[SuspectTask], n: int, grace: float) -> list[Outcome]:
    """The tasks in a pool of ``n`` processes, waited on within their limits."""
    tasks[0].model.compile()  # forked workers inherit the compiled model
    method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    rounds = math.ceil(len(tasks) / n)
    longest = max(task.limits.time_limit for task in tasks)
    wait = rounds * longest + grace if math.isfinite(longest) else None
    deadline = None if wait is None else time.monotonic() + wait
    with multiprocessing.get_context(method).Pool(n) as pool:  # terminated on exit
        pending: list[AsyncResult[Outcome]] = [pool.apply_async(_attempt, (task,))
                                               for task in tasks]
        out = []
        for task, job in zip(tasks, pending):
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            try:
                out.append(job.get(timeout=left))
            except multiprocessing.TimeoutError:
                out.append(Outcome(None, f"timed out: no answer from its worker within "
                                         f"{wait:.0f} s"))
            except Exception as exc:  # noqa: BLE001 - a worker that died
                out.append(Outcome(None, f"simulation failed: {type(exc).__name__}: {exc}"))
    return out


def plausible_range(parameter: Parameter, factor: float) -> tuple[float, float] | None:
    """Values an estimate of ``parameter`` may take [parameter unit].

    The declared ``range`` when there is one; otherwise within ``factor`` of a
    non-zero nominal value on either side, and no bound for a zero nominal.

    Example
    -------
    >>> from condmon.models.registry import load_plant_model
    >>> m = load_plant_model("hst")
    >>> [round(v, 4) for v in plausible_range(m.parameter("Rv"), 100.0)]
    [0.1127, 1127.1]
    >>> plausible_range(m.parameter("Tld"), 100.0)    # declared
    (-450.0, 450.0)
    """
    if parameter.range is not None:
        return parameter.range
    v = parameter.value
    if v == 0 or not factor > 1:
        return None
    lo, hi = sorted((v / factor, v * factor))
    return lo, hi
