"""Stage-two (cadra2) speed, accuracy and honesty against the simulator's exact truth.

Usage::

    python tools/bench_cadra2.py                 # full run (~20-30 min on 2 cores)
    python tools/bench_cadra2.py --quick         # fewer realisations, for a smoke test
    python tools/bench_cadra2.py --realisations 100 --seed 7 --skip-baseline --skip-pulls
    python tools/bench_cadra2.py --baseline-only       # sections 1-2 only (speed, baseline)

Problems (synthetic data from the sample-shot specs; truth = the simulator's truth.csv):
single fit of M2-2429 (model m2_m070, all its free parameters) and the 7-shot M2 M0.70
multi-fit (2425 2426 2427 2428 2429 2431 2433); the 7-shot M1 M1.10 multi-fit (m1_m110;
2366 2379 2380 2384 2386 2388 2393) for accuracy and pulls. Film noise
(:data:`cadra.flight.data.FILM_SIGMAS`: 0.1 mm, 0.1 deg, 10 ns timing). The "perturbed"
start is the true epoch state moved by ~1 mm, 0.5 m/s, 0.5 deg, 0.5 rad/s (Gaussian, per
component) and every free aero value by 5-10 % (random sign); the "auto" start is
:mod:`cadra.fitting.start` (linear theory from the data, seeded with the perturbed model as
the analyst's model file).

Sections:

1. speed: best-of-3 warm wall time of the single fit and of the 7-shot multi-fit, from the
   perturbed start (default: sensitivities over all cores; also on one thread) and from the
   automatic start (start time included, and shown apart);
2. baseline: :func:`cadra.validation.fit_baseline.baseline_fit` (``solve_ivp`` DOP853 at rtol 1e-10,
   atol 1e-12 over the same compiled equations of motion and observation model;
   ``least_squares`` 'trf' with a '2-point' finite-difference Jacobian, relative step 1e-5)
   on the same problems and starts: wall time, speed-up, and both fits' accuracy vs truth.
   Two right-hand sides: ``rhs="compiled"`` (CADRA's numba equations of motion called from
   ``solve_ivp``: the strict baseline, keys ``baseline_*``, ``baseline_speedup``) and
   ``rhs="python"`` (what a SciPy user without CADRA writes: the same equations in plain
   Python, coefficients from the model's trees by :func:`cadra.aero.expr.evaluate_tree`; keys
   ``baseline_python_*``, ``baseline_python_speedup``) with the same start, tolerances and
   ``least_squares`` settings; per-trajectory times (fit wall time / trajectories, ms) of both.
   The python multi-fit runs only if its estimate (python ms per trajectory of the single fit
   x the compiled multi-fit's trajectory count) is under 10 min; otherwise it is skipped and the
   reason printed (``baseline_python_multifit_skipped``);
3. cold start: the first fit in a fresh Python process (import, data from truth.csv, fit),
   with the on-disk compiled caches present, and with an empty ``NUMBA_CACHE_DIR`` (a temporary
   directory: the shared caches of the repository are not touched);
4. noise-free: the two 7-shot multi-fits on noise-free measurements (film sigmas as
   weights): max |fit - truth| / |truth| over the free parameters, (a) on truth.csv (25 us
   fixed-step RK4 truth, off by up to 0.16 um at Table 4's kinks) with default options,
   (b) on exact measurements (``solve_ivp`` DOP853 at rtol 1e-13 from the true epoch state,
   an integrator independent of the fitter's) with default options, and (c) on exact
   measurements with the convergence test at 1e-4 sigma and integrator tolerance 1e-10 (the
   headline figure): the default stop rule (remaining step < 0.01 sigma) leaves up to
   ~0.003 sigma, which is > 1e-4 relative for parameters whose sigma exceeds ~3 % of their
   value;
5. pulls: >= 50 noise realisations of both multi-fits (film sigmas), and a smaller set at
   stage-one sigmas (0.3 um, 0.0012 deg, no timing error; exact measurements as in 4b):
   per parameter mean and std of (fit - truth) / sigma and the fraction within 2 sigma.
   Realisations run over 2 processes, each fit on one thread.

The sections are :mod:`cadra.validation.stage2_bench`'s. The last printed line is a JSON
object with the figures; it is also recorded in ``results/bench_cadra2.json``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from cadra.validation.stage2_bench import (
    cold_start,
    figures,
    noise_free,
    pulls,
    speed_and_baseline,
)
from cadra.validation.tool import run_tool

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer realisations (smoke test)")
    ap.add_argument("--realisations", type=int, default=50,
                    help="noise realisations per multi-fit at film sigmas (default 50)")
    ap.add_argument("--stage1-realisations", type=int, default=None,
                    help="realisations at stage-one sigmas (default realisations / 2.5)")
    ap.add_argument("--skip-baseline", action="store_true")
    ap.add_argument("--skip-pulls", action="store_true")
    ap.add_argument("--baseline-only", action="store_true",
                    help="run only sections 1-2 (speed and the SciPy baselines)")
    ap.add_argument("--seed", type=int, default=2024)
    ap.add_argument("--workers", type=int, default=2, help="processes for the pulls")
    args = ap.parse_args()
    n_film = 6 if args.quick else args.realisations
    n_stage1 = (args.stage1_realisations if args.stage1_realisations is not None
                else (3 if args.quick else max(1, round(args.realisations / 2.5))))
    run_tool("bench_cadra2", ROOT, lambda: run(args, n_film, n_stage1), seconds_key=None)
    return 0


def run(args, n_film: int, n_stage1: int) -> dict:
    """The sections ``args`` asks for, each announced; their figures."""
    t_bench = time.perf_counter()
    print("== 1-2. speed (warm) and the SciPy baseline")
    sp = speed_and_baseline(args.seed, args.skip_baseline, args.quick)
    cold = nf = pl = None
    if not args.baseline_only:
        print("\n== 3. cold start (fresh process: imports, data from truth.csv, first fit)")
        cold = cold_start()
        print("\n== 4. noise-free 7-shot multi-fits, max |fit - truth| / |truth|")
        nf = noise_free(args.seed)
    if not (args.skip_pulls or args.baseline_only):
        print(f"\n== 5. pulls: {n_film} film-sigma and {n_stage1} stage-one-sigma realisations"
              f" per multi-fit, {args.workers} processes")
        pl = pulls(args.seed, n_film, n_stage1, args.workers)

    return figures(sp, cold, nf, pl, time.perf_counter() - t_bench)


if __name__ == "__main__":
    sys.exit(main())
