"""The coefficient-form language: safe parser, expression trees, and the compiler to the
stack-machine program of :mod:`cadra.aero.program` (the numpy reference evaluator and the
finite checks: :mod:`cadra.aero.evaluate`; nesting limits: :mod:`cadra.aero.nesting`).

Expressions are parsed with ``ast.parse(text, mode="eval")`` and a whitelist visitor: nothing of
the user's text is ever executed. The language (docs/aero_models.md):

- numbers; the constant ``pi``; the variables of :data:`cadra.aero.program.VARIABLES`
  (``alpha, beta, sigma, mach, reynolds, p_hat, q_hat, r_hat, phi``; angles in radians);
  parameters (any other name the model declares);
- ``+ - * / **``, unary ``-`` and ``+``, parentheses;
- functions ``sin cos tan asin acos atan atan2 sqrt abs exp log``, ``min``/``max``
  (two or more arguments);
- comparisons ``< > <= >=`` (1.0 or 0.0, on real parts);
- piecewise: ``where(cond, a, b)`` (``a`` where ``cond`` is nonzero, else ``b``), Python's
  ``a if cond else b`` (the same), and ``piecewise(c1, v1, c2, v2, ..., default)`` (the first
  ``v_i`` whose ``c_i`` is nonzero).

Trees are nested tuples, hashable and comparable: ``("num", 1.5)``, ``("var", "alpha")``,
``("par", "Cm_A1")``, ``("neg", x)``, ``("add"|"sub"|"mul"|"div"|"pow", a, b)``,
``(fn, x)`` for the one-argument functions, ``("atan2", y, x)``, ``("max"|"min", a, b)``,
``("lt"|"gt"|"le"|"ge", a, b)``, ``("where", c, a, b)``; :func:`simplify` adds ``("sqr", x)`` and
``("powc", x, c)``.
"""

from __future__ import annotations

import ast
import math
import re
from collections.abc import Collection, Mapping, Sequence

import numpy as np

from cadra.aero import program as P
from cadra.aero.evaluate import evaluate_tree  # noqa: F401 (re-exported: the reference)
from cadra.aero.nesting import MAX_DEPTH, ast_depth, deep_recursion
from cadra.aero.program import COEFFICIENTS, VARIABLES, AeroProgram

#: one-argument functions
UNARY_FUNCTIONS = ("sin", "cos", "tan", "asin", "acos", "atan", "sqrt", "abs", "exp", "log")
#: every callable name -> (min args, max args or None)
FUNCTIONS = {
    **{f: (1, 1) for f in UNARY_FUNCTIONS},
    "atan2": (2, 2),
    "min": (2, None),
    "max": (2, None),
    "where": (3, 3),
    "piecewise": (3, None),
}
#: named constants
CONSTANTS = {"pi": math.pi}
#: names a parameter may not take
RESERVED = frozenset(VARIABLES) | frozenset(FUNCTIONS) | frozenset(CONSTANTS)
NAME_RE = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")
MAX_LENGTH = 20000

_BINOPS = {ast.Add: "add", ast.Sub: "sub", ast.Mult: "mul", ast.Div: "div", ast.Pow: "pow"}
_CMPOPS = {ast.Lt: "lt", ast.Gt: "gt", ast.LtE: "le", ast.GtE: "ge"}
_OP_SYMBOLS = {ast.FloorDiv: "//", ast.Mod: "%", ast.MatMult: "@", ast.BitAnd: "&",
               ast.BitOr: "|", ast.LShift: "<<", ast.RShift: ">>"}
_FORBIDDEN = {
    ast.Attribute: "attribute access",
    ast.Subscript: "subscripts (indexing)",
    ast.Slice: "slices",
    ast.Lambda: "lambda",
    ast.JoinedStr: "f-strings",
    ast.FormattedValue: "f-strings",
    ast.List: "list literals",
    ast.Tuple: "tuples",
    ast.Set: "set literals",
    ast.Dict: "dict literals",
    ast.ListComp: "comprehensions",
    ast.SetComp: "comprehensions",
    ast.DictComp: "comprehensions",
    ast.GeneratorExp: "generator expressions",
    ast.BoolOp: "'and'/'or' (multiply 0/1 conditions, or nest where())",
    ast.NamedExpr: "assignment expressions",
    ast.Starred: "starred arguments",
    ast.Await: "await",
    ast.Yield: "yield",
    ast.YieldFrom: "yield",
}


