"""Do cadra2's starting values gain from the epicyclic fit?

``cadra2 fit`` starts every free coefficient from linear theory (cadra.fitting.start): damped
sines of theta and psi give a pitch frequency and damping, hence C_m_alpha = -omega^2 I/(q S d)
and C_mq. ``cadra.flight.starts.epicyclic_estimates`` gives the same targets from the epicyclic
fit's two arms instead (C_m_alpha = I (omega_1 omega_2 - lambda_1 lambda_2)/(q S d), with the
swerve's lift; docs/motion.md). This bench fits the same data from both starts, every free
parameter at ZERO in the model file, and reports per case: the starting C_m_alpha and C_mq
against the truth, how many fits converge to the truth's chi^2 (within 1 + 3 sqrt(2/nu) of the
fit from the truth's values), iterations and seconds.

Cases (each over ``--draws`` noise draws of a simulated shot: truth + Gaussian noise, 20 um and
0.05 deg, the CONE-1 stations of the HFFAF):

- ``cone``: CONE-1 as bundled (10 deg cone, C_m_alpha -0.49, 62.5 rad/s spin: nearly planar);
- ``cone_spin``: the same cone spun at 1700 rad/s (P = p I_x/I equal to the pitch frequency:
  fast and slow arms at +749 and -287 rad/s);
- ``cone_gyro``: statically unstable (C_m_alpha +0.30), spun at 3800 rad/s: gyroscopic
  stability factor about 2, as a rifle bullet (BRL MR 1833's M-80: 2.1-2.4).

Usage::

    python tools/bench_starts.py            # 10 draws a case, ~5 min on one core
    python tools/bench_starts.py --draws 3  # smoke run

The last printed line is a JSON object. The cases and figures are
cadra.validation.starts_bench's.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cadra.validation.tool import one_thread, run_tool

one_thread()

from cadra.validation.starts_bench import CASES, run_case, summary  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--draws", type=int, default=10, help="noise draws a case (default 10)")
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    parser.add_argument("--seed", type=int, default=19)
    args = parser.parse_args(argv)
    run_tool("bench_starts", ROOT, lambda: run(args.cases, args.draws, args.seed), argv=argv,
             seconds_key="total_seconds")
    return 0


def run(cases, draws: int, seed: int) -> dict:
    """Every case in ``cases``, printed as it ends; the summary over them."""
    results = {}
    for case in cases:
        print(f"== {case}", flush=True)
        results[case] = run_case(case, draws, seed)
        r = results[case]
        print(f"   gyroscopic stability factor {r['gyro_factor']:.2f}; truth C_m_alpha "
              f"{r['truth_Cm_a']:+.3f}, C_mq {r['truth_Cmq_0']:+.2f}")
        for lab in ("linear", "epicyclic"):
            x = r[lab]
            print(f"   {lab:9s}: start C_m_alpha {x['start_Cm_a_median']:+.3f}, C_mq "
                  f"{x['start_Cmq_0_median']:+.2f} (medians); to the truth's chi^2 "
                  f"{x['to_truth_frac']:.2f}; {x['iterations_median']:.0f} iterations, "
                  f"{x['seconds_median']:.1f} s (medians)")
    return summary(results, draws)


if __name__ == "__main__":
    sys.exit(main())
