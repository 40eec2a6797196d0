"""Operating regimes declared as data: named conditions over a record's signals.

A machine is not the same machine in every operating regime: an actuator's
friction differs with the direction of motion, a pump's with its load, and a
record held against an end stop says nothing about friction at all. A
declaration names its regimes in a ``[regimes]`` table; every sample of a
record is in the first regime whose condition holds, the record is cut into
windows of one regime each (:func:`condmon.identify.windows.cut_windows`), and
a machine's baseline, checks and trends are kept per regime.

.. code-block:: toml

    [regimes]
    settle = 0.2              # [s] left out at both ends of a window (transients)
    min_duration = 0.5        # [s] shortest window kept
    metadata = ["load"]       # record metadata that split every regime

    [regimes.forward]
    when = "omega > 0.1"
    description = "stroke, angle rising"

    [regimes.holding]
    when = "abs(omega) <= 0.1"
    use = false
    why = "held against the end stop: the stop's torque is not in the model"

A condition is an expression over the record's columns (after its
``[record]`` settings), the model's states the route derives from them (a
speed from a measured angle) and the record's metadata fields (from
``unit.toml``, a manifest row or ``--meta``): numbers, ``+ - * / **``,
comparisons (``< <= > >= == !=``, chained), ``and``, ``or``, ``not``,
parentheses, ``abs``, ``sqrt``, ``exp``, ``log``, ``sin``, ``cos``, ``tanh``,
``sign``, ``min``, ``max``, and text constants compared with metadata
(``load == "butterfly"``). It is parsed with :mod:`ast`, never evaluated by
Python, and refused beyond :func:`~condmon.models.limits.condition_limits`.
"""

from __future__ import annotations

import ast
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from condmon.errors import ConfigError, DataError
from condmon.models.limits import condition_limits

__all__ = ["Regime", "RegimeSpec", "Condition", "parse_condition", "parse_regimes",
           "regime_key", "split_key"]

FloatArray = NDArray[np.float64]

_RESERVED = ("settle", "min_duration", "metadata")

_FUNCTIONS: dict[str, Callable[..., Any]] = {
    "abs": np.abs, "sqrt": np.sqrt, "exp": np.exp, "log": np.log, "sin": np.sin,
    "cos": np.cos, "tanh": np.tanh, "sign": np.sign,
    "min": lambda *a: _reduce(np.minimum, a), "max": lambda *a: _reduce(np.maximum, a)}

_ARITH: dict[type[ast.operator], Callable[[Any, Any], Any]] = {
    ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.divide,
    ast.Pow: np.power}
_COMPARE: dict[type[ast.cmpop], Callable[[Any, Any], Any]] = {
    ast.Lt: np.less, ast.LtE: np.less_equal, ast.Gt: np.greater, ast.GtE: np.greater_equal,
    ast.Eq: lambda a, b: np.equal(a, b) if not isinstance(a, str) else a == b,
    ast.NotEq: lambda a, b: np.not_equal(a, b) if not isinstance(a, str) else a != b}


def _reduce(fn: Callable[[Any, Any], Any], args: tuple[Any, ...]) -> Any:
    out = args[0]
    for a in args[1:]:
        out = fn(out, a)
    return out


@dataclass(frozen=True)
class Condition:
    """A parsed condition (see the module's description).

    Attributes
    ----------
    text : str
        As written.
    names : tuple of str
        The signal or metadata names it uses.
    where : str
        The declaration and entry, for messages.

    Example
    -------
    >>> c = parse_condition("omega > 0.1 and load == 'valve'", "rig.toml[regimes.a]")
    >>> c.names
    ('load', 'omega')
    >>> c.evaluate({"omega": np.array([0.0, 0.5])}, {"load": "valve"}, 2).tolist()
    [False, True]
    """

    text: str
    names: tuple[str, ...]
    where: str
    tree: ast.Expression

    def evaluate(self, signals: Mapping[str, FloatArray], metadata: Mapping[str, Any],
                 n: int, source: str = "record") -> NDArray[np.bool_]:
        """Where the condition holds, sample by sample (shape ``(n,)``).

        Raises
        ------
        DataError
            A name that is neither a signal nor a metadata field of the record
            (the allowed ones listed), or a result that is not a condition.
        """
        missing = [k for k in self.names if k not in signals and k not in metadata]
        if missing:
            raise DataError(
                f"{source}: {self.where}: the condition {self.text!r} names {missing[0]!r}, "
                f"which is neither a column of the record ({', '.join(sorted(signals))}) "
                f"nor a metadata field ({', '.join(sorted(metadata)) or 'none given'})")
        try:
            with np.errstate(all="ignore"):
                value = _evaluate(self.tree.body, signals, metadata)
        except (TypeError, ValueError, np.exceptions.DTypePromotionError) as err:
            raise DataError(f"{source}: {self.where}: cannot evaluate {self.text!r} on this "
                            f"record ({type(err).__name__}: text metadata in arithmetic?)"
                            ) from None
        arr = np.asarray(value)
        if arr.dtype != np.bool_:
            raise DataError(f"{source}: {self.where}: {self.text!r} is not a condition (write a "
                            "comparison such as 'omega > 0.1')")
        return np.broadcast_to(arr, (n,)).copy()