class ExpressionError(ValueError):
    """A coefficient form that does not parse or uses something not allowed.

    Attributes: ``context`` (e.g. ``"coefficients.Cm"``), ``text``, ``line`` and ``column``
    (1-based; 0 when the error has no position).
    """

    def __init__(self, message: str, text: str = "", offset: int | None = None,
                 context: str = "expression"):
        self.context = context
        self.text = text
        self.reason = message
        self.offset = offset
        if offset is None:
            self.line = self.column = 0
            full = f"{context}: {message}"
        else:
            offset = max(0, min(offset, len(text)))
            before = text[:offset]
            self.line = before.count("\n") + 1
            self.column = offset - (before.rfind("\n") + 1) + 1
            src = text.splitlines()[self.line - 1] if text.splitlines() else ""
            full = (f"{context}: {message} (line {self.line}, column {self.column})\n"
                    f"    {src}\n    {' ' * (self.column - 1)}^")
        super().__init__(full)

    def prefixed(self, prefix: str) -> ExpressionError:
        """The same error with ``prefix`` put before its context (e.g. a file name)."""
        return ExpressionError(self.reason, self.text, self.offset, f"{prefix}: {self.context}")


# --- parsing -------------------------------------------------------------------------------


def parse_expression(text: str, parameters: Collection[str] | None = None, *,
                     context: str = "expression") -> tuple:
    """Parse ``text`` into a validated expression tree.

    Parameters
    ----------
    text : the form, e.g. ``"Cm_A1*(sin(alpha) - sin(alpha_ref))"``; may span lines.
    parameters : names the model declares; any other non-variable name is an error. ``None``
        accepts every valid name as a parameter.
    context : prefix of error messages (e.g. ``"coefficients.Cm"``).

    Raises
    ------
    ExpressionError
        bad syntax, disallowed construct or undeclared name; the message names it and points
        at its line and column.
    """
    if not isinstance(text, str):
        raise ExpressionError(f"expected a string, got {type(text).__name__}", context=context)
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"expression longer than {MAX_LENGTH} characters", context=context)
    for i, ch in enumerate(text):
        if ord(ch) > 127:
            raise ExpressionError(f"non-ASCII character {ch!r} (write names in ASCII, e.g. "
                                  "alpha)", text, i, context)
        if ch == "#":
            raise ExpressionError("comments ('#') are not allowed inside an expression",
                                  text, i, context)
        if ch == "\0":
            raise ExpressionError("NUL character", text, i, context)
    if not text.strip():
        raise ExpressionError("empty expression", context=context)
    # one logical line with the same character offsets, so ast positions map back to text
    flat = text.replace("\r", " ").replace("\n", " ").replace("\t", " ")
    shift = len(flat) - len(flat.lstrip())  # leading blanks would be an "indent"
    deep = ExpressionError(f"expression nested more than {MAX_DEPTH} levels deep (a sum of "
                           f"more than {MAX_DEPTH} terms, or as many signs or brackets)",
                           context=context)
    try:
        with deep_recursion():
            tree = ast.parse(flat[shift:], mode="eval")
            if ast_depth(tree.body) > MAX_DEPTH:
                raise deep
            return _Builder(text, parameters, context, shift).visit(tree.body)
    except SyntaxError as exc:
        off = (exc.offset - 1 + shift) if exc.offset else None
        raise ExpressionError(f"syntax error: {exc.msg}", text, off, context) from None
    except (RecursionError, MemoryError):
        raise deep from None


