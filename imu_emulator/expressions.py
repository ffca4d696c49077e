"""Safe parsing of the user's motion expressions.

User text is never handed to eval or sympify (both execute code). It is parsed with `ast`, every node
is checked against a whitelist, and the tree is translated into sympy objects by hand. Validation
needs no sympy, so a run whose compiled kernel is already cached never imports it.
"""
from __future__ import annotations

import ast
import math
from typing import Mapping

from imu_emulator.errors import SceneError

# name in expressions -> (sympy attribute, number of arguments)
FUNCTIONS = {
    "sin": ("sin", 1), "cos": ("cos", 1), "tan": ("tan", 1),
    "asin": ("asin", 1), "acos": ("acos", 1), "atan": ("atan", 1), "atan2": ("atan2", 2),
    "sinh": ("sinh", 1), "cosh": ("cosh", 1), "tanh": ("tanh", 1),
    "exp": ("exp", 1), "log": ("log", 1), "sqrt": ("sqrt", 1), "abs": ("Abs", 1),
}
CONSTANTS = {"pi": math.pi, "e": math.e}
TIME = "t"

_BINOPS = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**"}
_UNARY = {ast.USub: "-", ast.UAdd: "+"}


def _describe(node: ast.AST) -> str:
    try:
        return ast.unparse(node)
    except Exception:  # pragma: no cover - unparse handles every node the parser produces
        return type(node).__name__


def check(text: str, where: str, names: set[str]) -> ast.Expression:
    """Parse `text` and verify it uses only numbers, the given names, t, pi, e and whitelisted functions.

    `where` names the scene key (e.g. "trajectory.x") so the error points at it.
    """
    if not isinstance(text, (str, int, float)) or isinstance(text, bool):
        raise SceneError(f"{where}: expected an expression string or a number, got {type(text).__name__}")
    source = str(text)
    if "^" in source:
        raise SceneError(f"{where}: '^' is not a power operator here; write '**' (in {source!r})")
    try:
        tree = ast.parse(source.strip(), mode="eval")
    except SyntaxError as exc:
        raise SceneError(f"{where}: syntax error in {source!r} at column {exc.offset}: {exc.msg}") from None
    called = {id(n.func) for n in ast.walk(tree) if isinstance(n, ast.Call)}
    for node in ast.walk(tree):
        if isinstance(node, (ast.Expression, ast.Load)) or type(node) in _BINOPS or type(node) in _UNARY:
            continue
        if isinstance(node, ast.BinOp):
            if type(node.op) not in _BINOPS:
                raise SceneError(f"{where}: operator not allowed in {source!r}: {_describe(node)}")
        elif isinstance(node, ast.UnaryOp):
            if type(node.op) not in _UNARY:
                raise SceneError(f"{where}: operator not allowed in {source!r}: {_describe(node)}")
        elif isinstance(node, ast.Constant):
            if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
                raise SceneError(f"{where}: only numbers are allowed as literals, not {node.value!r}")
        elif isinstance(node, ast.Name):
            if node.id in FUNCTIONS and id(node) not in called and node.id not in names:
                raise SceneError(f"{where}: function '{node.id}' used without arguments in {source!r}")
            if node.id not in names and node.id not in CONSTANTS and node.id != TIME and node.id not in FUNCTIONS:
                raise SceneError(f"{where}: unknown name '{node.id}' in {source!r} "
                                 f"(known: t, pi, e, params {sorted(names) or '[]'}, functions {sorted(FUNCTIONS)})")
        elif isinstance(node, ast.Call):
            if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
                raise SceneError(f"{where}: unknown function '{_describe(node.func)}' in {source!r} "
                                 f"(allowed: {', '.join(sorted(FUNCTIONS))})")
            if node.keywords:
                raise SceneError(f"{where}: keyword arguments are not allowed in {source!r}")
            wanted = FUNCTIONS[node.func.id][1]
            if len(node.args) != wanted:
                raise SceneError(f"{where}: {node.func.id} takes {wanted} argument(s), got {len(node.args)}")
        else:
            raise SceneError(f"{where}: not allowed in an expression: {_describe(node)!r} in {source!r}")
    return tree


def uses_time(tree: ast.Expression) -> bool:
    return any(isinstance(n, ast.Name) and n.id == TIME for n in ast.walk(tree))


def _fold(tree: ast.Expression, constant, name, call):
    """Evaluate a checked tree; the caller supplies what numbers, names and function calls become, and
    + - * / ** work on whatever those are (floats, or sympy objects)."""
    def walk(node):
        if isinstance(node, ast.Expression):
            return walk(node.body)
        if isinstance(node, ast.Constant):
            return constant(node.value)
        if isinstance(node, ast.Name):
            return name(node.id)
        if isinstance(node, ast.UnaryOp):
            operand = walk(node.operand)
            return -operand if isinstance(node.op, ast.USub) else operand
        if isinstance(node, ast.BinOp):
            a, b = walk(node.left), walk(node.right)
            op = type(node.op)
            return a + b if op is ast.Add else a - b if op is ast.Sub else a * b if op is ast.Mult \
                else a / b if op is ast.Div else a ** b
        if isinstance(node, ast.Call):
            return call(node.func.id, [walk(a) for a in node.args])
        raise AssertionError(f"unchecked node {node!r}")  # check() guarantees we never get here

    return walk(tree)


def evaluate_constant(tree: ast.Expression, values: Mapping[str, float], where: str) -> float:
    """Evaluate a time-free expression numerically (for params defined from other params)."""
    def call(fn, args):
        return ({"abs": abs}.get(fn) or getattr(math, fn))(*args)
    try:
        value = float(_fold(tree, float, lambda n: values[n] if n in values else CONSTANTS[n], call))
    except (ArithmeticError, ValueError) as exc:
        raise SceneError(f"{where}: {exc}") from None
    if not math.isfinite(value):
        raise SceneError(f"{where}: evaluates to {value}")
    return value


def to_sympy(tree: ast.Expression, params: Mapping[str, float], t_symbol):
    """Translate a checked tree into a sympy expression; params become exact binary floats."""
    import sympy

    def constant(value):
        return sympy.Integer(value) if isinstance(value, int) else sympy.Float(value, 17)

    def name(n):
        if n == TIME:
            return t_symbol
        if n in params:
            return sympy.Float(params[n], 17)
        return sympy.pi if n == "pi" else sympy.E

    return _fold(tree, constant, name, lambda fn, args: getattr(sympy, FUNCTIONS[fn][0])(*args))