def _evaluate(node: ast.AST, signals: Mapping[str, FloatArray],
              metadata: Mapping[str, Any]) -> Any:
    if isinstance(node, ast.Constant):
        return node.value
    if isinstance(node, ast.Name):
        if node.id in signals:
            return signals[node.id]
        return metadata[node.id]
    if isinstance(node, ast.BinOp):
        return _ARITH[type(node.op)](_evaluate(node.left, signals, metadata),
                                     _evaluate(node.right, signals, metadata))
    if isinstance(node, ast.UnaryOp):
        value = _evaluate(node.operand, signals, metadata)
        if isinstance(node.op, ast.Not):
            return np.logical_not(value)
        return -value if isinstance(node.op, ast.USub) else value
    if isinstance(node, ast.BoolOp):
        parts = [np.asarray(_evaluate(v, signals, metadata), dtype=bool) for v in node.values]
        return _reduce(np.logical_and if isinstance(node.op, ast.And) else np.logical_or,
                       tuple(parts))
    if isinstance(node, ast.Compare):
        left = _evaluate(node.left, signals, metadata)
        out: Any = True
        for op, comp in zip(node.ops, node.comparators):
            right = _evaluate(comp, signals, metadata)
            out = np.logical_and(out, _COMPARE[type(op)](left, right))
            left = right
        return out
    assert isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
    return _FUNCTIONS[node.func.id](*(_evaluate(a, signals, metadata) for a in node.args))


def parse_condition(text: Any, where: str) -> Condition:
    """Parse a regime's condition, refusing anything but the grammar of the
    module's description.

    Raises
    ------
    ConfigError
        Naming ``where``: a syntax error, an unknown function, an unsupported
        construct, or a text beyond :func:`~condmon.models.limits.condition_limits`.
    """
    if not isinstance(text, str) or not text.strip():
        raise ConfigError(f"{where}.when must be a condition such as \"omega > 0.1\"")
    lim = condition_limits()
    if len(text) > lim.max_length:
        raise ConfigError(f"{where}.when: the condition is {len(text)} characters long "
                          f"(limit {lim.max_length:g})")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except (SyntaxError, RecursionError, MemoryError, ValueError) as err:
        why = err.msg if isinstance(err, SyntaxError) else "too deeply nested"
        raise ConfigError(f"{where}.when: cannot read {text!r}: {why}") from None
    names: set[str] = set()

    def check(node: ast.AST, depth: int) -> None:
        if depth > lim.max_depth:
            raise ConfigError(f"{where}.when: {text!r} is nested deeper than "
                              f"{lim.max_depth:g} levels")
        if isinstance(node, ast.Constant):
            if isinstance(node.value, bool) or not isinstance(node.value, (int, float, str)):
                raise ConfigError(f"{where}.when: cannot use {ast.unparse(node)!r} in {text!r}")
            if isinstance(node.value, (int, float)) and not abs(node.value) <= lim.max_literal:
                raise ConfigError(f"{where}.when: the number {ast.unparse(node)[:20]} in "
                                  f"{text[:60]!r} is beyond {lim.max_literal:g}")
            return
        if isinstance(node, ast.Name):
            names.add(node.id)
            return
        if isinstance(node, ast.BinOp) and type(node.op) in _ARITH:
            if isinstance(node.op, ast.Pow):
                exp = node.right
                value = exp.value if isinstance(exp, ast.Constant) else None
                if (not isinstance(value, (int, float)) or isinstance(value, bool)
                        or abs(value) > lim.max_exponent):
                    raise ConfigError(f"{where}.when: an exponent must be a number within "
                                      f"±{lim.max_exponent:g} in {text[:60]!r}")
            check(node.left, depth + 1)
            check(node.right, depth + 1)
            return
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd, ast.Not)):
            check(node.operand, depth + 1)
            return
        if isinstance(node, ast.BoolOp):
            for v in node.values:
                check(v, depth + 1)
            return
        if isinstance(node, ast.Compare) and all(type(op) in _COMPARE for op in node.ops):
            for v in (node.left, *node.comparators):
                check(v, depth + 1)
            return
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
            if node.func.id not in _FUNCTIONS or node.keywords or not node.args:
                raise ConfigError(f"{where}.when: unknown function {node.func.id!r} in "
                                  f"{text!r}; allowed: {', '.join(_FUNCTIONS)}")
            for a in node.args:
                check(a, depth + 1)
            return
        raise ConfigError(f"{where}.when: cannot use {ast.unparse(node)[:40]!r} in a "
                          f"condition ({text[:60]!r})")

    try:
        check(tree.body, 0)
    except RecursionError:
        raise ConfigError(f"{where}.when: {text[:60]!r} is nested too deeply") from None
    return Condition(text.strip(), tuple(sorted(names)), where, tree)


