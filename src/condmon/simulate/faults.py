"""Parameter faults written the way engineers say them.

``R=+40%`` (relative), ``D=*7`` (factor), ``L=+0.25mH`` (absolute increment with an
SI prefix), ``R=1.4`` (new value), ``Rv=+40%@10s`` (a step at t = 10 s).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Literal

from condmon.errors import ConfigError

__all__ = ["Fault", "parse_fault", "apply_fault"]

_PREFIX = {"p": 1e-12, "n": 1e-9, "u": 1e-6, "µ": 1e-6, "m": 1e-3, "k": 1e3, "M": 1e6}
_PATTERN = re.compile(
    r"^\s*(?P<name>[A-Za-z_][A-Za-z0-9_]*)\s*=\s*(?P<op>[+\-*]?)\s*"
    r"(?P<num>(\d+(\.\d*)?|\.\d+)([eE][+\-]?\d+)?)\s*(?P<unit>%|[A-Za-zµΩ]*)"
    r"\s*(@\s*(?P<at>(\d+(\.\d*)?|\.\d+)([eE][+\-]?\d+)?)\s*s?)?\s*$"
)

Kind = Literal["relative", "factor", "increment", "value"]


@dataclass(frozen=True)
class Fault:
    """One parameter change.

    Attributes
    ----------
    name : str
        Parameter name.
    kind : {"relative", "factor", "increment", "value"}
        How ``amount`` applies: ``x*(1+amount)``, ``x*amount``, ``x+amount``, ``amount``.
    amount : float
        Fraction for "relative" (0.4 for +40 %), SI value otherwise.
    at : float or None
        Time at which the fault steps in [s]; None: present from the start.
    """

    name: str
    kind: Kind
    amount: float
    at: float | None = None

    def apply(self, value: float) -> float:
        """The faulty value of a parameter whose healthy value is ``value``."""
        return apply_fault(value, self)

    def __str__(self) -> str:
        text = {
            "relative": f"{self.name}={self.amount * 100:+g}%",
            "factor": f"{self.name}=*{self.amount:g}",
            "increment": f"{self.name}={self.amount:+g}",
            "value": f"{self.name}={self.amount:g}",
        }[self.kind]
        return text if self.at is None else f"{text}@{self.at:g}s"


def parse_fault(spec: str) -> Fault:
    """Parse a fault specification.

    Parameters
    ----------
    spec : str
        ``NAME=+P%``, ``NAME=-P%``, ``NAME=*F``, ``NAME=+X[unit]``, ``NAME=X[unit]``,
        optionally followed by ``@Ts`` (step time in seconds).

    Returns
    -------
    Fault

    Example
    -------
    >>> parse_fault("L=+0.25mH")
    Fault(name='L', kind='increment', amount=0.00025, at=None)
    >>> parse_fault("Rv=-10%@5s").amount
    -0.1
    """
    m = _PATTERN.match(spec)
    if m is None:
        raise ConfigError(
            f"cannot read fault {spec!r}; write NAME=+40%, NAME=-10%, NAME=*7, "
            "NAME=+0.25mH or NAME=1.4, optionally followed by @10s"
        )
    name, op, unit = m["name"], m["op"], m["unit"]
    number = float(m["num"])
    at = float(m["at"]) if m["at"] is not None else None
    if unit == "%":
        if op not in "+-" or op == "":
            raise ConfigError(f"fault {spec!r}: a percentage needs a sign (+40% or -40%)")
        return Fault(name, "relative", (number if op == "+" else -number) / 100.0, at)
    scale = 1.0
    if len(unit) > 1 and unit[0] in _PREFIX:
        scale = _PREFIX[unit[0]]
    number *= scale
    if op == "*":
        if unit:
            raise ConfigError(f"fault {spec!r}: a factor takes no unit")
        return Fault(name, "factor", number, at)
    if op in "+-" and op != "":
        return Fault(name, "increment", number if op == "+" else -number, at)
    return Fault(name, "value", number, at)


def apply_fault(value: float, fault: Fault) -> float:
    """Apply ``fault`` to a healthy ``value``."""
    if fault.kind == "relative":
        return value * (1.0 + fault.amount)
    if fault.kind == "factor":
        return value * fault.amount
    if fault.kind == "increment":
        return value + fault.amount
    return fault.amount
