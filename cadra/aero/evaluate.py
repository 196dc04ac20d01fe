"""The numpy reference evaluator of expression trees (slow, independent of the compiled
program of :mod:`cadra.aero.program`), and checks that a model's forms give finite numbers.

:func:`evaluate_tree` follows the complex-step rules of docs/aero_models.md. The checks
(:func:`nonfinite_constant`, :func:`nonfinite_everywhere`, :func:`nonfinite_points`) evaluate a
tree node by node, bottom up and without recursion, so they can name the smallest term that is
not finite (``1.0 / 0.0``, ``exp(1000.0)``, ``log(-mach)``).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from cadra.aero.nesting import deep_recursion


def evaluate_tree(node: tuple, variables: Mapping, params: Mapping) -> np.ndarray:
    """Evaluate a tree with numpy (the slow, independent reference for the compiled program).

    ``variables`` maps variable names to arrays or numbers (missing ones are 0), ``params``
    parameter names to values; complex inputs follow the same complex-step rules.
    """
    with np.errstate(all="ignore"), deep_recursion():
        return np.asarray(_ev(node, variables, params))


def _re(x):
    return np.real(x)


def _ev(n, V, Pm):
    tag = n[0]
    if tag == "num":
        return n[1]
    if tag == "var":
        return V.get(n[1], 0.0)
    if tag == "par":
        return Pm[n[1]]
    if tag == "powc":
        return np.power(_ev(n[1], V, Pm), n[2])
    a = [_ev(c, V, Pm) for c in n[1:]]
    if tag == "neg":
        return -a[0]
    if tag == "sqr":
        return a[0] * a[0]
    if tag == "add":
        return a[0] + a[1]
    if tag == "sub":
        return a[0] - a[1]
    if tag == "mul":
        return a[0] * a[1]
    if tag == "div":
        return a[0] / a[1]
    if tag == "pow":
        return np.power(a[0], a[1])
    if tag == "abs":
        return np.where(_re(a[0]) < 0, -a[0], a[0])
    if tag in ("sin", "cos", "tan", "sqrt", "exp", "log"):
        return getattr(np, tag)(a[0])
    if tag in ("asin", "acos", "atan"):
        return getattr(np, "arc" + tag[1:])(a[0])
    if tag == "atan2":
        y, x = np.asarray(a[0]), np.asarray(a[1])
        if not (np.iscomplexobj(y) or np.iscomplexobj(x)):
            return np.arctan2(y, x)
        yr, xr = _re(y), _re(x)
        base = np.where(xr != 0, np.arctan(y / np.where(xr != 0, x, 1)), 0)
        side = np.where(yr != 0, np.arctan(x / np.where(yr != 0, y, 1)), 0)
        return np.where(xr > 0, base,
               np.where(xr < 0, base + np.where(yr >= 0, np.pi, -np.pi),
               np.where(yr > 0, np.pi / 2 - side,
               np.where(yr < 0, -np.pi / 2 - side, 0 * y))))
    if tag == "max":
        return np.where(_re(a[0]) > _re(a[1]), a[0], a[1])
    if tag == "min":
        return np.where(_re(a[0]) < _re(a[1]), a[0], a[1])
    if tag == "lt":
        return (_re(a[0]) < _re(a[1])) * 1.0
    if tag == "gt":
        return (_re(a[0]) > _re(a[1])) * 1.0
    if tag == "le":
        return (_re(a[0]) <= _re(a[1])) * 1.0
    if tag == "ge":
        return (_re(a[0]) >= _re(a[1])) * 1.0
    if tag == "where":
        return np.where(_re(a[0]) != 0, a[1], a[2])
    raise ValueError(f"unknown node {tag!r}")


# --- finite checks (node by node, without recursion) ---------------------------------------


def _kids(n: tuple) -> tuple:
    if n[0] in ("num", "var", "par"):
        return ()
    return (n[1],) if n[0] == "powc" else n[1:]


def _walk(tree: tuple, variables: Mapping, params: Mapping):
    """``(node, value, child values, constant)`` of every node of ``tree``, children first."""
    vals: dict[int, tuple] = {}
    stack = [(tree, False)]
    with np.errstate(all="ignore"):
        while stack:
            n, done = stack.pop()
            kids = _kids(n)
            if kids and not done:
                stack.append((n, True))
                stack.extend((c, False) for c in reversed(kids))
                continue
            if not kids:
                v = np.nan if n[0] == "par" and n[1] not in params else _ev(n, variables, params)
                const = n[0] == "num"
            else:
                a = [("num", vals[id(c)][0]) for c in kids]
                v = _ev((n[0], a[0], n[2]) if n[0] == "powc" else (n[0], *a), variables, params)
                const = all(vals[id(c)][1] for c in kids)
            v = np.asarray(v)
            vals[id(n)] = (v, const)
            yield n, v, [vals[id(c)][0] for c in kids], const


def _finite(v) -> np.ndarray:
    return np.isfinite(np.asarray(v))


def nonfinite_constant(tree: tuple) -> tuple[tuple, float] | None:
    """The first (innermost) subexpression of ``tree`` made of numbers only whose value is not
    finite (``1/0``, ``exp(1000)``, ``log(-1)``), with its value; ``None`` if there is none."""
    for n, v, _, const in _walk(tree, {}, {}):
        if const and not _finite(v).all():
            return n, complex(v).real if np.iscomplexobj(v) else float(v)
    return None


def nonfinite_origin(tree: tuple, variables: Mapping, params: Mapping, *,
                     everywhere: bool) -> tuple[tuple, np.ndarray] | None:
    """Where ``tree`` is not finite at the points ``variables`` (arrays), the innermost term
    that makes it so: ``(term, its values)``; ``None`` if the tree is finite (``everywhere``:
    finite at one point at least). The term is the first, children first, that is not finite
    (at every point, for ``everywhere``) while its operands are (at some point)."""
    nodes = list(_walk(tree, variables, params))
    root = nodes[-1][:2]
    if _finite(root[1]).any() if everywhere else _finite(root[1]).all():
        return None
    for n, v, kids, _ in nodes:
        bad = ~_finite(v)
        if everywhere:
            if bad.all() and all(_finite(k).any() for k in kids):
                return n, v
        else:
            ok_in = np.ones(bad.shape, dtype=bool)
            for k in kids:
                ok_in = ok_in & _finite(k)
            if (bad & ok_in).any():
                return n, v
    return root  # pragma: no cover - a leaf is always finite
