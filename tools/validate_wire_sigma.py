"""Is the wire affine's reported uncertainty honest at the model's position? (issue 18)

Renders wire-only views like ``tests/test_wires.py``'s (HFFAF station 1 top and 5 side, a
perturbed film affine per placement, default realism), measures them with
:func:`cadra.measure.wires.fit.measure_wires` and compares the solved map of the image centre
(where the model flies) with the true map, in units of the reported
``WireMeasurement.position_sigma_m`` (a along the range, b across it). Each placement is
rendered twice: with the default noise, and noise-free (same wires, same placement), whose
error is the deterministic part; both are divided by the noisy render's sigma.

Usage::

    OMP_NUM_THREADS=1 PYTHONPATH=. python tools/validate_wire_sigma.py [--n 120] [--centroid]
        [--blur PX]

``--centroid`` measures with the centroids and their phase term instead of the profile model
(the default); ``--blur`` renders with another optics blur.

The last printed line is a JSON object: the rms of error / sigma (a, b) with noise and
noise-free, the median reported sigma (um) and the number of renders.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from test_wires import FAC, QUIET, VIEWS, make_image, true_affine  # noqa: E402

from cadra.geometry import apply_affine  # noqa: E402
from cadra.measure.wires.fit import measure_wires  # noqa: E402
from cadra.synthetic.render import RenderConfig  # noqa: E402


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=120, help="renders (split over the two views)")
    ap.add_argument("--seed0", type=int, default=1000)
    ap.add_argument("--centroid", action="store_true",
                    help="centroid centres with the phase term (profile_model=False)")
    ap.add_argument("--blur", type=float, default=None,
                    help="optics blur sigma (px) of the renders (default: the renderer's)")
    args = ap.parse_args(argv)
    model = not args.centroid
    noisy_cfg, quiet_cfg = RenderConfig(), QUIET
    if args.blur is not None:
        noisy_cfg = replace(noisy_cfg, optics_blur_sigma_px=args.blur)
        quiet_cfg = replace(quiet_cfg, optics_blur_sigma_px=args.blur)
    err_um = []
    z_noisy, z_quiet, sig, sig_sys, gains = [], [], [], [], []
    for k in range(args.n):
        station, name = VIEWS[k % len(VIEWS)]
        view = FAC.view(station, name)
        seed = args.seed0 + k
        M = true_affine(view, 100 * station + seed)
        centre = np.array([[(view.width_px - 1) / 2.0, (view.height_px - 1) / 2.0]])
        truth = apply_affine(M, centre)[0]
        res = measure_wires(make_image(view, M, noisy_cfg, seed=seed), view,
                            profile_model=model)
        quiet = measure_wires(make_image(view, M, quiet_cfg, seed=seed), view,
                              profile_model=model)
        if not (res.ok and quiet.ok):
            print(f"render {k}: {res.reason or quiet.reason}")
            continue
        s = res.position_sigma_m(centre[0])
        z_noisy.append((apply_affine(res.affine, centre)[0] - truth) / s)
        err_um.append((apply_affine(res.affine, centre)[0] - truth) * 1e6)
        z_quiet.append((apply_affine(quiet.affine, centre)[0] - truth) / s)
        sig.append(s)
        sig_sys.append([getattr(f, "sigma_sys_px", 0.0) for f in res.wires])
        gains.append(getattr(res, "phase_gain", (np.nan,) * 3))
    z_noisy, z_quiet, sig = np.array(z_noisy), np.array(z_quiet), np.array(sig)
    rms = lambda z: [round(float(x), 3) for x in np.sqrt(np.mean(z ** 2, axis=0))]  # noqa: E731
    out = {"n": len(sig), "centres": "profile model" if model else "centroid",
           "blur_px": args.blur, "z_rms_ab": rms(z_noisy),
           "z_rms_noise_free_ab": rms(z_quiet),
           "error_rms_um_ab": [round(float(x), 4)
                               for x in np.sqrt(np.mean(np.square(err_um), axis=0))],
           "sigma_median_um_ab": [round(float(x), 4) for x in np.median(sig, axis=0) * 1e6],
           "sigma_sys_px_median": round(float(np.median(sig_sys)), 5),
           "sigma_sys_px_max": round(float(np.max(sig_sys)), 5),
           # the centroids' phase gain (NaN with the profile model, which has none)
           "phase_gain_median": ([round(float(x), 3) for x in np.nanmedian(gains, axis=0)]
                                 if np.isfinite(gains).any() else None)}
    print(f"{out['centres']}: error / sigma at the image centre, {out['n']} renders: rms a "
          f"{out['z_rms_ab'][0]}, b {out['z_rms_ab'][1]}; noise-free "
          f"{out['z_rms_noise_free_ab']}; error rms {out['error_rms_um_ab']} um; sigma "
          f"{out['sigma_median_um_ab']} um")
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
