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
- ``max(a, b)`` → ``(a + b + |a − b|)/2`` and ``min(a, b)`` → ``(a + b − |a − b|)/2``,
  with the smooth ``|·|``.
"""

from __future__ import annotations

import ast
import functools
from collections.abc import Callable, Mapping

import sympy as sp

from condmon.errors import ConfigError

__all__ = ["FUNCTIONS", "NON_SMOOTH", "parse_expression", "smoothed"]

FUNCTIONS: dict[str, Callable[..., sp.Expr]] = {
    "sqrt": sp.sqrt, "abs": sp.Abs, "sign": sp.sign, "exp": sp.exp, "log": sp.log,
    "sin": sp.sin, "cos": sp.cos, "tanh": sp.tanh, "min": sp.Min, "max": sp.Max,
}

NON_SMOOTH = ("sign", "abs", "min", "max")
"""Functions of :data:`FUNCTIONS` with a kink or a jump, smoothed for simulation."""

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
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as err:
        raise ConfigError(f"{prefix}cannot read equation {text!r}: {err.msg}") from None

    def build(node: ast.AST) -> sp.Expr:
        if isinstance(node, ast.Expression):
            return build(node.body)
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) \
                and not isinstance(node.value, bool):
            return sp.Float(node.value) if isinstance(node.value, float) else sp.Integer(node.value)
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

    return build(tree)


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

    def smooth_max(a: sp.Expr, b: sp.Expr) -> sp.Expr:
        return (a + b + smooth_abs(a - b)) / 2

    def smooth_min(a: sp.Expr, b: sp.Expr) -> sp.Expr:
        return (a + b - smooth_abs(a - b)) / 2

    out = expr.replace(sp.Max, lambda *args: functools.reduce(smooth_max, args))
    out = out.replace(sp.Min, lambda *args: functools.reduce(smooth_min, args))
    out = out.replace(sp.sign, lambda a: sp.tanh(a / e))
    out = out.replace(sp.Abs, smooth_abs)
    return out
