"""Stage one on distorted records, against the renderer's exact truth (the harness is
cadra.validation.distortion; docs/validation.md).

Station 1 of the bundled HFFAF range, each view recording through its own seed-002-size
distortion (0.3 deg at most on a line's direction, at the corners): each view's distortion
calibrated from a rendered dot grid; the M2 capsule at random poses across the window,
measured undistorted (the reference), distorted with the calibrated distortion declared,
distorted and resampled to ideal images (the alternative not taken), and distorted with none
declared. The first cases are also rendered through a small radial distortion (0.014 deg)
none declares, measured with stage one finding it from the wires' bow and without.
Figures: the calibrated case's errors over the reference's (the axis angle's rms ratio: at
most 1.2), its sigma honesty, the calibrations' pulls, how often an undeclared distortion is
named, and the 3-D errors of the undeclared ones over the reference's.

Usage: python tools/validate_distortion.py [--cases 60] [--undeclared 20] (about 15 s a
case and 40 s more an undeclared one on one core). The last printed line is a JSON object,
recorded in results/validate_distortion.json.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from cadra.validation.tool import one_thread, round_figures, run_tool

one_thread()

from cadra.validation.distortion import run as run_cases  # noqa: E402 (after one_thread)
from cadra.validation.distortion import summarize  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", type=int, default=60)
    ap.add_argument("--undeclared", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    run_tool("validate_distortion", ROOT, lambda: run(args), argv=argv, seconds_key="run_s")
    return 0


def run(args) -> dict:
    from tqdm import tqdm

    from cadra.io.facility_file import load_facility

    station = load_facility("hffaf").stations[0]
    bar = tqdm(total=args.cases, desc="cases", file=sys.stderr)
    out = run_cases(station, args.cases, args.undeclared, args.seed,
                    progress=lambda i: bar.update(1))
    bar.close()
    s = summarize(out)
    print(json.dumps(round_figures(s)), flush=True)
    fig = {"distortion_max_angle_deg": s["max_angle_deg"],
           "distortion_angle_rms_ratio": s["angle_rms_ratio"],
           "distortion_angle_rms_ratio_se": s["angle_rms_ratio_se"],
           "distortion_view_rms_ratio_max": max(s["view_rms_ratio"]),
           "distortion_resampled_view_rms_ratio_max": max(s["resampled_view_rms_ratio"]),
           "distortion_3d_rms_ratio_max": max(s["rms_ratio_3d"]),
           # the station's sigmas (a view's silhouette sigma leaves out the wires' map and
           # the distortion's calibration, which the station adds)
           "distortion_sigma_ratio_min": min(s["calibrated"]["sigma_ratio_3d"]),
           "distortion_sigma_ratio_max": max(s["calibrated"]["sigma_ratio_3d"]),
           "distortion_calibration_pull_std_min": s["calibration_pull_std_min"],
           "distortion_calibration_pull_std_max": s["calibration_pull_std_max"],
           "distortion_calibration_pull_mean_abs_max": s["calibration_pull_mean_abs_max"],
           "distortion_cases_both_ok": s["cases_both_ok"],
           "distortion_undeclared_named_frac": s.get("undeclared_named_frac"),
           "distortion_undeclared_3d_rms_ratio_max": _max(s.get("undeclared_rms_ratio_3d")),
           "distortion_small_named_frac": s.get("small_named_frac"),
           "distortion_small_found_3d_rms_ratio_max": _max(s.get("small_found_rms_ratio_3d")),
           "distortion_small_ignored_3d_rms_ratio_max":
               _max(s.get("small_ignored_rms_ratio_3d")),
           "distortion_plain_named_frac": s["plain_named_frac"]}
    return {"summary": round_figures(s), "calibration": out["calibration"], "fitted": out["fitted"],
            **round_figures(fig)}


def _max(values):
    return None if values is None else max(values)


if __name__ == "__main__":
    sys.exit(main())
