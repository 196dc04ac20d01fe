"""Forward-mode automatic differentiation of CADRA's compiled scalar code, by source transform.

The equations of motion, the aero-model interpreter and the integrator are written once, as
plain scalar numba code (:mod:`cadra.dynamics.eom`, :mod:`cadra.aero.program`,
:mod:`cadra.dynamics.integrate`). This module reads that source and writes its *tangent*
version: the same statements, in the same order and with the same branches (every branch is
decided on the primal values, as complex step decides on real parts), each followed by the
chain rule of the statement for all derivative lanes at once::

    c = a * b            ->    _v1 = a * b
                               for _j in range(_L):
                                   c_t[_j] = b * a_t[_j] + a * b_t[_j]
                               c = _v1

Every *active* value (one that depends on what is differentiated) gets a tangent: a scalar
``a`` the lane vector ``a_t`` (``_L``,), an array ``A`` the array ``A_t`` with a trailing
lane axis. The primal statements are untouched, so the primal values are those of the float
code to the last bit, and the lanes share them: a run with ``L`` lanes costs one float run
plus a few multiply-adds a lane and statement, where complex step costs ``L`` complex runs.

What it handles is what that code uses: assignments (also to array elements, augmented and
tuple ones), ``if``/``for``/``while``, ``+ - * / **``, unary minus, conditional expressions,
numpy's ``sqrt exp log sin cos tan arctan arcsin arccos``, the interpreter's ``_div _max _min
_atan2`` helpers, calls of other transformed functions (tangents passed alongside), array
allocations, and returns. Anything else that touches an active value is refused with the
statement named, so the tangent code is never silently wrong. The check is complex step: the
tests compare every lane with it (docs/fitting.md, "Sensitivities").
"""

from __future__ import annotations

import ast
import inspect
import textwrap
from dataclasses import dataclass, field

#: d(value)/d(argument) of the supported numpy functions; ``a`` the argument, ``v`` the value
_UNARY = {
    "sqrt": "0.5 / {v}",
    "exp": "{v}",
    "log": "1.0 / {a}",
    "sin": "np.cos({a})",
    "cos": "-np.sin({a})",
    "tan": "1.0 + {v} * {v}",
    "arctan": "1.0 / (1.0 + {a} * {a})",
    "arcsin": "1.0 / np.sqrt(1.0 - {a} * {a})",
    "arccos": "-1.0 / np.sqrt(1.0 - {a} * {a})",
}
#: allocations: a tangent of the same shape plus the lane axis
_ALLOC = ("empty", "zeros", "ones")
#: helpers (of the aero interpreter) whose partials the transform knows:
#: name -> (partial wrt the first argument, partial wrt the second), of ``a``, ``b``, ``v``
_BINARY_HELPERS = {
    "_div": ("1.0 / {b}", "-{v} / {b}"),
    "_atan2": ("{b} / ({a} * {a} + {b} * {b})", "-{a} / ({a} * {a} + {b} * {b})"),
    "_max": ("_sel_first_max({a}, {b})", "_sel_second_max({a}, {b})"),
    "_min": ("_sel_first_min({a}, {b})", "_sel_second_min({a}, {b})"),
}

#: the selection weights of ``_max``/``_min`` (decided on real parts; NaN: the sum, both 1)
PRELUDE = '''
@njit(cache=True, inline="always")
def _sel_first_max(a, b):
    return 0.0 if a.real <= b.real else 1.0


@njit(cache=True, inline="always")
def _sel_second_max(a, b):
    return 0.0 if a.real > b.real else 1.0


@njit(cache=True, inline="always")
def _sel_first_min(a, b):
    return 0.0 if a.real >= b.real else 1.0


@njit(cache=True, inline="always")
def _sel_second_min(a, b):
    return 0.0 if a.real < b.real else 1.0
'''


class TransformError(ValueError):
    """The source uses something the transform does not differentiate."""


