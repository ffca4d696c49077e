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

# Bounds on one expression. Python's parser and sympy recurse, and the third derivative of a product of
# n time-dependent factors has ~n^3/6 terms (10 sine factors: 1.4 s in sympy, 20: 46 s), so size is capped
# well above any motion written by hand, below what takes more than a few seconds to differentiate.
MAX_LENGTH = 1000          # characters
MAX_DEPTH = 64             # nesting of operators and calls
MAX_CALL_DEPTH = 8         # functions of functions (sin(sin(...)))
MAX_NODES = 256            # operators, calls, names and numbers
MAX_TIME_USES = 16         # occurrences of t
MAX_EXPONENT = 1000        # |p| in (expression of t)**p
_UNARY = {ast.USub: "-", ast.UAdd: "+"}


def _describe(node: ast.AST) -> str:
    try:
        return ast.unparse(node)
    except Exception:  # pragma: no cover - unparse handles every node the parser produces
        return type(node).__name__


def check(text: str, where: str, names: Mapping[str, float] | set[str]) -> ast.Expression:
    """Parse `text` and verify it uses only numbers, the given names, t, pi, e and whitelisted functions,
    within the size bounds above.

    `where` names the scene key (e.g. "trajectory.x") so the error points at it. With the params' values
    (a mapping), every time-free part is also evaluated once: complex, undefined or overflowing constants
    are refused here, by key and part, instead of reaching sympy or the kernel.
    """
    if not isinstance(text, (str, int, float)) or isinstance(text, bool):
        raise SceneError(f"{where}: expected an expression string or a number, got {type(text).__name__}")
    source = str(text)
    if "^" in source:
        raise SceneError(f"{where}: '^' is not a power operator here; write '**' (in {source!r})")
    if len(source) > MAX_LENGTH:
        raise SceneError(f"{where}: expression is {len(source)} characters long; the limit is {MAX_LENGTH}")
    try:
        tree = ast.parse(source.strip(), mode="eval")
    except SyntaxError as exc:
        raise SceneError(f"{where}: syntax error in {source!r} at column {exc.offset}: {exc.msg}") from None
    except (RecursionError, MemoryError, ValueError):
        raise SceneError(f"{where}: expression nested too deeply to parse (limit: depth {MAX_DEPTH})") from None
    _check_size(tree, where)
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
    if isinstance(names, Mapping):
        _constant_parts(tree.body, names, where, source)
    return tree


def _check_size(tree: ast.Expression, where: str) -> None:
    """Depth, call nesting, node and t counts within the MAX_* bounds (iteratively: nothing recurses
    before the depth is known to be small)."""
    nodes = uses = 0
    stack = [(tree.body, 1, 0)]
    while stack:
        node, depth, calls = stack.pop()
        nodes += 1
        calls += isinstance(node, ast.Call)
        uses += isinstance(node, ast.Name) and node.id == TIME
        for limit, value, what in ((MAX_DEPTH, depth, "nested"), (MAX_CALL_DEPTH, calls, "function calls nested"),
                                   (MAX_NODES, nodes, "terms"), (MAX_TIME_USES, uses, "uses of t")):
            if value > limit:
                raise SceneError(f"{where}: expression too large: more than {limit} {what} "
                                 f"(limit {limit}; split it with [params] or simplify it)")
        stack.extend((child, depth + 1, calls) for child in ast.iter_child_nodes(node)
                     if not isinstance(child, (ast.expr_context, ast.operator, ast.unaryop)))


def _float_call(fn: str, args):
    return ({"abs": abs}.get(fn) or getattr(math, fn))(*args)