class _Builder:
    def __init__(self, text, parameters, context, shift):
        self.text = text
        self.parameters = None if parameters is None else frozenset(parameters)
        self.context = context
        self.shift = shift

    def error(self, node, message):
        col = getattr(node, "col_offset", None)
        return ExpressionError(message, self.text, None if col is None else col + self.shift,
                               self.context)

    def visit(self, node) -> tuple:
        if isinstance(node, ast.Constant):
            v = node.value
            if isinstance(v, bool) or v is None or v is Ellipsis:
                raise self.error(node, f"{v!r} is not allowed (numbers only)")
            if isinstance(v, str | bytes):
                raise self.error(node, "strings are not allowed")
            if isinstance(v, complex):
                raise self.error(node, "complex literals are not allowed")
            if isinstance(v, int | float):
                if isinstance(v, int) and abs(v) > 2**1023:
                    raise self.error(node, f"integer of {len(str(v))} digits is too large "
                                           "for a float64")
                if not math.isfinite(v):
                    raise self.error(node, "number too large for a float64 (it is inf)")
                return ("num", float(v))
            raise self.error(node, f"constant {v!r} is not allowed")
        if isinstance(node, ast.Name):
            return self.name(node)
        if isinstance(node, ast.BinOp):
            op = _BINOPS.get(type(node.op))
            if op is None:
                if isinstance(node.op, ast.BitXor):
                    raise self.error(node, "'^' is not allowed; use ** for powers")
                sym = _OP_SYMBOLS.get(type(node.op), type(node.op).__name__)
                raise self.error(node, f"operator '{sym}' is not allowed")
            return (op, self.visit(node.left), self.visit(node.right))
        if isinstance(node, ast.UnaryOp):
            if isinstance(node.op, ast.USub):
                return ("neg", self.visit(node.operand))
            if isinstance(node.op, ast.UAdd):
                return self.visit(node.operand)
            raise self.error(node, "operator 'not' / '~' is not allowed")
        if isinstance(node, ast.Compare):
            if len(node.ops) != 1:
                raise self.error(node, "chained comparisons are not allowed (nest where())")
            op = _CMPOPS.get(type(node.ops[0]))
            if op is None:
                raise self.error(node, "only < > <= >= comparisons are allowed")
            return (op, self.visit(node.left), self.visit(node.comparators[0]))
        if isinstance(node, ast.IfExp):
            return ("where", self.visit(node.test), self.visit(node.body),
                    self.visit(node.orelse))
        if isinstance(node, ast.Call):
            return self.call(node)
        what = _FORBIDDEN.get(type(node), type(node).__name__)
        raise self.error(node, f"{what} not allowed")

    def name(self, node) -> tuple:
        n = node.id
        if not NAME_RE.match(n):
            raise self.error(node, f"invalid name {n!r} (names start with a letter and contain "
                                   "letters, digits and '_')")
        if n in VARIABLES:
            return ("var", n)
        if n in CONSTANTS:
            return ("num", CONSTANTS[n])
        if n in FUNCTIONS:
            raise self.error(node, f"function {n!r} used without a call")
        if self.parameters is not None and n not in self.parameters:
            raise self.error(node, f"undeclared name {n!r} (not a variable, function or "
                                   "declared parameter)")
        return ("par", n)

    def call(self, node) -> tuple:
        f = node.func
        if not isinstance(f, ast.Name):
            what = "attribute access" if isinstance(f, ast.Attribute) else "this call"
            raise self.error(node, f"{what} not allowed (only the functions "
                                   f"{', '.join(FUNCTIONS)})")
        name = f.id
        if name not in FUNCTIONS:
            raise self.error(node, f"unknown function {name!r} (allowed: "
                                   f"{', '.join(FUNCTIONS)})")
        if node.keywords:
            raise self.error(node, f"{name}(): keyword arguments are not allowed")
        for a in node.args:
            if isinstance(a, ast.Starred):
                raise self.error(a, "starred arguments not allowed")
        lo, hi = FUNCTIONS[name]
        n = len(node.args)
        if n < lo or (hi is not None and n > hi):
            want = f"{lo}" if lo == hi else (f"at least {lo}" if hi is None else f"{lo}-{hi}")
            raise self.error(node, f"{name}() takes {want} argument(s), got {n}")
        args = [self.visit(a) for a in node.args]
        if name in UNARY_FUNCTIONS:
            return (name, args[0])
        if name == "atan2":
            return ("atan2", args[0], args[1])
        if name in ("min", "max"):
            out = args[0]
            for a in args[1:]:
                out = (name, out, a)
            return out
        if name == "where":
            return ("where", args[0], args[1], args[2])
        # piecewise(c1, v1, c2, v2, ..., default)
        if n % 2 == 0:
            raise self.error(node, "piecewise() takes condition/value pairs and a default "
                                   "(an odd number of arguments)")
        out = args[-1]
        for k in range(n - 3, -1, -2):
            out = ("where", args[k], args[k + 1], out)
        return out


# --- tree utilities ------------------------------------------------------------------------


def children(node: tuple) -> tuple:
    """The sub-expressions of ``node``."""
    tag = node[0]
    if tag in ("num", "var", "par"):
        return ()
    if tag == "powc":
        return (node[1],)
    return node[1:]


def parameter_names(node: tuple) -> set[str]:
    """Names of the parameters ``node`` uses."""
    out: set[str] = set()
    stack = [node]
    while stack:
        n = stack.pop()
        if n[0] == "par":
            out.add(n[1])
        else:
            stack.extend(children(n))
    return out


