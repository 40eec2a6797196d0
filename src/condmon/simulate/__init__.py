"""Simulated test-beds with known parameters and switchable faults."""

from condmon.simulate.actuator import (
    ActuatorRig, band_limited_noise, load_actuator_rig, simulate_actuator,
)
from condmon.simulate.faults import Fault, apply_fault, parse_fault

__all__ = ["ActuatorRig", "load_actuator_rig", "simulate_actuator", "band_limited_noise",
           "Fault", "parse_fault", "apply_fault"]
