"""Models: transfer functions, ZOH conversions and physical models."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from condmon._lazy import load, names

if TYPE_CHECKING:
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

# Imported on first use (PEP 562).
_EXPORTS: dict[str, str] = {
    **dict.fromkeys(("StateSpace", "c2d", "d2c", "tf_c2d", "tf_d2c"), "condmon.models.conversion"),
    **dict.fromkeys(("PARAMETER_NAMES", "PARAMETER_UNITS", "DCMotorParameters",
                     "dc_motor_from_discrete", "dc_motor_from_tf", "dc_motor_tf"),
                    "condmon.models.dc_motor"),
    "Machine": "condmon.models.machine",
    **dict.fromkeys(("get_model", "list_models", "register_model"), "condmon.models.registry"),
    **dict.fromkeys(("ContinuousTF", "DiscreteTF"), "condmon.models.transfer"),
}


def __getattr__(name: str) -> Any:
    return load(__name__, _EXPORTS, name)


def __dir__() -> list[str]:
    return names(globals(), _EXPORTS)
