"""Shared fixtures: simulated records with known parameters."""

from __future__ import annotations

import dataclasses

import pandas as pd
import pytest

from condmon.simulate import ActuatorRig, load_actuator_rig, simulate_actuator


@pytest.fixture(scope="session")
def rig() -> ActuatorRig:
    return load_actuator_rig()


@pytest.fixture(scope="session")
def noise_free_record(rig: ActuatorRig) -> pd.DataFrame:
    quiet = dataclasses.replace(rig, noise_I=0.0, noise_omega=0.0)
    return simulate_actuator(quiet, seed=11, linear=True)


@pytest.fixture(scope="session")
def noisy_record(rig: ActuatorRig) -> pd.DataFrame:
    return simulate_actuator(rig, seed=5)
