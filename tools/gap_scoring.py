"""The size of an effect the gap diagnosis adds, scored as a vector: the gap cases whose
effects have more than one parameter, each trial named first scored both ways
(cadra.validation.gap_scoring.effect_size_ok; docs/gap.md, "What size within 2 sigma can
reach").

For each case (default: cross-flow, two winds; and the strong effects, one to six
parameters), ``--trials`` trials are made and diagnosed as ``tools/validate_gap.py`` makes
them. Among the trials whose effect is named first, the share whose size passes:

- as one vector with the refit's covariance, at the chi-square quantile of 2 sigma for its
  k parameters (a body pair by its magnitude): a perfect diagnosis passes 95.45 %;
- each parameter alone within 2 sigma: a perfect diagnosis passes 0.9545^k for independent
  parameters (printed beside it, averaged over the trials' k).

Each rate carries its 95 % binomial (Clopper-Pearson) interval. Usage: python
tools/gap_scoring.py [--trials 20] [--strong-trials N] [--cases crossflow,strong] (about
25 s a cross-flow trial and 3 min a strong one on one core). The last printed line is a
JSON object, recorded in results/gap_scoring.json.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from cadra.validation.tool import binomial_rate, one_thread, run_tool

one_thread()

import numpy as np  # noqa: E402 (after one_thread)

from cadra.validation.gap_trials import run_case  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: a perfect diagnosis' pass rate of the vector score
TWO_SIGMA = 0.9545


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--seed", type=int, default=16)
    ap.add_argument("--cases", default="crossflow,strong")
    ap.add_argument("--strong-trials", type=int, default=None,
                    help="trials of the strong case (default --trials; ~3 min each: its "
                         "effects are large and its fits long)")
    args = ap.parse_args(argv)
    run_tool("gap_scoring", ROOT, lambda: run(args), argv=argv)
    return 0


def run(args) -> dict:
    rng = np.random.default_rng(args.seed)
    by_case = {}
    with tempfile.TemporaryDirectory() as tmp:
        for case in [c for c in args.cases.split(",") if c]:
            n = (args.strong_trials if case == "strong" and args.strong_trials is not None
                 else args.trials)
            rows, redrawn = run_case(case, rng, tmp, n, progress=True)
            named = [r for r in rows if r.get("top1")]
            multi = [r for r in named if r.get("n_params", 1) > 1]
            k = [r["n_params"] for r in multi]
            by_case[case] = {
                "trials": len(rows), "named_first": len(named), "multi_parameter": len(multi),
                "parameters": sorted(set(k)),
                "vector": binomial_rate(sum(bool(r["size_ok"]) for r in multi), len(multi)),
                "per_parameter": binomial_rate(sum(bool(r["size_ok_per_parameter"]) for r in multi),
                                       len(multi)),
                "per_parameter_perfect": float(np.mean([TWO_SIGMA ** n for n in k]))
                if k else None}
            print(f"{case}: {by_case[case]}", flush=True)
    cases = [c for c in by_case.values() if c["multi_parameter"]]
    worst = min(cases, key=lambda c: c["vector"]["rate"]) if cases else None
    return {
        "by_case": by_case,
        "gap_size_vector_rate_min": worst["vector"]["rate"] if worst else None,
        "gap_size_vector_rate_min_ci_high": worst["vector"]["ci95"][1] if worst else None,
        "gap_size_per_parameter_rate_min": min((c["per_parameter"]["rate"] for c in cases),
                                               default=None),
        "gap_size_per_parameter_perfect_min": min((c["per_parameter_perfect"]
                                                   for c in cases), default=None),
        "gap_size_multi_parameter_trials": sum(c["multi_parameter"] for c in cases),
    }


if __name__ == "__main__":
    sys.exit(main())
