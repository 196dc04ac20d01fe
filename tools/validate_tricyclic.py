"""Seed 002 Table 2 re-run: tricyclic fits to 6-DOF simulations of Jaffe's Run 21, a 60 deg
blunt cone flown free in the JPL supersonic wind tunnel, with the table's perturbations, and
the gap diagnosis of what the tricyclic fit could only leave as a residual.

Each case is simulated by CADRA's 6-DOF dynamics in the ``tunnel`` test mode (the model,
nose upstream, drifts downstream in a uniform stream; docs/dynamics.md "Test modes"), sampled
at the movie's 2000 frames/s, turned into the paper's measured angles (the vertical and
horizontal projected angles of the axis, then seed 002 eqs. 6-7's fixed-plane angles) and
fitted by ``cadra.motion.fit_epicyclic`` in the air's distance x = integral of V dt, as the
paper does, in its four programs: 10-constant, 10-constant with the nonrolling-axis
correction (NR, eq. 8, one iteration), 12-constant (eq. 12's phi'' terms) and 12-constant
with NR. The rms angle-of-attack deviations (rms |xi - xi_fit|, deg) are printed beside the
paper's Table 2 (its rows placed as the text describes them).

Then ``cadra2 diagnose`` (the CLI, in process; docs/gap.md) is run on the mass-asymmetry and
flow cases written as a tunnel shot file and trajectory file with measurement noise: the 6-DOF
fit with the truth's aerodynamic forms (free coefficients) and the nominal, symmetric body,
started from the epicyclic fit's arms (cadra.flight.starts.epicyclic_estimates), then the
ranking of the gap library. What it names is printed and returned as it is.

The seed omits the cubic C_m, C_N alpha, C_D, C_mq, the mass (its printed value is garbled) and
the initial conditions: the choices are cadra.validation.tricyclic's constants, each with its
reason (docs/motion.md, "Seed 002 Table 2"); the tables are cadra.validation.tricyclic_table's,
the diagnosis cadra.validation.tricyclic_gap's.

Usage: python tools/validate_tricyclic.py [--no-diagnose] [--no-sensitivity] [--noise-deg 0.1]
[--paper-noise] [--cli] [--seed 1]   (about 5 min on one core; --paper-noise --cli: about 8)
Last line: a JSON object (seed002_ordering_matches, seed002_nr_lowers_rms_frac,
seed002_cubic_12nr_over_10_ratio, seed002_diagnose_named, seconds and the per-case figures).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

one_thread()

from cadra.cli.cadra2 import main as cadra2_main  # noqa: E402 (after one_thread)
from cadra.validation.tricyclic_table import run  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--no-diagnose", action="store_true", help="the tricyclic table only")
    ap.add_argument("--noise-deg", type=float, default=0.1,
                    help="angle noise of the diagnosed records, deg (default 0.1)")
    ap.add_argument("--paper-noise", action="store_true",
                    help="also diagnose Table 2's mass and flow cases at the paper's blunt-body "
                         "accuracy, 0.5 deg")
    ap.add_argument("--cli", action="store_true",
                    help="also run the cg case through the cadra2 diagnose command itself "
                         "(its own epicyclic start; about 2 min)")
    ap.add_argument("--no-sensitivity", action="store_true",
                    help="skip the tricyclic table's sensitivity to the unstated choices")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    run_tool("validate_tricyclic", ROOT, lambda: run(
        diagnosis=not args.no_diagnose, noise_deg=args.noise_deg, paper_noise=args.paper_noise,
        cadra2_main=cadra2_main if args.cli else None,
        with_sensitivity=not args.no_sensitivity, seed=args.seed), argv=argv)


if __name__ == "__main__":
    main()
