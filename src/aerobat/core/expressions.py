"""Arithmetic expressions in maneuver files, parsed safely (no ``eval``) and compiled once.

The language is ordinary arithmetic on floats:

* numbers (``1.5``, ``2e-3``), names (parameters ``p0``…, constants, derived quantities,
  vehicle constants), ``+ - * / **``, unary minus, parentheses;
* functions ``sqrt``, ``sin``, ``cos``, ``tan``, ``atan2``, ``abs``, ``min``, ``max``,
  ``radians``, ``degrees``, ``exp``, ``log``, and the constant ``pi``.

Anything else — attribute access, subscripts, calls of other names, comparisons,
strings — is refused with a message that points at the offending text. Expressions are
parsed with Python's :mod:`ast` in ``eval`` mode and only the node types above are
accepted; the result is compiled into nested closures, so evaluating one is a handful of
Python calls.
"""

from __future__ import annotations

import ast
import math
import operator
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from aerobat.errors import ConfigError

__all__ = ["ARITY", "Expression", "FUNCTIONS", "parse_expression"]

FUNCTIONS: dict[str, Callable[..., float]] = {
    "sqrt": math.sqrt, "sin": math.sin, "cos": math.cos, "tan": math.tan, "atan2": math.atan2,
    "abs": abs, "min": min, "max": max, "radians": math.radians, "degrees": math.degrees, "exp": math.exp,
    "log": math.log,
}
ARITY: dict[str, tuple[int, int | None]] = {
    name: (1, 1) for name in ("sqrt", "sin", "cos", "tan", "abs", "radians", "degrees", "exp", "log")
} | {"atan2": (2, 2), "min": (2, None), "max": (2, None)}
"""How many arguments each function takes: (at least, at most; None: any number)."""
_CONSTANTS = {"pi": math.pi}


def _power(base: float, exponent: float) -> float:
    """``base ** exponent`` on reals: a negative base with a fractional exponent is an error, never complex."""
    if base < 0.0 and exponent != math.floor(exponent):
        raise ValueError(f"{base:g} ** {exponent:g}: a negative number to a fractional power has no real value")
    return math.pow(base, exponent)


_BINARY = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
           ast.Pow: _power}

Scope = Mapping[str, float]


@dataclass(frozen=True)
class Expression:
    """A parsed expression: its text, the names it reads, and ``evaluate(scope) -> float``."""

    text: str
    names: frozenset[str]
    _fn: Callable[[Scope], float]

    def evaluate(self, scope: Scope, *, where: str = "") -> float:
        """The value with ``scope`` giving every name; :class:`ConfigError` if it is not a finite number."""
        try:
            value = float(self._fn(scope))
        except KeyError as exc:
            raise ConfigError(f"{where}: {self.text!r}: unknown name {exc.args[0]!r}") from None
        except (ZeroDivisionError, OverflowError, ValueError) as exc:
            raise ConfigError(f"{where}: {self.text!r} cannot be evaluated here: {exc}") from None
        if not math.isfinite(value):
            raise ConfigError(f"{where}: {self.text!r} evaluates to {value}")
        return value

    @property
    def constant(self) -> bool:
        return not self.names