@dataclass(frozen=True)
class Regime:
    """One declared regime.

    Attributes
    ----------
    name : str
    condition : Condition
    use : bool
        Whether estimation routes may use its windows.
    why : str
        Why not, when ``use`` is False (said in the windows' report).
    description : str
    """

    name: str
    condition: Condition
    use: bool = True
    why: str = ""
    description: str = ""


@dataclass(frozen=True)
class RegimeSpec:
    """The ``[regimes]`` table of a declaration (empty: one regime, the whole record).

    Attributes
    ----------
    regimes : tuple of Regime
        In declaration order: a sample is in the first whose condition holds.
    settle : float
        Left out at both ends of each window (transients). [s]
    min_duration : float
        Shortest window kept (after ``settle``). [s]
    metadata : tuple of str
        Metadata fields that split every regime: a record with ``load =
        "ball"`` is in regime ``forward, load=ball``.
    """

    regimes: tuple[Regime, ...] = ()
    settle: float = 0.0
    min_duration: float = 0.0
    metadata: tuple[str, ...] = ()

    @property
    def declared(self) -> bool:
        """Whether the declaration names regimes."""
        return bool(self.regimes) or bool(self.metadata)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"regimes": [{"name": r.name, "when": r.condition.text, "use": r.use,
                             "why": r.why or None} for r in self.regimes],
                "settle_s": self.settle, "min_duration_s": self.min_duration,
                "metadata": list(self.metadata)}


def _seconds(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
            math.isfinite(value) and value >= 0):
        raise ConfigError(f"{where} must be a duration >= 0 [s], not {value!r}")
    return float(value)


def parse_regimes(table: Mapping[str, Any] | None, source: str) -> RegimeSpec:
    """Read and validate a declaration's ``[regimes]`` table.

    Raises
    ------
    ConfigError
        Naming the file and the entry.

    Example
    -------
    >>> spec = parse_regimes({"settle": 0.1, "moving": {"when": "abs(omega) > 0.1"},
    ...                       "held": {"when": "abs(omega) <= 0.1", "use": False}}, "rig.toml")
    >>> [(r.name, r.use) for r in spec.regimes], spec.settle
    ([('moving', True), ('held', False)], 0.1)
    """
    if not table:
        return RegimeSpec()
    where = f"{source}[regimes]"
    if not isinstance(table, Mapping):
        raise ConfigError(f"{where} must be a table of regimes")
    regimes = []
    for name, entry in table.items():
        if name in _RESERVED:
            continue
        at = f"{source}[regimes.{name}]"
        if not isinstance(entry, Mapping):
            raise ConfigError(f"{at} must be a table with 'when' (the reserved keys are "
                              f"{', '.join(_RESERVED)})")
        extra = [k for k in entry if k not in ("when", "use", "why", "description")]
        if extra:
            raise ConfigError(f"{at}: unknown key {extra[0]!r}; allowed: when, use, why, "
                              "description")
        if not name.replace("_", "").replace("-", "").isalnum():
            raise ConfigError(f"{at}: a regime's name holds letters, digits, - and _ only")
        use = entry.get("use", True)
        if not isinstance(use, bool):
            raise ConfigError(f"{at}.use must be true or false, not {use!r}")
        regimes.append(Regime(name, parse_condition(entry.get("when"), at), use,
                              str(entry.get("why", "")), str(entry.get("description", ""))))
    meta = table.get("metadata", [])
    if not isinstance(meta, list) or not all(isinstance(m, str) and m for m in meta):
        raise ConfigError(f"{where}.metadata must be a list of metadata field names")
    return RegimeSpec(tuple(regimes), _seconds(table.get("settle", 0.0), f"{where}.settle"),
                      _seconds(table.get("min_duration", 0.0), f"{where}.min_duration"),
                      tuple(meta))


def regime_key(parameter: str, regime: str) -> str:
    """The history's name of a parameter estimated in a regime: ``Tc@forward``
    (the parameter's own name when the machine declares no regimes).

    Example
    -------
    >>> regime_key("Tc", "forward"), regime_key("R", "")
    ('Tc@forward', 'R')
    """
    return f"{parameter}@{regime}" if regime else parameter


def split_key(key: str) -> tuple[str, str]:
    """``"Tc@forward"`` -> ``("Tc", "forward")``; ``"R"`` -> ``("R", "")``.

    Example
    -------
    >>> split_key("Tc@forward, load=ball")
    ('Tc', 'forward, load=ball')
    """
    name, _, regime = key.partition("@")
    return name, regime
