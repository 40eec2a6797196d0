"""Equations of declared models: a safe parser from text to sympy.

The text of an equation comes from a file a user edits, so it is never handed to
``eval`` (which ``sympy.sympify`` uses): it is parsed with :mod:`ast` and only
names, numbers, ``+ - * / **`` and a short list of functions are accepted.

Of those functions, ``sign``, ``abs``, ``min`` and ``max`` are not smooth: a
model using them (Coulomb friction ``Fc*sign(v)``) chatters about the kink and
a variable-step solver crawls there. :func:`smoothed` replaces them, for
simulation only, by smooth approximations of width ``eps`` (the structure of the
equations, used by the fault signature matrix, is unchanged):

- ``sign(x)`` → ``tanh(x/eps)``
- ``abs(x)`` → ``x*tanh(x/eps)``
- ``max(a, b)`` → ``(a + b + √((a − b)² + eps²))/2`` and ``min(a, b)`` →
  ``(a + b − √((a − b)² + eps²))/2``: never below (above) either argument, so
  a guard keeps its sign (``max(x, 0)`` is positive for every x, and
  ``sqrt(max(x, 0))`` finite), at most ``eps/2`` off at the kink.
"""

from __future__ import annotations

import ast
import functools
import math
from collections.abc import Callable, Mapping

import sympy as sp

from condmon.errors import ConfigError
from condmon.models.limits import EquationLimits, equation_limits

__all__ = ["FUNCTIONS", "NON_SMOOTH", "parse_expression", "smoothed", "EquationLimits",
           "equation_limits"]

FUNCTIONS: dict[str, Callable[..., sp.Expr]] = {
    "sqrt": sp.sqrt, "abs": sp.Abs, "sign": sp.sign, "exp": sp.exp, "log": sp.log,
    "sin": sp.sin, "cos": sp.cos, "tanh": sp.tanh, "min": sp.Min, "max": sp.Max,
}

NON_SMOOTH = ("sign", "abs", "min", "max")
"""Functions of :data:`FUNCTIONS` with a kink or a jump, smoothed for simulation."""

def _constant(node: ast.AST) -> float | None:
    """The value of a subtree of numbers only (``-3``, ``1/2``, ``10**10``), or
    None when it holds a name; OverflowError beyond float."""
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) \
            and not isinstance(node.value, bool):
        return float(node.value)
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        v = _constant(node.operand)
        return None if v is None else (-v if isinstance(node.op, ast.USub) else v)
    if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
        a, b = _constant(node.left), _constant(node.right)
        if a is None or b is None:
            return None
        if isinstance(node.op, ast.Div) and b == 0:
            return math.inf
        op = {ast.Add: float.__add__, ast.Sub: float.__sub__, ast.Mult: float.__mul__,
              ast.Div: float.__truediv__, ast.Pow: math.pow}[type(node.op)]
        try:
            return float(op(a, b))
        except ValueError:  # a negative number to a fractional power
            return math.nan
    return None


def _check_limits(tree: ast.AST, text: str, prefix: str, lim: EquationLimits) -> None:
    """Refuse a parsed equation beyond the limits (walked without recursion)."""
    stack: list[tuple[ast.AST, int, int]] = [(tree, 0, 0)]
    while stack:
        node, depth, exps = stack.pop()
        if depth > lim.max_depth:
            raise ConfigError(f"{prefix}the equation is nested deeper than {lim.max_depth} "
                              f"levels ([equations] max_depth of condmon/data/limits.toml)")
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) \
                and not isinstance(node.value, bool) and not abs(node.value) <= lim.max_literal:
            raise ConfigError(f"{prefix}the number {str(node.value)[:20]} is beyond "
                              f"{lim.max_literal:g} ([equations] max_literal)")
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
            try:
                exponent = _constant(node.right)
                whole = _constant(node)
            except OverflowError:
                raise ConfigError(f"{prefix}a power of numbers in {text[:60]!r} is beyond "
                                  f"{lim.max_literal:g} ([equations] max_literal)") from None
            if exponent is None or not abs(exponent) <= lim.max_exponent:
                raise ConfigError(f"{prefix}an exponent must be a number within "
                                  f"±{lim.max_exponent:g} ([equations] max_exponent) in "
                                  f"{text[:60]!r}")
            if whole is not None and not abs(whole) <= lim.max_literal:
                raise ConfigError(f"{prefix}a power of numbers in {text[:60]!r} is beyond "
                                  f"{lim.max_literal:g} ([equations] max_literal)")
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                and node.func.id == "exp":
            exps += 1
            if exps > lim.max_exp_nesting:
                raise ConfigError(f"{prefix}exponentials nested {exps} deep in {text[:60]!r} "
                                  f"(limit {lim.max_exp_nesting}: [equations] max_exp_nesting)")
        for child in ast.iter_child_nodes(node):
            stack.append((child, depth + 1, exps))


