"""End-to-end honesty: shadowgraphs -> cadra1 -> cadra2 over many realisations.

For each seed-004 set (the M2 M0.70 and M1 M1.10 seven-shot sets of the sample specs) and
each realisation r, every shot is flown with its spec but a new seed (new trigger offsets,
new fixed illumination and clutter pattern, new film grain and noise), rendered, measured by
stage one, and the set is fitted by stage two with the case's Table 4 forms, every free
parameter started at ZERO (the automatic starting values do the rest). Reported per
parameter over the realisations: the pulls (fit - truth) / sigma, their mean and standard
deviation, the fraction within 2 sigma; and chi^2/nu against the scatter that chi^2 with the
fit's degrees of freedom allows.

A third fit of the same end-to-end data uses cadra2's per-channel variance components
(``fit_shots(..., variance_components=True)``, ``cadra2 fit --variance-components``): each
channel's sigmas rescaled by the factor the fit's own residuals ask for.

Beside each realisation runs the CONTROL: the same stations and the same stage-one sigmas,
but the measurements replaced by the images' exact truth plus Gaussian noise of those sigmas.
The control has honest errors by construction, so its pulls check the benchmark itself.

Stage one's own errors are summarised too: (measured - truth) / sigma per channel, their
standard deviation, and the shot-wide part (the variance of each shot's mean error, times
the stations per shot, over the within-shot variance: 1 for independent errors).

Usage::

    python tools/bench_e2e.py                    # 20 realisations a set (23 min; 40: 45 min)
    python tools/bench_e2e.py --realisations 3   # a smoke run

The last printed line is a JSON object (e2e_pull_std_min/max, e2e_pull_abs_mean_max,
e2e_within_2sigma_frac, e2e_chi2nu_median, control_pull_std_max, realisations,
seconds_per_realisation, and per-set details).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

one_thread(("OMP_NUM_THREADS",))

from cadra.validation.e2e import SETS, run_bench  # noqa: E402 (after one_thread)

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--realisations", type=int, default=20,
                        help="realisations per set (default 20)")
    parser.add_argument("--sets", nargs="+", default=list(SETS), choices=list(SETS),
                        help="seven-shot sets (default both)")
    parser.add_argument("--seed", type=int, default=18, help="benchmark seed (default 18)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                        help="processes (default: the cores)")
    parser.add_argument("--no-variance-components", dest="variance_components",
                        action="store_false",
                        help="skip the third fit of each realisation, the end-to-end fit "
                             "with cadra2's per-channel variance components")
    args = parser.parse_args(argv)
    run_tool("bench_e2e", ROOT, lambda: run_bench(
        ROOT, args.realisations, args.sets, args.seed, args.workers, args.variance_components),
        argv=argv, seconds_key=None)
    return 0


if __name__ == "__main__":
    sys.exit(main())
