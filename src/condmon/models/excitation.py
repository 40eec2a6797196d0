"""Excitation of a built-in test: known perturbations added to a declared input.

A record can tell a machine's parameters only if its inputs move: a constant
input excites nothing, and condmon refuses such a record ("column 'u' is
constant"). A declaration's built-in test (``condmon simulate plant``) therefore
says how its inputs are excited, as data in ``[test]``:

.. code-block:: toml

    [test]
    duration = 10.0
    sample_rate = 1000.0
    excitation = [
        { input = "u", signal = "prbs", amplitude = 1.0, hold = 0.05, seed = 3 },
        { input = "F", signal = "sine", amplitude = 2.0, period = 1.5, start = 1.0 },
    ]

Signals (each added to the input's nominal value and scheduled steps, from
``start`` to ``stop`` [s]):

- ``prbs``: a random binary sequence of +-``amplitude``, each level held for
  ``hold`` [s] (a new random level every hold: about half of them switch),
  drawn from ``seed`` (default 0), so the test is the same at every run;
- ``square``: +``amplitude`` for half a ``period`` [s], then -``amplitude``;
- ``sine``: ``amplitude`` * sin(2 pi t / ``period``).

Several entries for one input add up (a multisine is two ``sine`` entries).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from condmon.errors import ConfigError

__all__ = ["Excitation", "SIGNALS", "parse_excitation", "excitation_signal"]

FloatArray = NDArray[np.float64]

#: The signal kinds and the key that gives each one's time scale [s].
SIGNALS: dict[str, str] = {"prbs": "hold", "square": "period", "sine": "period"}


@dataclass(frozen=True)
class Excitation:
    """A perturbation of input ``input`` during the built-in test.

    Attributes
    ----------
    input : str
        The declared input it is added to.
    signal : str
        ``"prbs"``, ``"square"`` or ``"sine"`` (see the module's description).
    amplitude : float
        Size of the perturbation. [unit of the input]
    interval : float
        The hold of a ``prbs`` level, or the period of a ``square``/``sine``. [s]
    start, stop : float
        When the perturbation is on (``stop``: inf for the end of the test). [s]
    seed : int
        Seed of a ``prbs`` sequence.
    """

    input: str
    signal: str
    amplitude: float
    interval: float
    start: float = 0.0
    stop: float = math.inf
    seed: int = 0


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{where} must be a finite number, not {value!r}")
    return float(value)


def parse_excitation(entries: Any, where: str, inputs: Sequence[str],
                     sample_rate: float = math.inf) -> tuple[Excitation, ...]:
    """The ``excitation`` list of a ``[test]`` table, validated.

    Parameters
    ----------
    entries : list of tables
        As read from the declaration.
    where : str
        The declaration's name and table, for messages (``"x.toml[test]"``).
    inputs : sequence of str
        The declared inputs.
    sample_rate : float
        The test's sample rate: a ``prbs`` level is held one sample at least. [Hz]

    Raises
    ------
    ConfigError
        Naming the entry and the key: an unknown input or signal, a missing
        or non-positive time scale (a ``prbs`` hold shorter than a sample), an
        unknown key.

    Example
    -------
    >>> parse_excitation([{"input": "u", "signal": "prbs", "amplitude": 1, "hold": 0.05}],
    ...                  "m.toml[test]", ["u"])[0].interval
    0.05
    """
    if not isinstance(entries, list):
        raise ConfigError(f"{where}.excitation must be a list of tables "
                          "(excitation = [{ input = ..., signal = ..., ... }])")
    out = []
    for i, e in enumerate(entries):
        at = f"{where}.excitation[{i}]"
        if not isinstance(e, Mapping):
            raise ConfigError(f"{at} must be a table {{ input = ..., signal = ..., ... }}")
        signal = e.get("signal")
        if signal not in SIGNALS:
            raise ConfigError(f"{at}.signal: {signal!r} is not a signal; allowed: "
                              f"{', '.join(SIGNALS)}")
        scale = SIGNALS[str(signal)]
        allowed = {"input", "signal", "amplitude", scale, "start", "stop"} | (
            {"seed"} if signal == "prbs" else set())
        unknown = sorted(set(e) - allowed)
        if unknown:
            raise ConfigError(f"{at}: unknown key {unknown[0]!r}; a {signal} excitation takes "
                              f"{', '.join(sorted(allowed))}")
        for key in ("input", "amplitude", scale):
            if key not in e:
                raise ConfigError(f"{at}: {key!r} is missing")
        if e["input"] not in inputs:
            raise ConfigError(f"{at}.input: unknown input {e['input']!r}; allowed: "
                              f"{', '.join(inputs) or '(none declared)'}")
        interval = _number(e[scale], f"{at}.{scale}")
        if not interval > 0:
            raise ConfigError(f"{at}.{scale} must be > 0 [s], not {interval:g}")
        if signal == "prbs" and 0 < sample_rate and interval * sample_rate < 1.0 - 1e-9:
            raise ConfigError(f"{at}.hold: {interval:g} s is shorter than one sample "
                              f"({1.0 / sample_rate:g} s at {sample_rate:g} Hz)")
        start = _number(e.get("start", 0.0), f"{at}.start")
        stop = _number(e["stop"], f"{at}.stop") if "stop" in e else math.inf
        if not stop > start:
            raise ConfigError(f"{at}: stop ({stop:g} s) must come after start ({start:g} s)")
        seed = e.get("seed", 0)
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ConfigError(f"{at}.seed must be a whole number >= 0, not {seed!r}")
        out.append(Excitation(str(e["input"]), str(signal),
                              _number(e["amplitude"], f"{at}.amplitude"), interval, start,
                              stop, seed))
    return tuple(out)


def excitation_signal(exc: Excitation, t: FloatArray) -> FloatArray:
    """The perturbation on the sample times ``t`` [s] (0 outside start..stop).

    Example
    -------
    >>> t = np.arange(8) / 4.0
    >>> excitation_signal(Excitation("u", "square", 2.0, 1.0), t).tolist()
    [2.0, 2.0, -2.0, -2.0, 2.0, 2.0, -2.0, -2.0]
    """
    tau = np.asarray(t, dtype=np.float64) - exc.start
    on = (tau >= -1e-12) & (np.asarray(t) < exc.stop - 1e-12)
    # the index of the hold or half-period a sample falls in; the small shift keeps
    # a sample on a boundary in the later interval despite rounding
    if exc.signal == "sine":
        wave = np.sin(2.0 * np.pi * tau / exc.interval)
    elif exc.signal == "square":
        half = np.floor(np.maximum(tau, 0.0) / (exc.interval / 2.0) + 1e-9).astype(np.int64)
        wave = np.where(half % 2 == 0, 1.0, -1.0)
    else:
        k = np.floor(np.maximum(tau, 0.0) / exc.interval + 1e-9).astype(np.int64)
        levels = np.random.default_rng(exc.seed).choice((-1.0, 1.0), int(k.max(initial=0)) + 1)
        wave = levels[k]
    return np.where(on, exc.amplitude * wave, 0.0)