_BINARY: dict[type[ast.operator], Callable[[sp.Expr, sp.Expr], sp.Expr]] = {
    ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b,
    ast.Mult: lambda a, b: a * b, ast.Div: lambda a, b: a / b,
    ast.Pow: lambda a, b: a ** b,
}


def parse_expression(text: str, symbols: Mapping[str, sp.Symbol], where: str = "") -> sp.Expr:
    """Parse ``text`` into a sympy expression over ``symbols``.

    Parameters
    ----------
    text : str
        The equation's right-hand side, e.g. ``"Kp*(Dp*omega_p - Q)"``.
    symbols : mapping of str to sympy.Symbol
        The names the equation may use.
    where : str
        Where the text comes from, for error messages (file and key).

    Returns
    -------
    sympy.Expr

    Raises
    ------
    ConfigError
        On a syntax error, an unknown name or function, or any other construct.

    Example
    -------
    >>> x = sp.Symbol("x")
    >>> parse_expression("2*sqrt(abs(x))", {"x": x})
    2*sqrt(Abs(x))
    """
    prefix = f"{where}: " if where else ""
    lim = equation_limits()
    if len(text) > lim.max_length:
        raise ConfigError(f"{prefix}the equation is {len(text)} characters long (limit "
                          f"{lim.max_length}: [equations] max_length of "
                          "condmon/data/limits.toml)")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as err:
        raise ConfigError(f"{prefix}cannot read equation {text[:80]!r}: {err.msg}") from None
    except (RecursionError, MemoryError):
        raise ConfigError(f"{prefix}the equation is nested too deeply to read (limit "
                          f"{lim.max_depth} levels)") from None
    _check_limits(tree, text, prefix, lim)

    def build(node: ast.AST) -> sp.Expr:
        if isinstance(node, ast.Expression):
            return build(node.body)
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) \
                and not isinstance(node.value, bool):
            return sp.Float(node.value) if isinstance(node.value, float) else sp.Integer(node.value)
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
            folded = _constant(node)
            if folded is not None:  # a power of numbers, bounded above: its float value
                return sp.Float(folded)
        if isinstance(node, ast.Name):
            if node.id not in symbols:
                allowed = ", ".join(sorted(symbols))
                raise ConfigError(f"{prefix}unknown name {node.id!r} in {text!r}; "
                                  f"allowed: {allowed}")
            return symbols[node.id]
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            return _BINARY[type(node.op)](build(node.left), build(node.right))
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            arg = build(node.operand)
            return -arg if isinstance(node.op, ast.USub) else arg
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
            if node.func.id not in FUNCTIONS or node.keywords:
                raise ConfigError(f"{prefix}unknown function {node.func.id!r} in {text!r}; "
                                  f"allowed: {', '.join(FUNCTIONS)}")
            return FUNCTIONS[node.func.id](*(build(a) for a in node.args))
        raise ConfigError(f"{prefix}cannot use {ast.unparse(node)!r} in an equation ({text!r})")

    try:
        return build(tree)
    except ConfigError:
        raise
    except (ZeroDivisionError, OverflowError, ValueError) as err:
        raise ConfigError(f"{prefix}cannot evaluate the numbers in {text[:60]!r} "
                          f"({type(err).__name__}: a division by zero?)") from None


def smoothed(expr: sp.Expr, eps: float) -> sp.Expr:
    """``expr`` with its non-smooth functions (:data:`NON_SMOOTH`) regularised.

    Parameters
    ----------
    expr : sympy.Expr
    eps : float
        Width of the regularisation, in the unit of each function's argument;
        0 leaves the expression exact.

    Returns
    -------
    sympy.Expr

    Example
    -------
    >>> v = sp.Symbol("v", real=True)
    >>> smoothed(2*sp.sign(v), 0.01)
    2*tanh(100.0*v)
    """
    if eps == 0:
        return expr
    e = sp.Float(eps)

    def smooth_abs(a: sp.Expr) -> sp.Expr:
        return a * sp.tanh(a / e)

    # max and min from the hyperbolic |d| ≈ √(d² + eps²) ≥ |d|: the tanh form,
    # d·tanh(d/eps) ≤ |d|, made max(x, 0) negative for every x < 0
    def smooth_max(a: sp.Expr, b: sp.Expr) -> sp.Expr:
        return (a + b + sp.sqrt((a - b) ** 2 + e ** 2)) / 2

    def smooth_min(a: sp.Expr, b: sp.Expr) -> sp.Expr:
        return (a + b - sp.sqrt((a - b) ** 2 + e ** 2)) / 2

    out = expr.replace(sp.Max, lambda *args: functools.reduce(smooth_max, args))
    out = out.replace(sp.Min, lambda *args: functools.reduce(smooth_min, args))
    out = out.replace(sp.sign, lambda a: sp.tanh(a / e))
    out = out.replace(sp.Abs, smooth_abs)
    return out
