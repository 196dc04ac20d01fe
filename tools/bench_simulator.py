"""Benchmark: 16-station 6-DOF trajectories per second on one core.

Flies the sample shot M2-2429 (Table 4 M2 M0.70 aerodynamics, the heaviest bundled model) from
its launch state to its 16 spark times with the default RK4 step, repeatedly, in one process
(numba runs single-threaded here). Also times the complex128 path (complex-step sensitivities)
and the first call (compilation, or loading the on-disk cache).

Usage: python tools/bench_simulator.py [--seconds 3]
Last line: a JSON object with key ``trajectories_per_s`` (target >= 500).
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
    parser.add_argument("--seconds", type=float, default=3.0, help="time per measurement")
    parser.add_argument("--spec", default=str(ROOT / "sample_shots/specs/m2_2429.toml"))
    args = parser.parse_args()
    run_tool("bench_simulator", ROOT, lambda: run(args.spec, args.seconds), seconds_key=None)


def run(spec_path, seconds: float) -> dict:
    """Trajectories per second of the shot ``spec_path`` in float64 and complex128."""
    t_import = time.perf_counter()
    import numpy as np

    from cadra.dynamics.setup import DT_MAX_DEFAULT, propagate_states
    from cadra.synthetic.simulate import load_shot_spec, simulate_shot

    spec = load_shot_spec(spec_path)
    t0 = time.perf_counter()
    shot = simulate_shot(spec)
    first_s = time.perf_counter() - t0
    program, params = shot.model.compile(), shot.model.values()
    phys = shot.rigid.phys()
    # absolute spark times of the shot (the truth times are relative to station 1)
    x0 = shot.states[0]
    times = shot.times_s

    def rate(dtype_y0, label):
        propagate_states(dtype_y0, 0.0, times, phys, program, params)
        n, t_start = 0, time.perf_counter()
        while time.perf_counter() - t_start < seconds:
            propagate_states(dtype_y0, 0.0, times, phys, program, params)
            n += 1
        r = n / (time.perf_counter() - t_start)
        print(f"{label}: {r:8.1f} trajectories/s ({1e3 / r:.3f} ms each)")
        return r

    n_steps = int(np.ceil(times[-1] / DT_MAX_DEFAULT))
    print(f"shot {spec.shot_id}: {len(times)} stations over {times[-1] * 1e3:.1f} ms, "
          f"~{n_steps} RK4 steps (dt_max {DT_MAX_DEFAULT * 1e3:.2f} ms), model {spec.aero_model}"
          f" ({len(params)} parameters)")
    print(f"first simulate_shot (compile or cache load + crossing search): {first_s:.2f} s; "
          f"import {t0 - t_import:.2f} s")
    real = rate(x0.copy(), "float64   ")
    cplx = rate(x0.astype(complex), "complex128")
    return {
        "trajectories_per_s": round(real, 1),
        "complex_trajectories_per_s": round(cplx, 1),
        "ms_per_trajectory": round(1e3 / real, 4),
        "rk4_steps": n_steps,
        "stations": len(times),
        "first_call_s": round(first_s, 3),
    }


if __name__ == "__main__":
    main()