_PREC = {"where": 0, "lt": 1, "gt": 1, "le": 1, "ge": 1, "add": 2, "sub": 2, "mul": 3,
         "div": 3, "neg": 4, "pow": 5}
_SYM = {"add": "+", "sub": "-", "mul": "*", "div": "/", "pow": "**", "lt": "<", "gt": ">",
        "le": "<=", "ge": ">="}


def to_text(node: tuple) -> str:
    """Expression text of a tree; ``parse_expression(to_text(t)) == t`` for parsed trees."""
    with deep_recursion():
        return _text(node)


def _text(node: tuple) -> str:
    tag = node[0]
    if tag == "num":
        v = node[1]
        return repr(v) if v >= 0 or math.isnan(v) else f"({v!r})"
    if tag in ("var", "par"):
        return node[1]
    if tag == "neg":
        inner = _text(node[1])
        return f"-{_wrap(inner, node[1], 4, right=False)}"
    if tag in _SYM:
        p = _PREC[tag]
        a = _wrap(_text(node[1]), node[1], p, right=(tag == "pow"))
        b = _wrap(_text(node[2]), node[2], p, right=(tag != "pow"))
        return f"{a} {_SYM[tag]} {b}"
    if tag == "sqr":
        return f"{_wrap(_text(node[1]), node[1], 5, right=True)} ** 2"
    if tag == "powc":
        return f"{_wrap(_text(node[1]), node[1], 5, right=True)} ** {node[2]!r}"
    return f"{tag}({', '.join([_text(c) for c in node[1:]])})"


def _wrap(text, node, parent_prec, right):
    p = _PREC.get(node[0], 9)
    if node[0] in ("sqr", "powc"):
        p = 5
    if node[0] == "num" and node[1] < 0:
        return text
    if p < parent_prec or (p == parent_prec and right):
        return f"({text})"
    return text


# --- simplification (compile-time) ---------------------------------------------------------

_FOLD_UNARY = {"neg": lambda x: -x, "sin": math.sin, "cos": math.cos, "tan": math.tan,
               "asin": math.asin, "acos": math.acos, "atan": math.atan, "sqrt": math.sqrt,
               "abs": abs, "exp": math.exp, "log": math.log, "sqr": lambda x: x * x}
_FOLD_BINARY = {"add": lambda a, b: a + b, "sub": lambda a, b: a - b,
                "mul": lambda a, b: a * b, "div": lambda a, b: a / b,
                "pow": lambda a, b: a**b, "atan2": math.atan2,
                "max": lambda a, b: a if a > b else b, "min": lambda a, b: a if a < b else b,
                "lt": lambda a, b: float(a < b), "gt": lambda a, b: float(a > b),
                "le": lambda a, b: float(a <= b), "ge": lambda a, b: float(a >= b)}


