"""A spark surveyed off its place, named by the gap diagnosis, from rendered point-source
records (the harness is cadra.validation.spark_gap; docs/gap.md).

Each trial: two M-80 rounds through the bundled point-source range at mirror offsets from
the line of flight, rendered, measured by stage one, fitted together and diagnosed. In a
spark trial one view of one station records through a spark 3 mm farther from its film than
the facility file says; a null trial has none. Figures: how often the spark's candidate is
the effect added first (with its 95 % Clopper-Pearson interval), its fitted size within 2
sigma of the truth, and how often a null trial adds anything.

Usage: python tools/validate_spark_gap.py [--trials 12] [--nulls 6] (about 70 s a trial on
one core). The last printed line is a JSON object, recorded in results/validate_spark_gap.json.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from cadra.validation.tool import one_thread, round_figures, run_tool

one_thread()

from cadra.validation.spark_gap import run_trial, summarize  # noqa: E402 (after one_thread)

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=12, help="spark trials")
    ap.add_argument("--nulls", type=int, default=6, help="null trials")
    args = ap.parse_args(argv)
    run_tool("validate_spark_gap", ROOT, lambda: run(args), argv=argv)
    return 0


def run(args) -> dict:
    rows = []
    for k in range(args.trials + args.nulls):
        rows.append(run_trial(k, spark=k < args.trials))
        print(json.dumps(round_figures(rows[-1])), flush=True)
    s = summarize(rows)
    named = s.get("named_first") or {}
    null = s.get("null_added") or {}
    fig = {"spark_named_first_rate": named.get("rate"),
           "spark_named_first_ci_low": (named.get("ci95") or [None])[0],
           "spark_size_within_2sigma_frac": s.get("size_within_2sigma_frac"),
           "spark_null_added_rate": null.get("rate"),
           "spark_trial_median_s": s.get("median_seconds")}
    return {"summary": round_figures(s), "rows": round_figures(rows), **round_figures(fig)}


if __name__ == "__main__":
    sys.exit(main())