def parse_expression(value: object, *, where: str, known: frozenset[str] | None = None) -> Expression:
    """An :class:`Expression` from a TOML value (a number or a string of arithmetic).

    Parameters
    ----------
    value : a number, or a string such as ``"0.5 * (beta_max + beta_min)"``.
    where : the file and field, for messages (``"hop.toml: stages[2].duration_s"``).
    known : if given, every name must be one of these (else :class:`ConfigError` naming it).
    """
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        raise ConfigError(f"{where}: expected a number or an expression in quotes, got {type(value).__name__} "
                          f"{value!r}")
    if not isinstance(value, str):
        try:
            number = float(value)
        except OverflowError:
            raise ConfigError(f"{where}: {short_number(value)} is too large for a float") from None
        if not math.isfinite(number):
            raise ConfigError(f"{where}: {value} is not finite")
        return Expression(repr(number), frozenset(), lambda scope: number)
    text = value.strip()
    if not text:
        raise ConfigError(f"{where}: empty expression")
    if len(text) > 500:
        raise ConfigError(f"{where}: expression longer than 500 characters")
    try:
        tree = ast.parse(text, mode="eval")
    except SyntaxError as exc:
        column = (exc.offset or 1) - 1
        raise ConfigError(f"{where}: {text!r}: invalid expression at column {column + 1}: "
                          f"{_printable(text[:column])}⟨here⟩{_printable(text[column:])}") from None
    names: set[str] = set()
    fn = _compile(tree.body, text, where, names, depth=0)
    unknown = sorted(names - set(known)) if known is not None else []
    if unknown:
        raise ConfigError(f"{where}: {text!r}: unknown name(s) {', '.join(unknown)}; known: "
                          f"{', '.join(sorted(known or ()))}")
    return Expression(text, frozenset(names), fn)


def short_number(value: object) -> str:
    """A number's text, its middle left out if it is long (a 400-digit integer in a message)."""
    text = str(value)
    return text if len(text) <= 24 else f"{text[:10]}…{text[-6:]} ({len(text)} digits)"


def _printable(text: str) -> str:
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode() for c in text)


def _refuse(node: ast.AST, text: str, where: str, what: str) -> ConfigError:
    column = getattr(node, "col_offset", 0)
    segment = ast.get_source_segment(text, node) or text
    return ConfigError(f"{where}: {text!r}: {what} ({segment!r} at column {column + 1}); allowed: numbers, names, "
                       f"+ - * / **, parentheses and {', '.join(sorted(FUNCTIONS))}, pi")


def _compile(node: ast.AST, text: str, where: str, names: set[str], depth: int) -> Callable[[Scope], float]:
    if depth > 50:
        raise _refuse(node, text, where, "nested too deeply")
    if isinstance(node, ast.Constant):
        if isinstance(node.value, bool) or not isinstance(node.value, int | float):
            raise _refuse(node, text, where, "only numbers are allowed as literals")
        try:
            number = float(node.value)
        except OverflowError:
            raise _refuse(node, text, where, f"{short_number(node.value)} is too large for a float") from None
        if not math.isfinite(number):
            raise _refuse(node, text, where, "the number is not finite (too large for a float)")
        return lambda scope: number
    if isinstance(node, ast.Name):
        name = node.id
        if name in _CONSTANTS:
            constant = _CONSTANTS[name]
            return lambda scope: constant
        if name in FUNCTIONS:
            raise _refuse(node, text, where, f"{name} is a function: call it as {name}(…)")
        names.add(name)
        return lambda scope: scope[name]
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
        inner = _compile(node.operand, text, where, names, depth + 1)
        if isinstance(node.op, ast.USub):
            return lambda scope: -inner(scope)
        return inner
    if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
        op = _BINARY[type(node.op)]
        left = _compile(node.left, text, where, names, depth + 1)
        right = _compile(node.right, text, where, names, depth + 1)
        return lambda scope: op(left(scope), right(scope))
    if isinstance(node, ast.Call):
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
            raise _refuse(node, text, where, "unknown function")
        if node.keywords or not node.args:
            raise _refuse(node, text, where, "functions take positional arguments")
        name = node.func.id
        low, high = ARITY[name]
        count = len(node.args)
        if count < low or (high is not None and count > high):
            wanted = (f"{low}" if low == high else f"at least {low}" if high is None else f"{low} to {high}")
            raise _refuse(node, text, where, f"{name} takes {wanted} argument{'' if wanted == '1' else 's'}, "
                                             f"got {count}")
        function = FUNCTIONS[name]
        args = [_compile(a, text, where, names, depth + 1) for a in node.args]
        return lambda scope: function(*(a(scope) for a in args))
    raise _refuse(node, text, where, f"{type(node).__name__} is not allowed")