def _int_power(x: tuple, n: int) -> tuple:
    """x**n (n >= 1) as a tree of squares and products (exposes common subexpressions)."""
    if n == 1:
        return x
    if n % 2 == 0:
        return ("sqr", _int_power(x, n // 2))
    return ("mul", _int_power(x, n - 1), x)


def simplify(node: tuple) -> tuple:
    """Fold constants, turn integer powers into squares/products, ``x**0.5`` into ``sqrt``."""
    with deep_recursion():
        return _simplify(node)


def _simplify(node: tuple) -> tuple:
    tag = node[0]
    if tag in ("num", "var", "par"):
        return node
    if tag == "powc":
        kids = (_simplify(node[1]),)
    else:
        kids = tuple([_simplify(c) for c in node[1:]])
    if all(k[0] == "num" for k in kids) and tag != "powc":
        vals = [k[1] for k in kids]
        try:
            if tag in _FOLD_UNARY:
                v = _FOLD_UNARY[tag](vals[0])
            elif tag in _FOLD_BINARY:
                v = _FOLD_BINARY[tag](*vals)
            elif tag == "where":
                v = vals[1] if vals[0] != 0 else vals[2]
            else:  # pragma: no cover - every tag is listed above
                v = None
            if isinstance(v, float | int) and not isinstance(v, bool):
                return ("num", float(v))
        except (ArithmeticError, ValueError):
            pass  # leave it to run time (inf / nan)
    if tag == "neg" and kids[0][0] == "neg":
        return kids[0][1]
    if tag == "pow" and kids[1][0] == "num":
        x, e = kids[0], kids[1][1]
        if e == int(e) and abs(e) <= 64:
            n = int(e)
            if n == 0:
                return ("num", 1.0)
            p = _int_power(x, abs(n))
            return p if n > 0 else ("div", ("num", 1.0), p)
        if e == 0.5:
            return ("sqrt", x)
        return ("powc", x, e)
    if tag == "powc":
        return ("powc", kids[0], node[2])
    return (tag, *kids)


# --- compiler ------------------------------------------------------------------------------

_UNARY_OPS = {"neg": P.NEG, "sqr": P.SQR, "sin": P.SIN, "cos": P.COS, "tan": P.TAN,
              "asin": P.ASIN, "acos": P.ACOS, "atan": P.ATAN, "sqrt": P.SQRT, "abs": P.ABS,
              "exp": P.EXP, "log": P.LOG}
_FUSED_BASE = {"push": P.PUSH_C, "add": P.ADD_C, "sub": P.SUB_C, "rsub": P.RSUB_C,
               "mul": P.MUL_C, "div": P.DIV_C, "rdiv": P.RDIV_C, "max": P.MAX_C,
               "min": P.MIN_C}
_STACK_OPS = {"add": P.ADD, "sub": P.SUB, "mul": P.MUL, "div": P.DIV, "pow": P.POW,
              "atan2": P.ATAN2, "max": P.MAX, "min": P.MIN, "lt": P.LT, "gt": P.GT,
              "le": P.LE, "ge": P.GE}
_COMMUTATIVE = ("add", "mul", "max", "min")
_EXPENSIVE = frozenset(("sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sqrt", "exp",
                        "log", "pow", "powc", "div"))
_SRC = {"num": 0, "var": 1, "par": 2}


class _Compiler:
    """Code generator: accumulator machine with fused operand ops (docs/aero_models.md)."""

    def __init__(self, param_names: Sequence[str], temps: dict):
        self.pindex = {n: i for i, n in enumerate(param_names)}
        self.temps = temps
        self.defining: tuple | None = None
        self.ops: list[int] = []
        self.args: list[float] = []
        self.depth = 0
        self.max_depth = 0
        self._need: dict[tuple, int] = {}

    def operand(self, node):
        """(source, arg) when ``node`` is a leaf or a temporary (other than the one being
        defined), else None. Sources: 0 C, 1 V, 2 P, 3 T."""
        if node in self.temps and node != self.defining:
            return 3, float(self.temps[node])
        tag = node[0]
        if tag == "num":
            return 0, node[1]
        if tag == "var":
            return 1, float(VARIABLES.index(node[1]))
        if tag == "par":
            return 2, float(self.pindex[node[1]])
        return None

    def pair(self, node):
        """(k, packed args) when ``node`` is a product of two V/P/T operands, else None."""
        if node[0] != "mul" or node in self.temps and node != self.defining:
            return None
        ox, oy = self.operand(node[1]), self.operand(node[2])
        if ox is None or oy is None or ox[0] == 0 or oy[0] == 0:
            return None
        return 3 * (ox[0] - 1) + (oy[0] - 1), ox[1] + oy[1] * P.PAIR

    def emit(self, op, arg=0.0, ddepth=0):
        self.ops.append(int(op))
        self.args.append(float(arg))
        self.depth += ddepth
        self.max_depth = max(self.max_depth, self.depth)

    def fused(self, kind, operand):
        src, arg = operand
        self.emit(_FUSED_BASE[kind] + src, arg, 1 if kind == "push" else 0)

    def need(self, node) -> int:
        """Stack slots needed to evaluate ``node`` (a dry run of :meth:`gen`)."""
        if node not in self._need:
            saved = (self.ops, self.args, self.depth, self.max_depth)
            self.ops, self.args, self.depth, self.max_depth = [], [], 0, 0
            self.gen(node)
            self._need[node] = self.max_depth
            self.ops, self.args, self.depth, self.max_depth = saved
        return self._need[node]

    def gen(self, node):
        """Emit code leaving the value of ``node`` in the accumulator (one push)."""
        o = self.operand(node)
        if o is not None:
            self.fused("push", o)
            return
        pr = self.pair(node)
        if pr is not None:
            self.emit(P.PMUL_VV + pr[0], pr[1], 1)
            return
        tag = node[0]
        if tag in _UNARY_OPS:
            self.gen(node[1])
            self.emit(_UNARY_OPS[tag])
            return
        if tag == "powc":
            self.gen(node[1])
            self.emit(P.POW_C, node[2])
            return
        if tag == "where":
            for k in node[1:]:
                self.gen(k)
            self.emit(P.SELECT, 0.0, -2)
            return
        a, b = node[1], node[2]
        if tag in _COMMUTATIVE or tag in ("sub", "div"):
            ob, oa = self.operand(b), self.operand(a)
            if ob is not None:
                self.gen(a)
                self.fused(tag, ob)
                return
            if oa is not None:
                self.gen(b)
                self.fused(tag if tag in _COMMUTATIVE else "r" + tag, oa)
                return
            if tag == "add":
                pb, pa = self.pair(b), self.pair(a)
                if pb is not None:
                    self.gen(a)
                    self.emit(P.AMUL_VV + pb[0], pb[1])
                    return
                if pa is not None:
                    self.gen(b)
                    self.emit(P.AMUL_VV + pa[0], pa[1])
                    return
            if tag in _COMMUTATIVE and self.need(b) > self.need(a):
                a, b = b, a
        self.gen(a)
        self.gen(b)
        self.emit(_STACK_OPS[tag], 0.0, -1)


def _cost(node, temps, memo) -> float:
    """Rough cost of computing ``node`` inline, temporaries counting as loads."""
    if node[0] in ("num", "var", "par") or node in temps:
        return 1.0
    if node in memo:
        return memo[node]
    c = (8.0 if node[0] in _EXPENSIVE else 1.0) + sum([_cost(k, temps, memo)
                                                       for k in children(node)])
    memo[node] = c
    return c


def compile_program(forms: Mapping[str, tuple], param_names: Sequence[str],
                    angle_plane: str, moment_reference: str = "cg") -> AeroProgram:
    """Compile expression trees (coefficient name -> tree) into an :class:`AeroProgram`.

    Missing coefficients and forms that fold to 0 get empty programs. Sub-expressions used
    more than once anywhere in the model (and worth it) are computed once, in the prelude.
    """
    with deep_recursion():
        return _compile(forms, param_names, angle_plane, moment_reference)


def _compile(forms, param_names, angle_plane, moment_reference) -> AeroProgram:
    for k in forms:
        if k not in COEFFICIENTS:
            raise ValueError(f"coefficients.{k}: unknown coefficient (expected one of "
                             f"{', '.join(COEFFICIENTS)})")
    roots = {}
    for k in COEFFICIENTS:
        if k in forms:
            t = _simplify(forms[k])
            if t != ("num", 0.0):
                roots[k] = t
    # references to each unique sub-expression (a DAG of the whole model)
    uses: dict[tuple, int] = {}
    order: list[tuple] = []  # post-order of unique nodes

    def visit(node):
        stack = [(node, False)]
        while stack:
            n, done = stack.pop()
            if done:
                order.append(n)
                continue
            uses[n] = uses.get(n, 0) + 1
            if uses[n] == 1:
                stack.append((n, True))
                for c in reversed(children(n)):
                    stack.append((c, False))

    for t in roots.values():
        visit(t)
    temps: dict[tuple, int] = {}
    memo: dict[tuple, float] = {}
    for n in order:  # children before parents
        if n[0] in ("num", "var", "par") or uses[n] < 2:
            continue
        c = _cost(n, temps, memo)
        u = uses[n]
        if (u - 1) * c > u + 1:
            temps[n] = len(temps)
            memo.clear()
    comp = _Compiler(param_names, temps)
    comp.emit(P.HEADER, P.PROGRAM_FORMAT)
    for n, slot in temps.items():
        comp.defining = n
        comp.gen(n)
        comp.defining = None
        comp.emit(P.STORE_T, slot, -1)
    starts = [len(comp.ops)]
    for k in COEFFICIENTS:
        if k in roots:
            comp.gen(roots[k])
            comp.emit(P.OUT, COEFFICIENTS.index(k), -1)
        starts.append(len(comp.ops))
    assert comp.depth == 0
    return AeroProgram(
        ops=np.array(comp.ops, dtype=np.int64),
        args=np.array(comp.args, dtype=np.float64),
        starts=np.array(starts, dtype=np.int64),
        stack_size=max(comp.max_depth + len(temps), 1),
        param_names=tuple(param_names),
        angle_plane=angle_plane,
        moment_reference=moment_reference,
        n_temps=len(temps),
    )
