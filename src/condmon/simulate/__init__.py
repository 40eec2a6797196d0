"""Simulated test-beds with known parameters and switchable faults."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from condmon._lazy import load, names

if TYPE_CHECKING:
    from condmon.simulate.actuator import (
        ActuatorRig, ar1_noise, band_limited_noise, load_actuator_rig, simulate_actuator,
    )
    from condmon.simulate.faults import Fault, apply_fault, parse_fault

__all__ = ["ActuatorRig", "load_actuator_rig", "simulate_actuator", "band_limited_noise",
           "ar1_noise", "Fault", "parse_fault", "apply_fault"]

# Imported on first use (PEP 562).
_EXPORTS: dict[str, str] = {
    **dict.fromkeys(("ActuatorRig", "ar1_noise", "band_limited_noise", "load_actuator_rig",
                     "simulate_actuator"), "condmon.simulate.actuator"),
    **dict.fromkeys(("Fault", "apply_fault", "parse_fault"), "condmon.simulate.faults"),
}


def __getattr__(name: str) -> Any:
    return load(__name__, _EXPORTS, name)


def __dir__() -> list[str]:
    return names(globals(), _EXPORTS)
