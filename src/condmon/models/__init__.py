"""Models: transfer functions, ZOH conversions and physical models."""

from condmon.models.conversion import StateSpace, c2d, d2c, tf_c2d, tf_d2c
from condmon.models.dc_motor import (
    PARAMETER_NAMES, PARAMETER_UNITS, DCMotorParameters, dc_motor_from_discrete,
    dc_motor_from_tf, dc_motor_tf,
)
from condmon.models.machine import Machine
from condmon.models.registry import get_model, list_models, register_model
from condmon.models.transfer import ContinuousTF, DiscreteTF

__all__ = [
    "DiscreteTF", "ContinuousTF", "StateSpace", "c2d", "d2c", "tf_c2d", "tf_d2c",
    "DCMotorParameters", "PARAMETER_NAMES", "PARAMETER_UNITS", "dc_motor_tf",
    "dc_motor_from_tf", "dc_motor_from_discrete", "Machine", "get_model",
    "list_models", "register_model",
]