def _constant_parts(node: ast.AST, values: Mapping[str, float], where: str, source: str):
    """The float value of a time-free subtree, None where it depends on t; SceneError for a part that is
    complex, outside a function's domain, a division by zero or beyond float range. Floats only: an exact
    power such as 10**10**10 is refused in microseconds instead of being computed by sympy for ever."""
    def fail(part, reason):
        raise SceneError(f"{where}: {_describe(part)} {reason} (in {source!r})")

    if isinstance(node, ast.Constant):
        try:
            value = float(node.value)
        except OverflowError:
            fail(node, "is beyond the float range")
        if not math.isfinite(value):
            fail(node, "is beyond the float range")
        return value
    if isinstance(node, ast.Name):
        if node.id == TIME:
            return None
        return values[node.id] if node.id in values else CONSTANTS.get(node.id)
    if isinstance(node, ast.UnaryOp):
        operand = _constant_parts(node.operand, values, where, source)
        return None if operand is None else (-operand if isinstance(node.op, ast.USub) else operand)
    if isinstance(node, ast.BinOp):
        a = _constant_parts(node.left, values, where, source)
        b = _constant_parts(node.right, values, where, source)
        if isinstance(node.op, ast.Pow):
            if a is not None and a < 0 and b is None:
                fail(node, "is complex for most t (a negative base to a power that depends on t)")
            if a is None and b is not None and abs(b) > MAX_EXPONENT:
                fail(node, f"has an exponent beyond +-{MAX_EXPONENT}")
        if a is None or b is None:
            return None
        op = type(node.op)
        try:
            value = a + b if op is ast.Add else a - b if op is ast.Sub else a * b if op is ast.Mult \
                else a / b if op is ast.Div else a ** b
        except ZeroDivisionError:
            fail(node, "divides by zero")
        except OverflowError:
            fail(node, "is beyond the float range")
    elif isinstance(node, ast.Call):
        args = [_constant_parts(arg, values, where, source) for arg in node.args]
        if any(arg is None for arg in args):
            return None
        try:
            value = _float_call(node.func.id, args)
        except ValueError:
            fail(node, f"is outside the domain of {node.func.id} (no real value)")
        except OverflowError:
            fail(node, "is beyond the float range")
    else:  # pragma: no cover - check() admits no other node
        raise AssertionError(f"unchecked node {node!r}")
    if isinstance(value, complex):
        fail(node, "is complex (a negative number to a fractional power)")
    if not math.isfinite(value):
        fail(node, "is beyond the float range")
    return value


def uses_time(tree: ast.Expression) -> bool:
    return any(isinstance(n, ast.Name) and n.id == TIME for n in ast.walk(tree))


# Which numbers of an expression the kernel takes at run time ("lifted": a parameter slot, so scenes differing
# only in them share a kernel) and which stay literals of its source (keyed), decided on the tree alone (no sympy):
# - a number in the argument of sin, cos or tan that is linear in t (A t + B) stays: the kernel reduces such a
#   phase exactly from A and B at 50 digits (imu_emulator.motion.phases), which needs their values when the
#   source is generated. Attitude angles, latitude and longitude are such arguments themselves (the kernel takes
#   their cos and sin): `phase` says the whole expression is one.
# - an exponent stays (t**2 differentiates to 2*t and prints as a multiplication; t**c would be pow() calls);
# - a zero stays, and a time-free part that is zero (as an effect's zero removes its line, and t/0 or t/(2 - 2) is
#   refused when generated, not at run time), and a time-free function call (tan(pi/2) is refused, sqrt(4) is 2);
# - pi and e stay (the same in every scene), and so does a time-free part holding pi (pi/2, 2*pi/3): sympy's
#   exact identities need it (sin(pi/2 - x) is cos(x), the same operations as the scene written the other way,
#   so an ENU and a NED version of one attitude give the same bits). Every other number, and every [params]
#   value, is lifted.
_CONST, _LINEAR, _OTHER = 0, 1, 2
PHASE_FUNCTIONS = ("sin", "cos", "tan")


def _degree(node: ast.AST) -> int:
    """Whether a checked subtree is constant, linear in t or neither, from its form (t*t - t*t counts as
    neither: a phase sympy would find linear then only loses the exact reduction, never correctness)."""
    if isinstance(node, ast.Constant):
        return _CONST
    if isinstance(node, ast.Name):
        return _LINEAR if node.id == TIME else _CONST
    if isinstance(node, ast.UnaryOp):
        return _degree(node.operand)
    if isinstance(node, ast.Call):
        return _CONST if all(_degree(a) == _CONST for a in node.args) else _OTHER
    a, b = _degree(node.left), _degree(node.right)
    op = type(node.op)
    if op in (ast.Add, ast.Sub):
        return max(a, b)
    if op is ast.Mult and min(a, b) == _CONST or op is ast.Div and b == _CONST:
        return a if op is ast.Div else max(a, b)
    return _CONST if a == b == _CONST else _OTHER


