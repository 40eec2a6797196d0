"""Registry of the physical models an estimate can be mapped to."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from condmon.errors import ModelError
from condmon.io.config import load_default
from condmon.models.dc_motor import PARAMETER_NAMES, PARAMETER_UNITS, dc_motor_from_discrete
from condmon.models.plausibility import Plausibility, parse_plausibility
from condmon.models.transfer import DiscreteTF

__all__ = ["PhysicalModel", "get_model", "list_models"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class PhysicalModel:
    """A physical model reachable from a discrete transfer-function estimate.

    Attributes
    ----------
    name : str
        Registry key.
    input : str
        Input column.
    outputs : tuple of str
        Output columns, in model order.
    order : int
        Number of poles of the discrete model.
    parameters : tuple of str
        Physical parameter names.
    units : dict of str to str
        Unit of each parameter.
    gamma : float
        Default model constant (Ke/Kt for the DC motor).
    from_discrete : callable
        ``(model, covariance, gamma) -> (values, covariance)``.
    plausibility : Plausibility
        What is physically possible: parameter bounds, record timing, the
        believable change against a baseline.
    """

    name: str
    input: str
    outputs: tuple[str, ...]
    order: int
    parameters: tuple[str, ...]
    units: dict[str, str]
    gamma: float
    from_discrete: Callable[[DiscreteTF, FloatArray, float], tuple[FloatArray, FloatArray]]
    plausibility: Plausibility = field(default_factory=Plausibility)


def _dc_motor(model: DiscreteTF, cov: FloatArray, gamma: float
              ) -> tuple[FloatArray, FloatArray]:
    params, pcov = dc_motor_from_discrete(model, cov, gamma)
    return params.as_array(), pcov


def _registry() -> dict[str, PhysicalModel]:
    cfg = load_default("models.toml")
    dc = cfg["dc-motor"]
    return {
        "dc-motor": PhysicalModel("dc-motor", "V", ("I", "omega"), 2, PARAMETER_NAMES,
                                  PARAMETER_UNITS, float(dc["gamma"]), _dc_motor,
                                  parse_plausibility(dc, "models.toml [dc-motor]")),
    }


_MODELS = _registry()


def list_models() -> list[str]:
    """Names of the registered physical models."""
    return sorted(_MODELS)


def get_model(name: str) -> PhysicalModel:
    """The registered model ``name``.

    Example
    -------
    >>> get_model("dc-motor").parameters
    ('R', 'L', 'Ke', 'Kt', 'J', 'D')
    """
    try:
        return _MODELS[name]
    except KeyError:
        raise ModelError(f"unknown model {name!r}; allowed: {', '.join(list_models())}") from None
