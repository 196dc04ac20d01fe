"""The seeds' evaluations of the classic angular-motion reductions re-run: seed 001 Table II
(1-DOF nonlinear pitch), seed 000 Table 2 and seed 001 Table V (3-DOF nonlinear epicyclic
motion with spin and Magnus on a wind-tunnel gimbal).

Each case is simulated by CADRA's 6-DOF dynamics in the matching test mode (``pitch_pivot``,
``gimbal``), reduced by the classic method of ``cadra.motion`` (sectional fits and the
Kryloff-Bogoliuboff reduction) and fitted by CADRA's 6-DOF fit (``cadra.fitting.solver.fit``)
with the same forms, quadratic in the angle. Errors per coefficient are printed beside the
paper's; with noise, the CADRA fit's pulls (fit - truth) / sigma over the draws.

The seeds omit mass data and initial conditions: the choices are the constants of
cadra.validation.motion_cases (docs/motion.md, "Validation against the seeds"); the tables
are cadra.validation.motion_validation's.

Usage: python tools/validate_motion.py [--draws 10] [--seed 1] [--no-sensitivity]
(3.7 min on one core with the default 10 draws; --draws 50, the acceptance's pulls: 16 min).
Last line: a JSON object (classic_over_paper_error_max, cadra_over_classic_error_max,
cadra_pull_std_min, cadra_pull_std_max, m80_within_2sigma_frac, npr_planar, npr_circular,
epicyclic_fit_ms, kb_reduction_s and the per-case figures).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

one_thread()

from cadra.validation.motion_validation import run  # noqa: E402 (after one_thread)

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--draws", type=int, default=10, help="noise draws per noise case")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-sensitivity", action="store_true",
                    help="skip the classic method's sensitivity to the unstated record")
    args = ap.parse_args(argv)
    run_tool("validate_motion", ROOT, lambda: run(args.draws, args.seed, not args.no_sensitivity),
             argv=argv, seconds_key="run_s")


if __name__ == "__main__":
    main()
