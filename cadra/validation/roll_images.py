"""Stage one on the Basic Finner against the renderer's exact truth: roll, position, axis (the
work of ``tools/validate_roll_images.py``; docs/stage1.md, "Roll of a finned body").

Each case is one HFFAF station (both views, 1600 x 1200 px, default realism: default
``RenderConfig``, film placement, wires, clutter) showing the sample shot's finned body
(``sample_shots/specs/finner_1.toml``: the Basic Finner at d = 0.7 cm, 551 px long) at a
random roll (uniform over a turn), a random axis within 3 deg of the range axis and a random
reference point within 5 mm of the station's centre, flying at 690 m/s (motion blur, a Mach 2
bow shock). The images are measured by ``cadra.imaging.station.measure_station`` (wires, pose
fit, the roll). The station's best roll candidate is compared with the truth modulo 90 deg
(one station: no continuity); the Cramér–Rao bound of each view's roll
(``cadra.synthetic.crb_roll``, pose and nuisances marginalized) on every case, combined over
the views as the measurement combines them (inverse variance).

:func:`summarize`'s figures: roll error rms (per view and combined, and per fold bin) over
the rms bound; the reported sigma over the actual error (rms over rms), per view and combined
and over three bins of the roll's distance from the nearest mirror fold (0 or 45 deg modulo
90: near a fold the two mirror solutions merge); the per-view reference-point error (px) and
image axis-angle error (deg) over the M2 capsule's figures of tools/bench_cadra1.py. :func:`run`
makes the cases and the figures.
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from pathlib import Path

import numpy as np

__all__ = ["CAPSULE_AXIS_DEG", "CAPSULE_POSITION_PX", "FOLD_BINS", "run", "summarize"]

#: the sample shots' specs
SPECS_DIR = Path(__file__).resolve().parents[2] / "sample_shots" / "specs"
#: the M2 capsule's per-view reference-point rms (px) and axis rms (deg), bench_cadra1
CAPSULE_POSITION_PX = 0.00196
CAPSULE_AXIS_DEG = 0.00141
#: bins of the roll's distance from the nearest mirror fold, deg
FOLD_BINS = ((0.0, 3.0), (3.0, 10.0), (10.0, 22.5))


def _wrap90(x_deg):
    return (np.asarray(x_deg) + 45.0) % 90.0 - 45.0


def _rms(x):
    x = np.asarray(x, dtype=float)
    return float(np.sqrt(np.mean(x * x))) if x.size else math.nan


def _case(i, shot, rng, tmp, config, crb=True):
    """Render one random station of the finner (``shot``: the simulated FINNER-1) into
    ``tmp`` and measure it; the per-case figures (``crb``: with the views' Cramér–Rao
    bounds)."""
    from cadra.conventions import body_to_facility_matrix, quat_from_axis_roll
    from cadra.imaging.station import measure_station
    from cadra.synthetic.crb_roll import roll_crb
    from cadra.synthetic.render import render, write_image
    from cadra.synthetic.simulate import film_affine, view_scene

    facility = shot.facility
    k = int(rng.integers(len(facility.stations)))
    station = facility.stations[k]
    roll = rng.uniform(-math.pi, math.pi)
    tilt = np.radians(rng.uniform(0.0, 3.0))
    az = rng.uniform(0.0, 2.0 * math.pi)
    axis = np.array([math.cos(tilt), math.sin(tilt) * math.cos(az), math.sin(tilt) * math.sin(az)])
    R = body_to_facility_matrix(quat_from_axis_roll(axis, roll))
    # the body's middle near the station's centre: the reference point is the base centre
    r_ref = (np.array([station.x_m, 0.0, 0.0]) - 0.5 * shot.body.length_m * axis
             + rng.uniform(-0.005, 0.005, 3))
    v = np.array([690.0, 0.0, 0.0])
    paths, truth, crbs = {}, {}, {}
    cfg = config.replace(seed=int(rng.integers(1 << 30)), bow_shock_mach=2.0)
    for name, view in sorted(station.views.items()):
        affine = film_affine(view.image_to_plane, shot.spec.film, rng, view.width_px,
                             view.height_px)
        scene, tr = view_scene(shot.body, view, affine, R, r_ref, v)
        img = render(scene, cfg, rng)
        paths[name] = str(tmp / f"case{i:03d}_{name}.png")
        write_image(paths[name], img, overwrite=True)
        truth[name] = tr
        if crb:
            proj = view.optics(affine)

            def outline(g, proj=proj):
                Rg = body_to_facility_matrix(quat_from_axis_roll(axis, g))
                return proj.from_plane(proj.outline(shot.body, Rg, r_ref))

            crbs[name] = roll_crb(outline, roll, (tr["u_ref_px"], tr["v_ref_px"]), cfg,
                                  motion_blur_px=scene.motion_blur_px,
                                  width_px=view.width_px, height_px=view.height_px)
    t0 = time.perf_counter()
    res = measure_station(station, paths, shot.spec.model, overlays=False)
    seconds = time.perf_counter() - t0
    for p in paths.values():
        os.remove(p)
    out = {"station": station.id, "roll_deg": math.degrees(roll), "status": res.status,
           "reason": res.reason, "measure_s": seconds}
    if res.pose is None or res.roll is None:
        return out
    best = res.roll.best
    roll_deg = math.degrees(roll)
    out["roll_err_deg"] = float(_wrap90(math.degrees(best.roll_rad) - roll_deg))
    out["roll_sigma_deg"] = math.degrees(best.sigma_rad)
    out["mirror_chi2"] = (res.roll.candidates[1].chi2_excess if len(res.roll.candidates) > 1
                          else math.nan)
    m90 = roll_deg % 90.0
    out["fold_distance_deg"] = float(min(m90 % 45.0, 45.0 - m90 % 45.0))
    for name, tr in truth.items():
        vr = best.views[name]
        fit = res.views[name].fit
        out[f"{name}_roll_err_deg"] = float(_wrap90(math.degrees(vr.roll_rad) - roll_deg))
        out[f"{name}_roll_sigma_deg"] = math.degrees(vr.sigma_rad)
        out[f"{name}_roll_sigma_formal_deg"] = math.degrees(vr.sigma_formal_rad)
        out[f"{name}_du_px"] = fit.ref_px[0] - tr["u_ref_px"]
        out[f"{name}_dv_px"] = fit.ref_px[1] - tr["v_ref_px"]
        out[f"{name}_axis_err_deg"] = float(
            (math.degrees(fit.axis_angle_px_rad) - tr["axis_angle_image_deg"] + 180.0) % 360.0
            - 180.0)
        if crb:
            out[f"{name}_crb_deg"] = math.degrees(crbs[name].sigma_roll_rad)
            out[f"{name}_crb_known_pose_deg"] = math.degrees(
                crbs[name].sigma_roll_known_pose_rad)
    if crb:
        out["crb_deg"] = 1.0 / math.sqrt(sum(out[f"{n}_crb_deg"] ** -2 for n in truth))
    return out


def summarize(rows) -> dict:
    """The figures of the module docstring from the per-case rows."""
    ok = [r for r in rows if "roll_err_deg" in r]
    views = ("top", "side")
    e = np.array([r["roll_err_deg"] for r in ok])
    s = np.array([r["roll_sigma_deg"] for r in ok])
    out = {"renders": 2 * len(rows), "stations": len(rows), "measured": len(ok),
           "roll_rms_deg": _rms(e), "roll_bias_deg": float(np.mean(e)) if len(e) else math.nan,
           "roll_max_abs_deg": float(np.max(np.abs(e))) if len(e) else math.nan,
           "roll_sigma_rms_deg": _rms(s)}
    ratios = {"combined": _rms(s) / _rms(e)}
    for n in views:
        ratios[n] = (_rms([r[f"{n}_roll_sigma_deg"] for r in ok])
                     / _rms([r[f"{n}_roll_err_deg"] for r in ok]))
        out[f"{n}_roll_rms_deg"] = _rms([r[f"{n}_roll_err_deg"] for r in ok])
        out[f"{n}_roll_sigma_formal_ratio"] = (
            _rms([r[f"{n}_roll_sigma_formal_deg"] for r in ok]) / out[f"{n}_roll_rms_deg"])
    for lo, hi in FOLD_BINS:
        sel = [r for r in ok if lo <= r["fold_distance_deg"] < hi]
        if len(sel) >= 3:
            ratios[f"fold_{lo:g}_{hi:g}"] = (_rms([r["roll_sigma_deg"] for r in sel])
                                             / _rms([r["roll_err_deg"] for r in sel]))
            out[f"roll_rms_fold_{lo:g}_{hi:g}_deg"] = _rms([r["roll_err_deg"] for r in sel])
            out[f"n_fold_{lo:g}_{hi:g}"] = len(sel)
            if "crb_deg" in sel[0]:
                out[f"roll_crb_ratio_fold_{lo:g}_{hi:g}"] = (
                    out[f"roll_rms_fold_{lo:g}_{hi:g}_deg"] / _rms([r["crb_deg"] for r in sel]))
    out["roll_sigma_ratios"] = ratios
    out["roll_sigma_ratio_min"] = min(ratios.values())
    out["roll_sigma_ratio_max"] = max(ratios.values())
    if ok and "crb_deg" in ok[0]:
        out["roll_crb_rms_deg"] = _rms([r["crb_deg"] for r in ok])
        out["roll_crb_ratio"] = out["roll_rms_deg"] / out["roll_crb_rms_deg"]
        for n in views:
            out[f"{n}_roll_crb_ratio"] = (out[f"{n}_roll_rms_deg"]
                                          / _rms([r[f"{n}_crb_deg"] for r in ok]))
        out["roll_crb_known_pose_over_marginal"] = float(np.mean(
            [r[f"{n}_crb_known_pose_deg"] / r[f"{n}_crb_deg"] for r in ok for n in views]))
    pos = [r[f"{n}_{c}_px"] for r in ok for n in views for c in ("du", "dv")]
    ax = [r[f"{n}_axis_err_deg"] for r in ok for n in views]
    out["position_rms_px"] = _rms(pos)
    out["axis_rms_deg"] = _rms(ax)
    out["position_err_ratio_vs_capsule"] = _rms(pos) / CAPSULE_POSITION_PX
    out["axis_err_ratio_vs_capsule"] = _rms(ax) / CAPSULE_AXIS_DEG
    mirror = [r["mirror_chi2"] for r in ok if math.isfinite(r["mirror_chi2"])]
    out["mirror_chi2_min"] = float(min(mirror)) if mirror else math.nan
    out["measure_s_mean"] = float(np.mean([r["measure_s"] for r in rows]))
    return out


def run(n: int = 24, seed: int = 2020, crb: bool = True) -> dict:
    """``n`` random stations of the finned body (module doc), rendered and measured, each
    printed as it comes; returns :func:`summarize`'s figures."""
    from cadra.synthetic.render_config import RenderConfig
    from cadra.synthetic.simulate import load_shot_spec, simulate_shot

    shot = simulate_shot(load_shot_spec(SPECS_DIR / "finner_1.toml"))
    rng = np.random.default_rng(seed)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(n):
            r = _case(i, shot, rng, Path(tmp), RenderConfig(), crb=crb)
            rows.append(r)
            if "roll_err_deg" in r:
                print(f"case {i:3d} st {r['station']:2d} roll {r['roll_deg']:+8.3f}: err "
                      f"{r['roll_err_deg']:+.4f} sigma {r['roll_sigma_deg']:.4f}"
                      + (f" CRB {r['crb_deg']:.4f}" if "crb_deg" in r else "")
                      + f" | top {r['top_roll_err_deg']:+.4f}+-{r['top_roll_sigma_deg']:.4f}"
                      f" side {r['side_roll_err_deg']:+.4f}+-{r['side_roll_sigma_deg']:.4f}"
                      f" | pos {r['top_du_px']:+.4f} {r['top_dv_px']:+.4f} "
                      f"{r['side_du_px']:+.4f} {r['side_dv_px']:+.4f} px", flush=True)
            else:
                print(f"case {i:3d} st {r['station']:2d}: {r['status']} {r['reason']}",
                      flush=True)
    out = summarize(rows)
    for key in ("roll_rms_deg", "roll_bias_deg", "roll_sigma_rms_deg", "roll_crb_rms_deg",
                "roll_crb_ratio", "position_rms_px", "axis_rms_deg"):
        if key in out:
            print(f"{key}: {out[key]:.5g}")
    print("sigma / actual:", {k: round(v, 3) for k, v in out["roll_sigma_ratios"].items()})
    return out