@dataclass(frozen=True)
class Spec:
    """What to transform in one function.

    ``active``: its parameters that carry derivatives, each ``"s"`` (scalar), ``"a"`` (array)
    or ``"t"`` (tuple of arrays). ``returns``: the kinds of its return values when they carry
    derivatives (``()``: it returns nothing active). ``jit``: keyword arguments of the tangent
    function's ``njit``.
    """

    func: object
    active: dict
    returns: tuple = ()
    jit: dict = field(default_factory=lambda: {"cache": True, "error_model": "numpy"})


def tangent_name(name: str) -> str:
    return f"{name}_t"


class _Function:
    """The transform of one function (see :func:`tangent_module`)."""

    def __init__(self, spec: Spec, specs: dict, passive=()):
        self.spec = spec
        self.specs = specs                      # name -> Spec of every transformed function
        self.passive = frozenset(passive)       # functions whose results carry no derivative
        src = textwrap.dedent(inspect.getsource(spec.func))
        self.tree = ast.parse(src).body[0]
        self.name = self.tree.name
        self.params = [a.arg for a in self.tree.args.args]
        for p in spec.active:
            if p not in self.params:
                raise TransformError(f"{self.name}: no parameter {p!r}")
        self.kind = dict(spec.active)           # active name -> "s" | "a" | "t"
        self.counter = 0
        self.arities: set[int] = set()          # lane kernels used
        self.lines: list[str] = []
        self._activity()

    # --- activity ------------------------------------------------------------------------

    def _is_active_expr(self, node) -> bool:
        for n in ast.walk(node):
            if isinstance(n, (ast.Attribute, ast.Compare)):
                continue
            if isinstance(n, ast.Name) and n.id in self.kind:
                if not self._under_inactive(node, n):
                    return True
            if isinstance(n, ast.Call) and isinstance(n.func, ast.Name) \
                    and n.func.id in self.specs and self.specs[n.func.id].returns:
                return True
        return False

    def _under_inactive(self, root, target) -> bool:
        """Whether ``target`` sits under an attribute (``.real``, ``.shape``), a comparison,
        ``int(...)`` or a subscript's index inside ``root``: no derivative flows from there."""
        parents = {}
        for n in ast.walk(root):
            for c in ast.iter_child_nodes(n):
                parents[c] = n
        n = target
        while n in parents:
            p = parents[n]
            if isinstance(p, (ast.Attribute, ast.Compare)):
                return True
            if isinstance(p, ast.Call) and isinstance(p.func, ast.Name) \
                    and (p.func.id in ("int", "len", "range", "abs", "max", "min")
                         or p.func.id in self.passive):
                return True
            if isinstance(p, ast.Call) and isinstance(p.func, ast.Attribute) \
                    and p.func.attr in ("isfinite", "ceil", "floor"):
                return True
            if isinstance(p, ast.Subscript) and n is p.slice:
                return True
            if isinstance(p, ast.IfExp) and n is p.test:
                return True
            n = p
        return False

    def _local_kind(self, value) -> str:
        if isinstance(value, ast.Call) and isinstance(value.func, ast.Attribute) \
                and value.func.attr in _ALLOC:
            return "a"
        if isinstance(value, ast.Tuple) and value.elts and all(
                self._local_kind(e) == "a" for e in value.elts):
            return "t"
        return "s"

    def _activity(self):
        """Mark the locals that carry derivatives, to a fixed point."""
        body = self.tree.body
        returned = set()
        if self.spec.returns:
            for n in ast.walk(self.tree):
                if isinstance(n, ast.Return) and n.value is not None:
                    vals = n.value.elts if isinstance(n.value, ast.Tuple) else [n.value]
                    for v, k in zip(vals, self.spec.returns, strict=True):
                        if isinstance(v, ast.Name) and v.id not in self.params:
                            returned.add((v.id, k))
        changed = True
        for name, k in returned:
            self.kind.setdefault(name, k)
        while changed:
            changed = False
            for n in ast.walk(ast.Module(body=body, type_ignores=[])):
                marks = []
                if isinstance(n, ast.Assign):
                    value, targets = n.value, n.targets
                    call = self._call_spec(value)
                    for t in targets:
                        if isinstance(t, ast.Tuple) and call is not None and call.returns:
                            marks += [(e.id, k) for e, k in zip(t.elts, call.returns,
                                                                strict=True)
                                      if isinstance(e, ast.Name)]
                        elif isinstance(t, ast.Tuple) and isinstance(value, ast.Name) \
                                and self.kind.get(value.id) == "t":
                            marks += [(e.id, "a") for e in t.elts]
                        elif isinstance(t, ast.Tuple) and isinstance(value, ast.Tuple):
                            marks += [(e.id, self._local_kind(v))
                                      for e, v in zip(t.elts, value.elts, strict=True)
                                      if isinstance(e, ast.Name)
                                      and self._is_active_expr(v)]
                        elif isinstance(t, ast.Name) and self._is_active_expr(value):
                            marks.append((t.id, self._local_kind(value)))
                        elif isinstance(t, ast.Subscript) and isinstance(t.value, ast.Name) \
                                and self._is_active_expr(value):
                            marks.append((t.value.id, "a"))
                elif isinstance(n, ast.AugAssign):
                    t = n.target
                    if self._is_active_expr(n.value) or self._is_active_expr(
                            t.value if isinstance(t, ast.Subscript) else t):
                        base = t.value if isinstance(t, ast.Subscript) else t
                        if isinstance(base, ast.Name):
                            marks.append((base.id, "a" if isinstance(t, ast.Subscript)
                                          else "s"))
                elif isinstance(n, ast.Call):
                    spec = self._call_spec(n)
                    if spec is not None:
                        cparams = _params(spec.func)
                        for a, p in zip(n.args, cparams, strict=False):
                            if p in spec.active and isinstance(a, ast.Name) \
                                    and spec.active[p] != "s":
                                marks.append((a.id, spec.active[p]))
                for name, k in marks:
                    if name not in self.kind:
                        if name in self.params:
                            raise TransformError(
                                f"{self.name}: parameter {name!r} receives derivatives but "
                                "is not declared active")
                        self.kind[name] = k
                        changed = True

    def _call_spec(self, node):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
            return self.specs.get(node.func.id)
        return None

    # --- emission ------------------------------------------------------------------------

    def tmp(self, prefix="_v") -> str:
        self.counter += 1
        return f"{prefix}{self.counter}"

    def emit(self, line: str, indent: int):
        self.lines.append("    " * indent + line)

    def tangent_ref(self, node) -> str | None:
        """Source of the tangent of an active leaf (name or array element), without the lane
        index: ``a_t`` or ``R_t[i, 0`` (the caller closes it with ``, _j]``)."""
        if isinstance(node, ast.Name) and node.id in self.kind:
            return tangent_name(node.id)
        if isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name) \
                and node.value.id in self.kind:
            return f"{tangent_name(node.value.id)}[{_index(node.slice)}"
        return None

    def diff(self, node, indent) -> tuple[str, list[tuple[str, str]]]:
        """(value source, [(coefficient source, tangent ref)]) of an expression; the value of
        an active subexpression is stored in a temporary first."""
        if not self._is_active_expr(node):
            return ast.unparse(node), []
        ref = self.tangent_ref(node)
        if ref is not None:
            return ast.unparse(node), [("1.0", ref)]
        if isinstance(node, ast.BinOp):
            a, ta = self.diff(node.left, indent)
            b, tb = self.diff(node.right, indent)
            op = node.op
            sym = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/",
                   ast.Pow: "**"}.get(type(op))
            if sym is None:
                raise TransformError(f"{self.name}: operator {ast.unparse(node)!r}")
            v = self.tmp()
            self.emit(f"{v} = {a} {sym} {b}", indent)
            if sym == "+":
                terms = ta + tb
            elif sym == "-":
                terms = ta + [(f"-({c})", r) for c, r in tb]
            elif sym == "*":
                terms = self.scale(ta, b, indent) + self.scale(tb, a, indent)
            elif sym == "/":
                terms = self.scale(ta, f"1.0 / {b}", indent) + self.scale(
                    tb, f"-{v} / {b}", indent)
            else:
                terms = self.scale(ta, f"{b} * {a} ** ({b} - 1.0)", indent)
                if tb:
                    terms += self.scale(tb, f"{v} * np.log({a})", indent)
            return v, terms
        if isinstance(node, ast.UnaryOp):
            a, ta = self.diff(node.operand, indent)
            if isinstance(node.op, ast.USub):
                v = self.tmp()
                self.emit(f"{v} = -{a}", indent)
                return v, [(f"-({c})", r) for c, r in ta]
            if isinstance(node.op, ast.UAdd):
                return a, ta
            raise TransformError(f"{self.name}: operator {ast.unparse(node)!r}")
        if isinstance(node, ast.IfExp):
            t = self.tmp("_c")
            self.emit(f"{t} = {ast.unparse(node.test)}", indent)
            a, ta = self.diff(node.body, indent)
            b, tb = self.diff(node.orelse, indent)
            v = self.tmp()
            self.emit(f"{v} = {a} if {t} else {b}", indent)
            return v, ([(f"(({c}) if {t} else 0.0)", r) for c, r in ta]
                       + [(f"(0.0 if {t} else ({c}))", r) for c, r in tb])
        if isinstance(node, ast.Call):
            f = node.func
            if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) \
                    and f.value.id == "np" and f.attr in _UNARY and len(node.args) == 1:
                a, ta = self.diff(node.args[0], indent)
                v = self.tmp()
                self.emit(f"{v} = np.{f.attr}({a})", indent)
                return v, self.scale(ta, _UNARY[f.attr].format(a=a, v=v), indent)
            if isinstance(f, ast.Name) and f.id in _BINARY_HELPERS and len(node.args) == 2:
                a, ta = self.diff(node.args[0], indent)
                b, tb = self.diff(node.args[1], indent)
                v = self.tmp()
                self.emit(f"{v} = {f.id}({a}, {b})", indent)
                da, db = _BINARY_HELPERS[f.id]
                return v, (self.scale(ta, da.format(a=a, b=b, v=v), indent)
                           + self.scale(tb, db.format(a=a, b=b, v=v), indent))
        raise TransformError(f"{self.name}: cannot differentiate {ast.unparse(node)!r}")

    def scale(self, terms, factor: str, indent) -> list[tuple[str, str]]:
        if not terms:
            return []
        c = self.tmp("_d")
        self.emit(f"{c} = {factor}", indent)
        return [(c if t == "1.0" else f"{t} * {c}", r) for t, r in terms]

    def assign_tangent(self, target_ref: str, terms, indent):
        """``target_t = sum of coefficient * leaf tangent`` for every lane, by one call of the
        lane kernel ``_lin<n>`` (:func:`lane_kernel`): one call statement where a loop would
        make numba type and lower a loop (compile time)."""
        merged: dict[str, list[str]] = {}
        for c, r in terms:
            merged.setdefault(r, []).append(c)
        args = [self.view(target_ref)]
        for r, cs in merged.items():
            coef = cs[0] if len(cs) == 1 else " + ".join(cs)
            if not (coef.isidentifier() or coef == "1.0"):
                k = self.tmp("_k")
                self.emit(f"{k} = {coef}", indent)
                coef = k
            args += [coef, self.view(r)]
        self.arities.add(len(merged))
        self.emit(f"_lin{len(merged)}({', '.join(args)})", indent)

    @staticmethod
    def view(ref: str) -> str:
        """The lane vector of a tangent reference (``a_t``, ``R_t[i, 0]``)."""
        return ref if "[" not in ref else ref + "]"

    def target_ref(self, t) -> str | None:
        if isinstance(t, ast.Name):
            return tangent_name(t.id) if t.id in self.kind else None
        if isinstance(t, ast.Subscript) and isinstance(t.value, ast.Name):
            if t.value.id in self.kind:
                return f"{tangent_name(t.value.id)}[{_index(t.slice)}"
            return None
        raise TransformError(f"{self.name}: assignment target {ast.unparse(t)!r}")

    def alloc_tangent(self, value) -> str:
        """Tangent allocation of ``np.empty(shape, ...)``: zeros of shape + (_L,)."""
        shape = value.args[0]
        if isinstance(shape, ast.Tuple):
            dims = ", ".join(ast.unparse(e) for e in shape.elts)
        else:
            dims = ast.unparse(shape)
        return f"np.zeros(({dims}, _L))"

    def call_args(self, call) -> str:
        spec = self.specs[call.func.id]
        out = []
        for a, p in zip(call.args, _params(spec.func), strict=True):
            out.append(ast.unparse(a))
            if p in spec.active:
                ref = self.tangent_ref(a)
                if ref is None:
                    if spec.active[p] != "s":
                        raise TransformError(
                            f"{self.name}: {ast.unparse(a)!r} passed as active {p!r}")
                    z = self.tmp("_z")
                    self.emit(f"{z} = np.zeros(_L)", self._indent)
                    ref = z
                elif "[" in ref:
                    ref = ref + "]"
                out.append(ref)
        return f"{tangent_name(call.func.id)}({', '.join(out)})"

    def stmt(self, s, indent):
        self._indent = indent
        if isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant):
            return                                      # docstring
        if isinstance(s, ast.Expr) and self._call_spec(s.value) is not None:
            self.emit(self.call_args(s.value), indent)
            return
        if isinstance(s, ast.Expr):
            if self._is_active_expr(s.value):
                raise TransformError(f"{self.name}: {ast.unparse(s)!r}")
            self.emit(self.passive_src(s), indent)
            return
        if isinstance(s, ast.AugAssign):
            load = ast.parse(ast.unparse(s.target), mode="eval").body
            s = _assign(s.target, ast.BinOp(left=load, op=s.op, right=s.value))
        if isinstance(s, ast.Assign):
            self.assign(s, indent)
            return
        if isinstance(s, ast.If):
            self.emit(f"if {ast.unparse(s.test)}:", indent)
            self.block(s.body, indent + 1)
            if s.orelse:
                self.emit("else:", indent)
                self.block(s.orelse, indent + 1)
            return
        if isinstance(s, ast.For):
            self.emit(f"for {ast.unparse(s.target)} in {ast.unparse(s.iter)}:", indent)
            self.block(s.body, indent + 1)
            return
        if isinstance(s, ast.While):
            self.emit(f"while {ast.unparse(s.test)}:", indent)
            self.block(s.body, indent + 1)
            return
        if isinstance(s, ast.Return):
            self.ret(s, indent)
            return
        if isinstance(s, (ast.Pass, ast.Break, ast.Continue)):
            self.emit(ast.unparse(s), indent)
            return
        raise TransformError(f"{self.name}: statement {ast.unparse(s)!r}")

    def passive_src(self, node) -> str:
        """Source of a statement or expression that carries no derivative, with any call of a
        transformed function in it replaced by the call of its tangent version (whose
        tangent outputs must still be written, e.g. ``n += abs(propagate(...))``)."""
        fn = self

        class _Calls(ast.NodeTransformer):
            def visit_Call(self, node):
                self.generic_visit(node)
                if fn._call_spec(node) is not None:
                    return ast.parse(fn.call_args(node), mode="eval").body
                return node

        return ast.unparse(_Calls().visit(ast.parse(ast.unparse(node))))

    def block(self, body, indent):
        n = len(self.lines)
        for s in body:
            self.stmt(s, indent)
        if len(self.lines) == n:
            self.emit("pass", indent)

    def ret(self, s, indent):
        if not self.spec.returns:
            if s.value is not None and self._is_active_expr(s.value):
                raise TransformError(f"{self.name}: returns an active value undeclared")
            self.emit(ast.unparse(s), indent)
            return
        vals = s.value.elts if isinstance(s.value, ast.Tuple) else [s.value]
        prim, tang = [], []
        for v, k in zip(vals, self.spec.returns, strict=True):
            value, terms = self.diff(v, indent)
            prim.append(value)
            if k == "s":
                z = self.tmp("_r")
                self.emit(f"{z} = np.empty(_L)", indent)
                self.assign_tangent(z, terms, indent)
                tang.append(z)
            else:
                if not isinstance(v, ast.Name) or v.id not in self.kind:
                    raise TransformError(f"{self.name}: returns {ast.unparse(v)!r}")
                tang.append(tangent_name(v.id))
        self.emit(f"return ({', '.join(prim)},), ({', '.join(tang)},)", indent)

    def assign(self, s, indent):
        if len(s.targets) != 1:
            raise TransformError(f"{self.name}: chained assignment {ast.unparse(s)!r}")
        t, value = s.targets[0], s.value
        call = self._call_spec(value)
        if call is not None:                           # a transformed function's results
            if call.returns:
                r = self.tmp("_res")
                self.emit(f"{r}, {r}_t = {self.call_args(value)}", indent)
                names = t.elts if isinstance(t, ast.Tuple) else [t]
                for i, e in enumerate(names):
                    self.emit(f"{ast.unparse(e)} = {r}[{i}]", indent)
                    if call.returns[i] == "s":
                        self.emit(f"{tangent_name(e.id)}[:] = {r}_t[{i}]", indent)
                    else:
                        self.emit(f"{tangent_name(e.id)} = {r}_t[{i}]", indent)
            else:
                self.emit(f"{ast.unparse(t)} = {self.call_args(value)}", indent)
            return
        if isinstance(t, ast.Tuple):
            if isinstance(value, ast.Name) and self.kind.get(value.id) == "t":
                self.emit(f"{ast.unparse(t)} = {value.id}", indent)
                self.emit(f"{', '.join(tangent_name(e.id) for e in t.elts)}, = "
                          f"{tangent_name(value.id)}", indent)
                return
            if isinstance(value, ast.Tuple) and len(value.elts) == len(t.elts):
                names = {n.id for e in t.elts for n in ast.walk(e) if isinstance(n, ast.Name)}
                for v in value.elts:
                    if any(isinstance(n, ast.Name) and n.id in names for n in ast.walk(v)):
                        raise TransformError(f"{self.name}: swap in {ast.unparse(s)!r}")
                for e, v in zip(t.elts, value.elts, strict=True):
                    self.assign(_assign(e, v), indent)
                return
            if not self._is_active_expr(value):
                self.emit(self.passive_src(s), indent)
                return
            raise TransformError(f"{self.name}: tuple assignment {ast.unparse(s)!r}")
        if isinstance(t, ast.Name) and self.spec.active.get(t.id) == "s":
            raise TransformError(f"{self.name}: assigns its active scalar parameter {t.id!r}")
        ref = self.target_ref(t)
        if ref is None:
            if self._is_active_expr(value):
                raise TransformError(f"{self.name}: active value into {ast.unparse(t)!r}")
            self.emit(self.passive_src(s), indent)
            return
        kind = self.kind.get(t.id) if isinstance(t, ast.Name) else "e"
        if kind in ("a", "t"):                          # an array (or tuple) bound to a name
            if self._local_kind(value) == "a":
                self.emit(f"{t.id} = {ast.unparse(value)}", indent)
                self.emit(f"{tangent_name(t.id)} = {self.alloc_tangent(value)}", indent)
            elif self._local_kind(value) == "t":
                self.emit(f"{t.id} = {ast.unparse(value)}", indent)
                tup = ", ".join(self.alloc_tangent(e) for e in value.elts)
                self.emit(f"{tangent_name(t.id)} = ({tup},)", indent)
            elif isinstance(value, ast.Name) and value.id in self.kind:
                self.emit(f"{t.id} = {value.id}", indent)
                self.emit(f"{tangent_name(t.id)} = {tangent_name(value.id)}", indent)
            else:
                raise TransformError(f"{self.name}: array binding {ast.unparse(s)!r}")
            return
        v, terms = self.diff(value, indent)
        self.assign_tangent(ref, terms, indent)
        self.emit(f"{ast.unparse(t)} = {v}", indent)

    def source(self) -> str:
        params = []
        for p in self.params:
            params.append(p)
            if p in self.spec.active:
                params.append(tangent_name(p))
        first = next(p for p in self.params if p in self.spec.active)
        lane_src = (f"{tangent_name(first)}[0].shape[-1]" if self.spec.active[first] == "t"
                    else f"{tangent_name(first)}.shape[-1]")
        body_start = len(self.lines)
        self.block(self.tree.body, 1)
        body = self.lines[body_start:]
        scalars = sorted(n for n, k in self.kind.items()
                         if k == "s" and n not in self.params)
        head = [f"    _L = {lane_src}"]
        if scalars:
            head.append(f"    _T = np.empty(({len(scalars)}, _L))")
            head += [f"    {tangent_name(n)} = _T[{i}]" for i, n in enumerate(scalars)]
        jit = ", ".join(f"{k}={v!r}" for k, v in self.spec.jit.items())
        return "\n".join([f"@njit({jit})",
                          f"def {tangent_name(self.name)}({', '.join(params)}):",
                          *head, *body])