def _is_number(node: ast.AST, params) -> bool:
    return isinstance(node, ast.Constant) or isinstance(node, ast.Name) and node.id in params


def _fold(tree: ast.Expression, constant, name, call, lift=None):
    """Evaluate a checked tree; the caller supplies what numbers, names and function calls become, and
    + - * / ** work on whatever those are (floats, or sympy objects). `lift`: (params, phase, lifted): the numbers
    and params the rule above lifts become lifted(value, i), i counting them in this walk's order."""
    count = 0

    def number(value, keep):
        nonlocal count
        if lift is None or keep or float(value) == 0.0:
            return constant(value)
        count += 1
        return lift[2](float(value), count - 1)

    def walk(node, keep):
        if isinstance(node, ast.Expression):
            return walk(node.body, keep)
        if isinstance(node, ast.Constant):
            return number(node.value, keep)
        if isinstance(node, ast.Name):
            if lift is not None and node.id in lift[0]:
                return number(lift[0][node.id], keep)
            return name(node.id)
        if isinstance(node, ast.UnaryOp):
            if lift is not None and not keep and _is_number(node.operand, lift[0]):
                value = node.operand.value if isinstance(node.operand, ast.Constant) else lift[0][node.operand.id]
                return number(-value if isinstance(node.op, ast.USub) else value, keep)   # the sign is the value's
            operand = walk(node.operand, keep)
            return -operand if isinstance(node.op, ast.USub) else operand
        if lift is not None and not keep and isinstance(node, (ast.BinOp, ast.Call)) and _degree(node) == _CONST:
            # a time-free call (tan(pi/2): sympy's zoo, refused when generated) or a time-free zero (t/(2 - 2))
            keep = (isinstance(node, ast.Call) or _constant_parts(node, lift[0], "", "") == 0.0
                    or any(isinstance(n, ast.Name) and n.id == "pi" for n in ast.walk(node)))
        if isinstance(node, ast.BinOp):
            op = type(node.op)
            a, b = walk(node.left, keep), walk(node.right, keep or op is ast.Pow)
            return a + b if op is ast.Add else a - b if op is ast.Sub else a * b if op is ast.Mult \
                else a / b if op is ast.Div else a ** b
        if isinstance(node, ast.Call):
            phase = node.func.id in PHASE_FUNCTIONS
            return call(node.func.id, [walk(a, keep or phase and _degree(a) == _LINEAR) for a in node.args])
        raise AssertionError(f"unchecked node {node!r}")  # check() guarantees we never get here

    body = tree.body if isinstance(tree, ast.Expression) else tree
    return walk(tree, lift is not None and lift[1] and _degree(body) == _LINEAR)


def lift(tree: ast.Expression, params: Mapping[str, float], phase: bool) -> tuple[str, list[float]]:
    """The expression's structure and its lifted numbers (the rule above; `phase`: the kernel takes the cos and
    sin of the whole expression). The structure is the text with each lifted number as `c` and every kept one as
    the repr of its value: what the kernel cache keys on. No sympy."""
    values: list[float] = []

    def lifted(value, i):
        values.append(value)
        return _Code("c")

    def call(fn, args):
        return _Code(f"{fn}(" + ", ".join(args) + ")")
    structure = _fold(tree, lambda v: _Code(repr(v)), _Code, call, lift=(params, phase, lifted))
    return str(structure), values


def evaluate_constant(tree: ast.Expression, values: Mapping[str, float], where: str) -> float:
    """Evaluate a time-free expression numerically (for params defined from other params)."""
    try:
        value = _fold(tree, float, lambda n: values[n] if n in values else CONSTANTS[n], _float_call)
    except (ArithmeticError, ValueError) as exc:
        raise SceneError(f"{where}: {exc}") from None
    if isinstance(value, complex):
        raise SceneError(f"{where}: evaluates to the complex number {value}")
    if not math.isfinite(value):
        raise SceneError(f"{where}: evaluates to {value}")
    return value


