"""Validate the gap diagnosis on shots whose effect is present but withheld from the analyst.

For each case, ``--trials`` randomized shots (one of the seven M2 M0.70 sample shots, a random
noise seed, a random size and sign of the effect) are simulated WITH the effect, measured with
stage one's precision (0.28 um, 0.0012 deg), fitted WITHOUT it (Table 4 M2 M0.70 forms, the
shot file's nominal mass properties, no biases; M1 M1.10 for the cases named in
``M1_CASES``), and diagnosed blind
(:func:`cadra.gap.score.diagnose_gap`). Cases: every library effect that an M2 shot can show
(dynamics: lateral cg offset, inertia asymmetry, products of inertia, density gradient,
cross-flow; aero: a missing higher-order C_m term, an alpha-dependent C_mq term, Mach
dependence of C_m; measurement: a station's position bias, timing bias, optical scale);
null shots (no effect); and an effect outside the library (angle biases of stage one at one or
two stations). The Magnus moment is not validated: the M2 shots do not spin (p = 0), so it has
no effect to find.

Sizes (physically realistic; a draw whose effect does not *matter* -- the fit without it has
a residual rms at least 20 % above the clean fit's in some channel, or moves an aero
coefficient by more than its sigma -- is not a trial of its case and is drawn again, at most
five times; the count is printed): cg offset 0.1-0.3 mm along y or z;
principal transverse inertia difference 0.05-0.2 % of Iyy with its axes at a random roll
angle (M1, swinging +-40 deg); one product of inertia Ixy or Ixz 3-8 % of Iyy (in one shot of
a set of three); density gradient 1-3e-3 per m (2-7 % over the range); cross-flow 0.5-1.5 m/s;
C_m += a s^3 with a s_max^3 = (0.07-0.15) |Cm_A1| s_max (in every shot of a set of three;
s_max the set's largest |s|; larger destabilizing terms change the motion so much that even
the true model, fitted from linear-theory starts, lands in another basin),
C_mq += (30-80) s^2 with s = sin(alpha) - sin(alpha_ref); C_m += (0.05-0.15)(M - M_nom);
station position bias 2-5 um in y or z at one station of three M2 shots; timing bias 50-150
ns at one station of three sphere shots; optical scale 3-8e-4 at one station of three M2
shots (the M2 sets each launched at its own lateral offset, ``OFFSET_CASES``); angle biases
0.01-0.03 deg.
Random signs. Sets: ``SET_CASES``. The cases, shots and sets are
:mod:`cadra.validation.gap_cases`; the trials :mod:`cadra.validation.gap_trials`; the
scoring :mod:`cadra.validation.gap_scoring` and :mod:`cadra.validation.gap_summary`.

Per case: top-1 rate (the injected effect ranks first; ``top1_alias`` also counts it when it is
named as indistinguishable from the first), size within 2 sigma (every parameter of the
effect; a body effect's pair, ``BODY_PAIRS``, by its magnitude across the axis, tested by
its linearized profile likelihood with the refit's covariance -- and, printed beside it, as
a vector with the truth turned into the fit's body frame; within the diagnosis'
profile-likelihood interval where it gave one),
shrink ratio (after adding the effect, residual rms per channel / rms of a fit of the same
shot and noise without the effect; max over channels; also pooled over the case's trials,
against the final model fitted to the same data from the truth, predicted from the two
fits' Jacobians and the noise drawn, and the fraction of trials above 1.10 beside the
fraction a perfect diagnosis would have, ``linear_shrink``), null: "no significant effect";
out of library: reported unexplained with an injected station/channel among the three
named.
Last line: a JSON object, also recorded as ``results/validate_gap.json``
(:func:`cadra.validation.results.record`). With the detection scan
(``tools/gap_detection.py``, :mod:`cadra.validation.gap_detection`) its keys join the line.

Usage:
    python tools/validate_gap.py [--trials 20] [--seed 6] [--cases cg,null,...]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

from cadra.validation.gap_summary import case_line, summarize, trial_notes
from cadra.validation.gap_trials import CASES, multifit_timing, run_case
from cadra.validation.tool import run_tool

ROOT = Path(__file__).resolve().parents[1]


def detection(cases, trials, seed) -> dict:
    """The detection-efficiency scan (tools/gap_detection.py) of the library effects among
    ``cases``: its keys (``detection_efficiency_max`` ...) join the JSON line."""
    from cadra.validation.gap_detection import CASES as DETECTION_CASES
    from cadra.validation.gap_detection import detection_summary

    chosen = [c for c in cases if c in DETECTION_CASES]
    return detection_summary(chosen, trials, seed + 15, progress=True) if chosen else {}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--seed", type=int, default=6)
    parser.add_argument("--cases", default=",".join(CASES))
    parser.add_argument("--no-multifit", action="store_true",
                        help="skip the seven-shot multi-fit diagnosis timing")
    parser.add_argument("--no-detection", action="store_true",
                        help="skip the detection-efficiency scan (tools/gap_detection.py, "
                             "~1 h for 20 trials per effect)")
    parser.add_argument("--verbose", action="store_true",
                        help="also list trials whose size or shrink ratio fails")
    args = parser.parse_args(argv)
    cases = [c for c in args.cases.split(",") if c]
    run_tool("validate_gap", ROOT, lambda: run(cases, args), argv=argv,
             seconds_key="total_seconds")
    return 0


def run(cases, args) -> dict:
    """Every case's trials, a line a case printed; the summary with the timing and the
    detection scan unless ``args`` leaves them out."""
    rng = np.random.default_rng(args.seed)
    per, redrawn = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for case in cases:
            per[case], redrawn[case] = run_case(case, rng, tmp, args.trials, progress=True)
            print(case_line(case, per[case], redrawn[case]))
            for line in trial_notes(case, per[case], args.verbose):
                print(line)
    return {
        **summarize(per, redrawn, args.trials),
        **({} if args.no_multifit else multifit_timing()),
        **({} if args.no_detection else detection(cases, args.trials, args.seed)),
    }


if __name__ == "__main__":
    sys.exit(main())
