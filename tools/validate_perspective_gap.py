"""Point-source records reduced under a facility file that declares parallel optics, named by
the gap diagnosis (the harness is cadra.validation.perspective_gap; docs/gap.md).

Each trial: two M-80 rounds at mirror offsets from the line of flight, rendered through the
bundled point-source range (sparks 1.5 m from the line of flight), measured by stage one with
every view declared parallel, fitted together and diagnosed with that declared facility. A
null trial renders through the declared parallel facility itself. Figures: how often a view's
point-source optics is the effect added first, and both views' (with 95 % Clopper-Pearson
intervals), the fitted 1/H over the true 1/1.5 m, and how often a null trial adds either.

Usage: python tools/validate_perspective_gap.py [--trials 6] [--nulls 4] (a few minutes a
trial on one core). The last printed line is a JSON object, recorded in
results/validate_perspective_gap.json.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from cadra.validation.tool import one_thread, round_figures, run_tool

one_thread()

from cadra.validation.perspective_gap import run_trial, summarize  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=6, help="declared-parallel trials")
    ap.add_argument("--nulls", type=int, default=4, help="null trials")
    args = ap.parse_args(argv)
    run_tool("validate_perspective_gap", ROOT, lambda: run(args), argv=argv)
    return 0


def run(args) -> dict:
    rows = []
    for k in range(args.trials + args.nulls):
        rows.append(run_trial(k, point_source=k < args.trials))
        print(json.dumps(round_figures(rows[-1])), flush=True)
    s = summarize(rows)
    named, both = s.get("named_first") or {}, s.get("both_named") or {}
    null = s.get("null_added") or {}
    fig = {"perspective_named_first_rate": named.get("rate"),
           "perspective_named_first_ci_low": (named.get("ci95") or [None])[0],
           "perspective_both_named_rate": both.get("rate"),
           "perspective_kappa_over_truth_median": s.get("kappa_over_truth_median"),
           "perspective_null_added_rate": null.get("rate"),
           "perspective_trial_median_s": s.get("median_seconds")}
    return {"summary": round_figures(s), "rows": round_figures(rows), **round_figures(fig)}


if __name__ == "__main__":
    sys.exit(main())