def to_sympy(tree: ast.Expression, params: Mapping[str, float], t_symbol, lifted=None, phase: bool = False):
    """Translate a checked tree into a sympy expression; params become exact binary floats. `lifted`: names of
    the symbols the lifted numbers (lift, with `phase`) become, in their order; None: every number a literal."""
    import sympy

    def constant(value):
        return sympy.Integer(value) if isinstance(value, int) else sympy.Float(value, 17)

    def name(n):
        if n == TIME:
            return t_symbol
        if n in params:
            return sympy.Float(params[n], 17)
        return sympy.pi if n == "pi" else sympy.E

    rule = None if lifted is None else (params, phase, lambda value, i: sympy.Symbol(lifted[i], real=True))
    return _fold(tree, constant, name, lambda fn, args: getattr(sympy, FUNCTIONS[fn][0])(*args), lift=rule)


def drop_impulses(expr):
    """The derivative away from kinks and steps: DiracDelta (d/dt sign(t)) and the unevaluated d/dt of sign(u(t))
    sympy leaves when u is not t itself (abs(log(t) - 1) twice differentiated) are zero except at isolated
    instants, where a sampled signal never lands exactly."""
    import sympy
    return expr.replace(sympy.DiracDelta, lambda *a: sympy.Integer(0)).replace(
        lambda e: isinstance(e, sympy.Derivative) and isinstance(e.expr, sympy.sign), lambda e: sympy.Integer(0))


def check_symbolic(expr, where: str, source: str, what: str = "its value") -> None:
    """SceneError when sympy's form of an expression (or a derivative: `what`) is not a real finite
    function of t: complex (I), undefined (nan) or infinite (oo, zoo) -- e.g. tan(pi/2) = zoo, or t/(t - t).
    Such a value would otherwise be printed into the kernel as a name numba does not know."""
    import sympy
    for atom, reason in ((sympy.zoo, "is infinite"), (sympy.oo, "is infinite"), (sympy.nan, "is undefined"),
                         (sympy.I, "is complex")):
        if expr.has(atom) or expr.has(-atom):
            raise SceneError(f"{where}: {what} {reason} for every t (in {source!r})")
    unevaluated = drop_impulses(expr).atoms(sympy.Derivative)
    if unevaluated:
        # the kernel printer has no form for a derivative sympy could not take
        raise SceneError(f"{where}: {what} has no closed form ({min(map(str, unevaluated))} stays unevaluated; "
                         f"in {source!r})")


class _Code(str):
    """Source text of a checked expression, built by _fold: operators give parenthesized source."""
    def _op(self, other, op, reverse=False):
        a, b = (other, self) if reverse else (self, other)
        return _Code(f"({a} {op} {b})")

    __add__ = lambda self, o: self._op(o, "+")          # noqa: E731
    __sub__ = lambda self, o: self._op(o, "-")          # noqa: E731
    __mul__ = lambda self, o: self._op(o, "*")          # noqa: E731
    __truediv__ = lambda self, o: self._op(o, "/")      # noqa: E731
    __pow__ = lambda self, o: self._op(o, "**")         # noqa: E731
    __neg__ = lambda self: _Code(f"(-{self})")          # noqa: E731
    __pos__ = lambda self: self                         # noqa: E731


_NUMPY_NAMES = {"asin": "arcsin", "acos": "arccos", "atan": "arctan", "atan2": "arctan2", "abs": "abs"}


def to_code(tree: ast.Expression, params: Mapping[str, float]) -> str:
    """Python source (math module, variable t) of a checked tree: numbers as repr of floats, names of the
    whitelist only, so no user text reaches generated code."""
    def name(n):
        if n == TIME:
            return _Code("t")
        return _Code(repr(float(params[n] if n in params else CONSTANTS[n])))

    def call(fn, args):
        return _Code(("abs" if fn == "abs" else f"math.{fn}") + "(" + ", ".join(args) + ")")
    return str(_fold(tree, lambda v: _Code(repr(float(v))), name, call))


def evaluate_array(tree: ast.Expression, params: Mapping[str, float], t):
    """Evaluate a checked tree at the times t (numpy array) with numpy."""
    import numpy as np

    def name(n):
        return t if n == TIME else float(params[n] if n in params else CONSTANTS[n])
    value = _fold(tree, float, name, lambda fn, args: getattr(np, _NUMPY_NAMES.get(fn, fn))(*args))
    return np.broadcast_to(np.asarray(value, dtype=float), np.shape(t))