def _index(node) -> str:
    """An index's source without the tuple's parentheses (``i, 0``, not ``(i, 0)``)."""
    if isinstance(node, ast.Tuple):
        return ", ".join(ast.unparse(e) for e in node.elts)
    return ast.unparse(node)


def _assign(target, value) -> ast.Assign:
    node = ast.Assign(targets=[target], value=value, lineno=1, col_offset=0)
    return ast.fix_missing_locations(node)


def lane_kernel(n: int) -> str:
    """Source of ``_lin<n>(out, c1, x1, ..., cn, xn)``: ``out[j] = c1 x1[j] + ... + cn xn[j]``
    over the lanes (``out`` may be one of the ``x``: each lane is read before it is
    written)."""
    params = ", ".join(f"c{i}, x{i}" for i in range(n))
    rhs = " + ".join(f"c{i} * x{i}[j]" for i in range(n)) or "0.0"
    return ("@njit(cache=True)\n"
            f"def _lin{n}(out{', ' if n else ''}{params}):\n"
            f"    for j in range(out.shape[0]):\n"
            f"        out[j] = {rhs}\n")


def _params(func) -> list[str]:
    return list(inspect.signature(getattr(func, "py_func", func)).parameters)


def tangent_module(specs: list[Spec], passive=()) -> str:
    """Source of a module holding the tangent version ``<name>_t`` of every function in
    ``specs`` (numba ``njit`` functions or plain ones), with the imports their bodies need.
    ``passive``: names of other functions they call whose results carry no derivative (the
    primal one is called)."""
    by_name = {}
    for s in specs:
        f = getattr(s.func, "py_func", s.func)
        by_name[f.__name__] = Spec(f, s.active, s.returns, s.jit)
    imports: dict[str, tuple[object, str]] = {}
    bodies = []
    arities: set[int] = set()
    for spec in by_name.values():
        fn = _Function(spec, by_name, passive)
        bodies.append(fn.source())
        arities |= fn.arities
        g = spec.func.__globals__
        for n in ast.walk(fn.tree):
            if isinstance(n, ast.Name) and n.id in g and n.id not in by_name and n.id != "np":
                obj = g[n.id]
                if n.id in imports and imports[n.id][0] is not obj:
                    raise TransformError(f"{n.id!r} means two things in the sources")
                imports[n.id] = (obj, f"from {spec.func.__module__} import {n.id}")
    head = ['"""Generated by cadra.dynamics.forward_ad: tangent code. Do not edit."""',
            "import numpy as np", "from numba import njit",
            *sorted({line for _, line in imports.values()})]
    kernels = "\n\n".join(lane_kernel(n) for n in sorted(arities))
    return ("\n".join(head) + "\n\n" + PRELUDE + "\n\n" + kernels + "\n\n"
            + "\n\n\n".join(bodies) + "\n")
