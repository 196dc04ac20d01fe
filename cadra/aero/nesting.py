"""How deep a coefficient form may nest, and room for the recursive tree code to reach it.

The parser, :func:`cadra.aero.expr.simplify`, :func:`~cadra.aero.expr.to_text`, the numpy
reference evaluator and the compiler walk expression trees recursively. A legitimate form can
nest deeply without looking deep: a sum of 700 terms is a left-leaning tree 700 levels deep, and
Python's default recursion limit (1000) is shared with the caller's own frames. So:

- :func:`ast_depth` measures the nesting of the parsed text (iteratively) and the parser refuses
  anything deeper than :data:`MAX_DEPTH` levels with a clear message;
- :func:`deep_recursion` raises the interpreter's recursion limit, for the duration of one call
  into the tree code, to what :data:`MAX_DEPTH` levels need (each level costs a few frames).
  Since Python 3.11 Python-to-Python calls do not use the C stack, so this is safe; the limit
  is put back on exit (it is interpreter-wide: a concurrent thread sees the raised value while
  the call runs, never a lower one than it had).
"""

from __future__ import annotations

import ast
import contextlib
import sys
import threading
from collections.abc import Iterator

#: deepest nesting of a form (operators, calls, unary signs); a sum of n terms is n deep
MAX_DEPTH = 1000
#: recursion limit the tree code runs under (frames per level of the deepest walker, x margin)
RECURSION_LIMIT = 5 * MAX_DEPTH + 2000

_lock = threading.Lock()
_active = 0
_saved = 0


def ast_depth(node: ast.AST) -> int:
    """Nesting depth of a Python syntax tree (a leaf is 1), measured without recursion."""
    deepest = 0
    stack = [(node, 1)]
    while stack:
        n, d = stack.pop()
        deepest = max(deepest, d)
        stack.extend((c, d + 1) for c in ast.iter_child_nodes(n))
    return deepest


@contextlib.contextmanager
def deep_recursion() -> Iterator[None]:
    """Run the body with the recursion limit at least :data:`RECURSION_LIMIT` (re-entrant and
    thread-safe: the first entry raises it, the last exit restores it)."""
    global _active, _saved
    with _lock:
        if _active == 0:
            _saved = sys.getrecursionlimit()
            if _saved < RECURSION_LIMIT:
                sys.setrecursionlimit(RECURSION_LIMIT)
        _active += 1
    try:
        yield
    finally:
        with _lock:
            _active -= 1
            if _active == 0 and sys.getrecursionlimit() == RECURSION_LIMIT != _saved:
                sys.setrecursionlimit(_saved)


__all__ = ["MAX_DEPTH", "RECURSION_LIMIT", "ast_depth", "deep_recursion"]
