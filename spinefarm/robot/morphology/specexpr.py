"""Safe arithmetic for spec files: numbers, names bound by the loader (i, k, n, pi), + - * / // % **,
parentheses and a few math functions. Anything else is refused, so a spec file cannot run code."""

from __future__ import annotations

import ast
import math
import operator

_BINARY = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
           ast.FloorDiv: operator.floordiv, ast.Mod: operator.mod, ast.Pow: operator.pow}
_UNARY = {ast.USub: operator.neg, ast.UAdd: operator.pos}
FUNCTIONS = {"sqrt": math.sqrt, "sin": math.sin, "cos": math.cos, "tan": math.tan, "radians": math.radians,
             "round": round, "abs": abs}
CONSTANTS = {"pi": math.pi}


class ExpressionError(ValueError):
    """An expression uses something outside the allowed grammar or an unbound name."""


def evaluate(text: str, names: dict[str, float]) -> float:
    """Value of `text` with the given names bound (plus pi and FUNCTIONS)."""
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        raise ExpressionError(f"not an arithmetic expression: {text!r}") from exc
    scope = {**CONSTANTS, **names}

    def ev(node: ast.AST) -> float:
        if isinstance(node, ast.Expression):
            return ev(node.body)
        if isinstance(node, ast.Constant) and isinstance(node.value, int | float) \
                and not isinstance(node.value, bool):
            return node.value
        if isinstance(node, ast.Name):
            if node.id not in scope:
                raise ExpressionError(f"unknown name {node.id!r} in {text!r}; "
                                      f"available: {sorted(scope)}")
            return scope[node.id]
        if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
            return _BINARY[type(node.op)](ev(node.left), ev(node.right))
        if isinstance(node, ast.UnaryOp) and type(node.op) in _UNARY:
            return _UNARY[type(node.op)](ev(node.operand))
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in FUNCTIONS \
                and not node.keywords:
            return FUNCTIONS[node.func.id](*(ev(a) for a in node.args))
        raise ExpressionError(f"{type(node).__name__} is not allowed in {text!r}; "
                              f"use numbers, {sorted(scope)}, + - * / // % ** and {sorted(FUNCTIONS)}")

    try:
        return ev(tree)
    except (ZeroDivisionError, OverflowError, TypeError) as exc:
        raise ExpressionError(f"{text!r} cannot be evaluated: {exc}") from exc
