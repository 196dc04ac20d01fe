"""The gap diagnosis's time now against before, in one run: forward-mode sensitivities and
the fit's lambda search against complex step and Marquardt's classic damping.

Each trial is made as ``tools/validate_gap.py`` makes it (its cases, shots, noise and fit),
then the same fit is diagnosed in three configurations (``cadra.validation.gap_trials.AB_ARMS``):
``before`` (every Jacobian by complex step, the classic damping: the diagnosis before either
change), ``forward`` (forward mode, the classic damping) and ``now`` (forward mode and the
lambda search, the default), in an order reversed every other trial so all see the same
machine and the same load. Printed: each arm's median diagnosis time, the ratios now / before
(of the medians, and the median of the paired ratios with its range) and forward / before,
how often ``now`` and ``before`` named the same effect first and found the same (the effects
added, a gap left unexplained or not, the misfits set aside; the verdict's sentence also
carries sizes, which may differ in their last printed digit), the trials that differ or
where ``now`` was the slower, and the seven-shot multi-fit diagnosis each way. The rows are
scored on the ``now`` diagnosis, as the validation scores them (top-1 rate per case).

Usage: python tools/ab_gap_speed.py [--trials 3] [--seed 6] [--cases cg,density,...]
(about 25 s a trial on one core, 12 min for the default). The last printed line is a JSON
object, recorded in results/ab_gap_speed.json.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

one_thread()

import numpy as np  # noqa: E402 (after one_thread)

from cadra.validation.gap_trials import AB_ARMS, multifit_timing, run_case  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: a case of each kind the library covers: body, aero, air, station effects, a null and an
#: effect outside the library, on single shots and a three-shot set
CASES = "cg,inertia_asym,density,crossflow,cm3,cmq2,station_bias,timing,null,out_of_library"
ARMS = tuple(AB_ARMS)       # before, forward, now


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=3)
    ap.add_argument("--seed", type=int, default=6)
    ap.add_argument("--cases", default=CASES)
    ap.add_argument("--no-multifit", action="store_true",
                    help="skip the seven-shot multi-fit diagnosis")
    args = ap.parse_args(argv)
    run_tool("ab_gap_speed", ROOT, lambda: run(args), argv=argv)
    return 0


def run(args) -> dict:
    from cadra.dynamics import tangent

    tangent.module()              # forward mode's code compiled (or loaded) before any timing
    rng = np.random.default_rng(args.seed)
    rows, by_case = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        for case in [c for c in args.cases.split(",") if c]:
            got, _ = run_case(case, rng, tmp, args.trials, progress=True, ab=ARMS)
            rows += got
            sec = {m: [r["ab_seconds"][m] for r in got] for m in ARMS}
            by_case[case] = {
                "trials": len(got),
                "median_s": {m: float(np.median(sec[m])) for m in ARMS},
                "same_first": sum(r["ab_first"]["before"] == r["ab_first"]["now"]
                                  for r in got),
                "top1_now": sum(bool(r.get("top1")) for r in got)
                if any("top1" in r for r in got) else None}
            print(f"{case}: {by_case[case]}", flush=True)

    def seconds(arm):
        return np.array([r["ab_seconds"][arm] for r in rows])

    ratio = seconds("now") / seconds("before")
    # the trials whose two diagnoses differ in what they found, or where now was the slower
    differing = [{"case": r["case"], "shot": r["shot"], "seconds": r["ab_seconds"],
                  "first": r["ab_first"], "verdicts": r["ab_verdicts"]}
                 for r, q in zip(rows, ratio, strict=True)
                 if r["ab_findings"]["before"] != r["ab_findings"]["now"] or q > 1.0]
    for d in differing:
        print(f"differ: {d}", flush=True)
    med = {m: float(np.median(seconds(m))) for m in ARMS}
    out = {
        "trials": len(rows),
        **{f"diagnosis_median_s_{m}": med[m] for m in ARMS},
        "diagnosis_median_ratio": med["now"] / med["before"],
        "diagnosis_median_ratio_forward": med["forward"] / med["before"],
        "diagnosis_time_ratio_median": float(np.median(ratio)),
        "diagnosis_time_ratio_range": [float(ratio.min()), float(ratio.max())],
        "same_first_rate": float(np.mean([r["ab_first"]["before"] == r["ab_first"]["now"]
                                          for r in rows])),
        "same_finding_rate": float(np.mean([r["ab_findings"]["before"]
                                            == r["ab_findings"]["now"] for r in rows])),
        "same_verdict_text_rate": float(np.mean([r["ab_verdicts"]["before"]
                                                 == r["ab_verdicts"]["now"]
                                                 for r in rows])),
        "by_case": by_case, "differing": differing}
    if not args.no_multifit:
        mf = multifit_timing(methods=ARMS)
        out["multifit_diagnosis_s"] = mf["multifit_ab_seconds"]
        out["multifit_time_ratio"] = (mf["multifit_ab_seconds"]["now"]
                                      / mf["multifit_ab_seconds"]["before"])
        out["multifit_same_first"] = (mf["multifit_ab_first"]["before"]
                                      == mf["multifit_ab_first"]["now"])
    return out


if __name__ == "__main__":
    sys.exit(main())
