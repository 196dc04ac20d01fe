"""Benchmark: ns per full 9-coefficient evaluation of a bundled aero model, in a numba loop.

Evaluates the compiled program (``cadra.aero.program.eval_coefficients``) at a sweep of
(alpha, beta, mach) points, as the 6-DOF integrator does, for float64 and complex128.

Usage: python tools/bench_aero.py [--model m2_m070] [--calls 2000000]
Last line: a JSON object with keys ``ns_float64`` and ``ns_complex128``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

one_thread()

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--model", default="m2_m070")
    parser.add_argument("--calls", type=int, default=2_000_000)
    args = parser.parse_args()
    run_tool("bench_aero", ROOT, lambda: run(args.model, args.calls), seconds_key=None)


def run(model_name: str, calls: int) -> dict:
    """ns per evaluation of ``model_name``'s coefficients in float64 and complex128."""
    import numpy as np
    from numba import njit

    from cadra.aero import eval_coefficients, load_bundled_model

    @njit(cache=False)
    def loop(ops, a, starts, variables, params, out, stack, n):
        acc = out[0] * 0.0
        m = variables.shape[0]
        for i in range(n):
            eval_coefficients(ops, a, starts, variables[i % m], params, out, stack)
            acc += out[0] + out[4] + out[7]
        return acc

    model = load_bundled_model(model_name)
    prog = model.compile()
    rng = np.random.default_rng(1)
    m = 256
    var = np.zeros((m, 8))
    var[:, 0] = np.radians(21.0 + rng.uniform(-15, 15, m))
    var[:, 1] = np.radians(rng.uniform(-5, 5, m))
    var[:, 2] = np.arccos(np.cos(var[:, 0]) * np.cos(var[:, 1]))
    var[:, 3] = rng.uniform(0.6, 0.8, m)
    result = {"model": model_name, "ops": int(prog.ops.size), "temps": int(prog.n_temps),
              "stack_size": int(prog.stack_size)}
    for dtype, key in ((np.float64, "ns_float64"), (np.complex128, "ns_complex128")):
        v = var.astype(dtype)
        if dtype is np.complex128:
            v[:, 0] += 1e-30j
        p = model.values().astype(dtype)
        out = np.empty(9, dtype=dtype)
        stack = prog.new_stack(dtype)
        loop(prog.ops, prog.args, prog.starts, v, p, out, stack, 10)
        best = np.inf
        for _ in range(3):
            t0 = time.perf_counter()
            loop(prog.ops, prog.args, prog.starts, v, p, out, stack, calls)
            best = min(best, time.perf_counter() - t0)
        result[key] = round(best / calls * 1e9, 1)
        print(f"{model_name} {np.dtype(dtype).name:10s}: {result[key]:7.1f} ns per "
              f"9-coefficient evaluation ({prog.ops.size} ops, {prog.n_temps} temporaries)")
    return result


if __name__ == "__main__":
    main()
