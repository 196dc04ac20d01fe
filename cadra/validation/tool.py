"""What every script in ``tools/`` does around its own work: one thread per process where the
figures are per core, the run timed, its figures printed as the last line (a JSON object) and
recorded in ``results/<tool>.json`` (:func:`cadra.validation.results.record`); the figures
rounded to their meaningful digits, and a rate given with its binomial interval."""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable

#: the thread counts a benchmark on one core pins (BLAS, OpenMP, numba)
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS")


def one_thread(variables=THREAD_VARIABLES) -> None:
    """One thread for each library in ``variables`` unless the environment says otherwise;
    call it before numpy or numba is imported (small SVDs and products: a multi-threaded
    BLAS only spins on a shared machine)."""
    for name in variables:
        os.environ.setdefault(name, "1")


def run_tool(tool: str, root, compute: Callable[[], dict], *, argv=None,
             seconds_key: str | None = "seconds") -> dict:
    """Time ``compute()``, add the time under ``seconds_key`` (rounded to 0.1 s; None: not
    added), print the figures as one line of strict JSON (:func:`cadra.io.plain.plain`) and
    record them as ``tool``'s results under ``root``; returns the figures as printed."""
    from cadra.io.plain import plain
    from cadra.validation.results import record

    t0 = time.perf_counter()
    out = compute()
    elapsed = time.perf_counter() - t0
    if seconds_key:
        out[seconds_key] = round(elapsed, 1)
    out = plain(out)
    print(json.dumps(out, allow_nan=False))
    record(tool, out, root, argv=argv, seconds=elapsed)
    return out


def round_figures(x, digits: int = 4):
    """``x`` (nested dicts and lists) with every float to ``digits`` significant digits: a
    tool's printed and recorded figures, no longer than they are meaningful."""
    if isinstance(x, dict):
        return {k: round_figures(v, digits) for k, v in x.items()}
    if isinstance(x, list):
        return [round_figures(v, digits) for v in x]
    if isinstance(x, float):
        return float(f"{x:.{digits}g}")
    return x


def binomial_rate(hits: int, n: int) -> dict:
    """A rate with its 95 % Clopper-Pearson interval: ``{"rate", "n", "ci95"}`` (NaN and None
    without trials)."""
    from scipy.stats import binomtest

    ci = binomtest(hits, n).proportion_ci(0.95, method="exact") if n else None
    return {"rate": hits / n if n else math.nan, "n": n,
            "ci95": [round(ci.low, 4), round(ci.high, 4)] if ci else None}


__all__ = ["THREAD_VARIABLES", "binomial_rate", "one_thread", "round_figures", "run_tool"]
