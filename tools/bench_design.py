"""The bootstrap and the next-shot planner, measured (``cadra/validation/design_bench.py``):
the M2 M0.70 seven-shot bootstrap's sigma ratios, its speed-up from one Dask worker to two,
the percentile interval's coverage on a nonlinear single shot, a plan over 1,000 candidates
(its time, and its best shot fired from images and refitted: realised over predicted sigmas,
the gain over random and grid candidates), and seed 004's decision (docs/design.md). Last
printed line: a JSON object.

Usage: python tools/bench_design.py [--refits 200] [--speedup-refits 100] [--draws 80]
       [--draw-refits 100] [--reps 10] [--candidates 1000] [--sections a,b,...]

Sections: bootstrap, speedup, coverage, plan, seed004 (default: all; about 50 min on two
cores). A run of some sections keeps the others' figures from the recorded results, each
section stamped with the commit and date it was measured at (``--sections ""`` only
recomputes the headline figures from them).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from cadra.validation.tool import run_tool

ROOT = Path(__file__).resolve().parents[1]
SECTIONS = ("bootstrap", "speedup", "coverage", "plan", "seed004")


def _headline(out: dict) -> dict:
    """The acceptance's figures, at the top level (None where a section has not run)."""
    def get(section, key):
        return out.get(section, {}).get(key)

    cov = out.get("coverage", {})
    return {"bootstrap_sigma_ratio_min": get("bootstrap", "ratio_min"),
            "bootstrap_sigma_ratio_max": get("bootstrap", "ratio_max"),
            "percentile_coverage": cov.get("percentile", {}).get("rate"),
            "basic_interval_coverage": cov.get("basic", {}).get("rate"),
            "studentized_coverage": cov.get("studentized", {}).get("rate"),
            "peak_percentile_coverage": cov.get("peak", {}).get("percentile", {}).get("rate"),
            "covariance_coverage": cov.get("covariance", {}).get("rate"),
            "plan_realised_over_predicted_min": get("plan", "realised_over_predicted_min"),
            "plan_realised_over_predicted_max": get("plan", "realised_over_predicted_max"),
            "plan_gain_over_random": get("plan", "gain_over_random"),
            "plan_gain_over_grid": get("plan", "gain_over_grid"),
            "plan_seconds_1000_candidates": get("plan", "plan_seconds"),
            "bootstrap_speedup_2_workers": get("speedup", "speedup")}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--refits", type=int, default=200)
    ap.add_argument("--speedup-refits", type=int, default=100)
    ap.add_argument("--draws", type=int, default=80)
    ap.add_argument("--draw-refits", type=int, default=100)
    ap.add_argument("--reps", type=int, default=10)
    ap.add_argument("--candidates", type=int, default=1000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sections", default=",".join(SECTIONS))
    args = ap.parse_args(argv)
    chosen = [s.strip() for s in args.sections.split(",") if s.strip()]
    bad = [s for s in chosen if s not in SECTIONS]
    if bad:
        ap.error(f"unknown section {bad[0]!r} (sections: {', '.join(SECTIONS)})")
    from cadra.validation import design_bench as db
    from cadra.validation.results import _commit

    previous = ROOT / "results" / "bench_design.json"
    old = json.loads(previous.read_text())["figures"] if previous.is_file() else {}

    def compute() -> dict:
        import datetime

        out = {s: old[s] for s in SECTIONS if s in old and s not in chosen}
        stamp = {"commit": _commit(ROOT), "date": datetime.date.today().isoformat()}
        runs = {"bootstrap": lambda: db.bootstrap_figures(args.refits, args.workers, args.seed),
                "speedup": lambda: db.speedup_figures(args.speedup_refits, args.seed),
                "coverage": lambda: db.coverage_figures(args.draws, args.draw_refits,
                                                        args.workers, args.seed),
                "plan": lambda: db.plan_figures(args.reps, args.candidates, args.seed),
                "seed004": lambda: db.seed004_figures(min(args.candidates, 300), args.seed)}
        for s in SECTIONS:
            if s in chosen:
                out[s] = {**runs[s](), "measured_at": stamp}
                print(f"{s}: {json.dumps(out[s], default=str)[:600]}", flush=True)
        return {**_headline(out), **out}

    run_tool("bench_design", ROOT, compute, argv=sys.argv[1:] if argv is None else list(argv))
    return 0


if __name__ == "__main__":
    sys.exit(main())
