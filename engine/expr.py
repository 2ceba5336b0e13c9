"""Safe arithmetic expressions for rule files: numbers, names, + - * / **, min, max.

Parsed once with :mod:`ast` (never ``eval``); unknown names and other syntax
are rejected at load time with a message naming what is allowed. Values are
Python floats, so a division by zero, an overflowing power or a complex result
is an :class:`ExpressionError` saying which, not a silent inf or nan.
"""

from __future__ import annotations

import ast
import math
import operator

_BINARY = {
    ast.Add: operator.add,
    ast.Sub: operator.sub,
    ast.Mult: operator.mul,
    ast.Div: operator.truediv,
    ast.Pow: operator.pow,
}
_FUNCTIONS = {"min": min, "max": max}


class ExpressionError(ValueError):
    pass


def _finite(number) -> bool:
    try:
        return math.isfinite(number)
    except OverflowError:  # an integer too large for a float
        return False


class Expression:
    """A parsed expression over a fixed set of names."""

    def __init__(self, text, names: set[str], where: str | None = None):
        self.text = str(text)
        self.where = where  # file:line:col of the expression, for messages
        if isinstance(text, bool) or not isinstance(text, (int, float, str)):
            raise ExpressionError(f"expected a number or an expression, got {type(text).__name__}")
        if isinstance(text, (int, float)) and not _finite(text):
            raise ExpressionError(f"{text} is not a finite number")
        try:
            self.tree = ast.parse(self.text, mode="eval").body
        except SyntaxError:
            raise ExpressionError(f"'{self.text}' is not a valid expression") from None
        self.names = set()
        self._check(self.tree, names)

    def _check(self, node, names):
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
            if not _finite(node.value):
                raise ExpressionError(f"a number in '{self.text}' is not finite (beyond 1.8e308)")
            return
        if isinstance(node, ast.Name):
            if node.id not in names:
                raise ExpressionError(f"unknown name '{node.id}' in '{self.text}' (known: {', '.join(sorted(names))})")
            self.names.add(node.id)
            return
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            self._check(node.left, names)
            self._check(node.right, names)
            return
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            self._check(node.operand, names)
            return
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Name)
            and node.func.id in _FUNCTIONS
            and node.args
            and not node.keywords
        ):
            for arg in node.args:
                self._check(arg, names)
            return
        raise ExpressionError(f"'{self.text}' uses syntax outside numbers, names, + - * / **, min() and max()")

    def __call__(self, values: dict) -> float:
        """The value at ``values`` (name -> float); ExpressionError if it divides by zero, overflows or is
        not real."""
        try:
            value = self._eval(self.tree, values)
        except ZeroDivisionError:
            raise ExpressionError("divides by zero") from None
        except OverflowError:
            raise ExpressionError("overflows") from None
        return value

    def _eval(self, node, values):
        if isinstance(node, ast.Constant):
            return float(node.value)
        if isinstance(node, ast.Name):
            return float(values[node.id])  # a Python float: numpy's would give inf with a warning, not an error
        if isinstance(node, ast.BinOp):
            value = _BINARY[type(node.op)](self._eval(node.left, values), self._eval(node.right, values))
            if isinstance(value, complex):
                raise ExpressionError("is not a real number (a negative number to a fractional power)")
            return value
        if isinstance(node, ast.UnaryOp):
            value = self._eval(node.operand, values)
            return -value if isinstance(node.op, ast.USub) else value
        args = [self._eval(a, values) for a in node.args]
        result = args[0]
        for arg in args[1:]:
            result = _FUNCTIONS[node.func.id](result, arg)
        return result

    def __repr__(self) -> str:
        return f"Expression({self.text!r})"
