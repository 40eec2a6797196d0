"""Limits on what a user's declaration may ask (``condmon/data/limits.toml``), without sympy."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["EquationLimits", "equation_limits", "condition_limits"]


@dataclass(frozen=True)
class EquationLimits:
    """What one equation (``[equations]`` of ``condmon/data/limits.toml``) or
    a regime's condition (``[conditions]``) may hold.

    Attributes
    ----------
    max_length : int
        Characters.
    max_depth : int
        Nesting of operations and calls.
    max_exponent : float
        Largest magnitude of an exponent, which must be a number. [-]
    max_literal : float
        Largest magnitude of a number, and of a power of numbers. [-]
    max_exp_nesting : int
        Exponentials nested in each other.
    time_limit : float
        To parse a declaration and derive what it implies. [s]
    """

    max_length: int = 20000
    max_depth: int = 200
    max_exponent: float = 64.0
    max_literal: float = 1e300
    max_exp_nesting: int = 2
    time_limit: float = 10.0


def equation_limits() -> EquationLimits:
    """The shipped limits (``condmon/data/limits.toml``).

    Example
    -------
    >>> equation_limits().max_exponent
    64.0
    """
    from condmon.io.config import shipped_limits

    return shipped_limits("equations", EquationLimits)


def condition_limits() -> EquationLimits:
    """The shipped limits on a regime's condition (``[conditions]`` of
    ``condmon/data/limits.toml``; of its fields, the first four apply).

    Example
    -------
    >>> condition_limits().max_depth
    40
    """
    from condmon.io.config import shipped_limits

    return shipped_limits("conditions", EquationLimits)
