"""Stage one and the whole chain on point-source (direct-shadowgraph) stations, against the
renderer's exact truth (the harness is cadra.validation.point_source; docs/validation.md).

Sections, all on station 3 of the bundled point-source range ``facilities/brl_spark.toml``
(sparks 1.5 m from the line of flight, films 0.3 m beyond it, magnification 1.2):

1. **accuracy**: a sphere and the M2 capsule of the parallel bench's size (35.6 mm) and the
   M-80 bullet, each at random poses within +-10 mm of the line of flight and +-10 deg:
   per view the reference point (px) and image axis angle (deg) -- their rms, the fit's
   sigma over it, the Cramer-Rao bound of the perspective case (the exact conical outline's
   image-model bound) and the rms over it, and the Otsu-and-moments baseline's rms over
   CADRA's -- and the same in 3-D (x, y, z in m; theta, psi in rad; the bound, with the film
   map's error the wires leave, carried through the rays and planes from the sparks);
2. **depth**: the M-80 off the line of flight by 50 mm in y and in z (the four corners):
   its 3-D error over the bound, and the same images measured as if the optics were
   parallel (the sparks taken away): that assumption's error in x, y, z;
3. **calibration**: the three biased sphere sample shots flown through this range, rendered,
   measured and calibrated: the injected station biases recovered (within 2 sigma, flags),
   as tools/bench_calibration.py --e2e does on the parallel range;
4. **roll** (``--roll-cases``): the Basic Finner at the sample shot's size (7 mm) at random
   poses and rolls: its roll through the shadows' cones (error rms, sigma over it), with the
   3-D pose's figures as in 1;
5. **end to end** (``--e2e-draws``; 0 skips it): the two M-80 sample rounds flown through
   this range, rendered, measured and fitted (6-DOF, both rounds, as tools/validate_m80.py
   does on the parallel range): pulls of the free coefficients, the fraction within
   2 sigma, chi^2/nu against its expected scatter.

Usage: python tools/validate_point_source.py [--cases 100] [--depth-cases 40] [--crb 4]
[--roll-cases 30] [--e2e-draws 8] (about 1.3 s a case, 2 s a bound, 10 s a finned case,
25 s a draw on one core: 20 min in all).
The last printed line is a JSON object, recorded in results/validate_point_source.json.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from cadra.validation.tool import one_thread, round_figures, run_tool

one_thread()

from cadra.validation.point_source import (  # noqa: E402 (after one_thread)
    BODIES,
    FACILITY,
    FINNER,
    calibration_e2e,
    e2e_draws,
    run_cases,
    summarize,
)

ROOT = Path(__file__).resolve().parents[1]
STATION_INDEX = 2
DEPTH_OFFSETS_M = ((0.05, 0.05), (0.05, -0.05), (-0.05, 0.05), (-0.05, -0.05))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", type=int, default=100, help="random cases per body")
    ap.add_argument("--depth-cases", type=int, default=40, help="M-80 cases 50 mm off axis")
    ap.add_argument("--crb", type=int, default=4, help="cases per body given a bound")
    ap.add_argument("--roll-cases", type=int, default=30, help="finned cases (roll)")
    ap.add_argument("--e2e-draws", type=int, default=8, help="end-to-end draws (0: none)")
    args = ap.parse_args(argv)
    s = run_tool("validate_point_source", ROOT, lambda: run(args), argv=argv,
                 seconds_key="run_s")
    return 0 if s.get("e2e", {}).get("failures", []) == [] else 1


def run(args) -> dict:
    from cadra.io.facility_file import load_facility

    station = load_facility(FACILITY).stations[STATION_INDEX]
    out = {"facility": FACILITY, "station": station.id, "accuracy": {}}
    for k, (name, spec) in enumerate(BODIES.items()):
        s = summarize(run_cases(station, spec, args.cases, seed=100 + k, n_crb=args.crb))
        out["accuracy"][name] = round_figures(s)
        print(f"{name}: {json.dumps(out['accuracy'][name])}", flush=True)
    depth = summarize(run_cases(station, BODIES["bullet"], args.depth_cases, seed=200,
                                offsets=DEPTH_OFFSETS_M, n_crb=min(args.crb, 4), parallel=True))
    out["depth"] = round_figures(depth)
    print(f"depth: {json.dumps(out['depth'])}", flush=True)
    if args.roll_cases > 0:
        out["roll"] = round_figures(summarize(run_cases(station, FINNER, args.roll_cases,
                                                        seed=300)))
        print(f"roll: {json.dumps(out['roll'])}", flush=True)
    out["calibration"] = round_figures(calibration_e2e())
    print(f"calibration: {json.dumps(out['calibration'])}", flush=True)
    if args.e2e_draws > 0:
        out["e2e"] = round_figures(e2e_draws(args.e2e_draws))
    out.update(figures(out))
    return out


def figures(out: dict) -> dict:
    """The headline figures (validation_figures.csv names them)."""
    acc = out["accuracy"]
    view_crb = [r for b in acc.values() for r in b.get("view_crb_ratio", [])]
    crb3 = [r for b in acc.values() for r in b.get("crb_ratio_3d", [])]
    sig = [r for b in acc.values() for r in b["view_sigma_ratio"] + b["sigma_ratio_3d"]]
    otsu = [r for b in acc.values() for r in b["otsu_ratio"]]
    otsu_se = [r for b in acc.values() for r in b["otsu_ratio_se"]]
    d = out["depth"]
    fig = {"ps_view_crb_ratio_max": max(view_crb), "ps_3d_crb_ratio_max": max(crb3),
           "ps_sigma_ratio_min": min(sig), "ps_sigma_ratio_max": max(sig),
           "ps_otsu_ratio_min": min(otsu), "ps_otsu_ratio_min_se": otsu_se[otsu.index(min(otsu))],
           "ps_depth_crb_ratio_max": max(d.get("crb_ratio_3d", [float("nan")])[:3]),
           "ps_parallel_error_max_mm": 1e3 * max(d.get("parallel_max_abs_3d", [float("nan")])),
           "ps_parallel_flagged_frac": d.get("parallel_flagged_frac"),
           "ps_failed_cases": sum(b["n"] - b["n_ok"] for b in acc.values()) + d["n"] - d["n_ok"]}
    if "roll" in out:
        r = out["roll"]
        fig.update(ps_roll_cases_ok=r["n_ok"], ps_roll_cases=r["n"],
                   ps_roll_rms_deg=r.get("roll_rms_deg"),
                   ps_roll_sigma_ratio=r.get("roll_sigma_ratio"),
                   ps_roll_3d_sigma_ratio_min=min(r.get("sigma_ratio_3d", [float("nan")])),
                   ps_roll_3d_sigma_ratio_max=max(r.get("sigma_ratio_3d", [float("nan")])))
    c = out["calibration"]
    fig.update(ps_calibration_within_2sigma_frac=c["injected_within_2sigma_frac"],
               ps_calibration_false_flags=c["false_flags"])
    if "e2e" in out:
        fig.update(ps_e2e_within_2sigma_frac=out["e2e"]["within_2sigma_frac"],
                   ps_e2e_chi2_nu_median=out["e2e"]["chi2_nu_median"],
                   ps_e2e_chi2_nu_max_dev_sigmas=out["e2e"]["chi2_nu_max_dev_sigmas"])
    return round_figures(fig)


if __name__ == "__main__":
    sys.exit(main())
