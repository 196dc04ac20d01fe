"""Per-view decomposition of stage one's whole-shot errors (a diagnostic).

Flies, renders and measures one sample shot several times (new seeds), and for every station
and view compares with the renderer's exact truth:

- the silhouette fit in the image: reference point u, v (px) and axis angle, in the fit's
  own sigmas (the template tilt's error included in the error, not in these sigmas);
- the wire affine at the model (m), in its sigma;
- the view's plane position as the rays' intersection uses it (pose + affine + tilt, with
  the covariance `combine` gives it), in that sigma;
- the station's x, and the correlation of the two views' x errors (the station's x sigma
  assumes none).

Usage::

    python tools/diag_views.py m1_2366 --realisations 6        # ~4 min
    python tools/diag_views.py m1_2366 --render dust=0 scratches=0 bow_shock=false

The last printed line is a JSON object with the figures.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]


def _rms_z(df, e, s):
    z = (df[e] / df[s]).dropna()
    return float(np.sqrt(np.mean(z**2)))


def station_rows(name: str, seed: int, render: dict) -> list[dict]:
    from cadra.imaging.combine import _tilt_propagated
    from cadra.imaging.shot import measure_shot
    from cadra.imaging.station import _view_pose
    from cadra.synthetic.simulate import load_shot_spec, simulate_shot, write_shot

    spec = load_shot_spec(ROOT / "sample_shots" / "specs" / f"{name}.toml")
    spec = replace(spec, seed=seed, render={**spec.render, **render})
    sim = simulate_shot(spec)
    tmp = Path(tempfile.mkdtemp(prefix="diag_views_"))
    try:
        write_shot(sim, tmp / "shot", images=True, progress=False)
        res = measure_shot(tmp / "shot" / "shot.toml", workers=1, progress=False, overlays=False)
        tv = pd.read_csv(tmp / "shot" / "truth_images.csv")
        truth = pd.read_csv(tmp / "shot" / "truth.csv").set_index("station")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    rows = []
    for st in res.stations:
        if st.pose is None or any(st.views.get(v) is None or st.views[v].fit is None
                                  for v in ("top", "side")):
            continue
        row = {"seed": seed, "station": st.station,
               "x_err": st.pose.x_m - truth.loc[st.station, "x_m"], "x_sig": st.pose.sigma_x_m}
        vp = {v: _view_pose(st.views[v].fit, st.views[v].wires) for v in ("top", "side")}
        covs, _ = _tilt_propagated(vp["top"], vp["side"])
        for v, C in zip(("top", "side"), covs, strict=True):
            vr, f = st.views[v], st.views[v].fit
            t = tv[(tv.station == st.station) & (tv.view == v)].iloc[0]
            A = np.array([[t[f"affine_{i}{j}"] for j in range(3)] for i in range(2)])
            p = np.array([t.u_ref_px, t.v_ref_px, 1.0])
            aff = vr.affine @ p - A @ p
            s_aff = vr.wires.position_sigma_m((t.u_ref_px, t.v_ref_px))
            row.update({
                f"{v}_eu": f.ref_px[0] - t.u_ref_px, f"{v}_su": f.sigma_ref_px[0],
                f"{v}_ev": f.ref_px[1] - t.v_ref_px, f"{v}_sv": f.sigma_ref_px[1],
                f"{v}_ephi": math.remainder(f.axis_angle_px_rad
                                            - math.radians(t.axis_angle_image_deg), 2 * math.pi),
                f"{v}_sphi": f.sigma_axis_px_rad,
                f"{v}_eaff": aff[0], f"{v}_saff": s_aff[0],
                f"{v}_ea": f.pose[0] - (A @ p)[0], f"{v}_sa": math.sqrt(C[0, 0]),
                f"{v}_eb": f.pose[1] - (A @ p)[1], f"{v}_sb": math.sqrt(C[1, 1]),
            })
        rows.append(row)
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("shot", help="sample spec name, e.g. m1_2366")
    ap.add_argument("--realisations", type=int, default=6)
    ap.add_argument("--seed", type=int, default=100, help="first spec seed")
    ap.add_argument("--render", nargs="*", default=[],
                    help="render overrides key=value (e.g. dust=0 illumination_mottle=0.0)")
    args = ap.parse_args()
    render = {}
    for kv in args.render:
        k, v = kv.split("=", 1)
        render[k] = ({"true": True, "false": False}[v.lower()] if v.lower() in ("true", "false")
                     else int(v) if v.lstrip("-").isdigit() else float(v))
    rows = []
    for r in range(args.realisations):
        rows += station_rows(args.shot, args.seed + r, render)
        print(f"realisation {r + 1}/{args.realisations}: {len(rows)} stations", flush=True)
    df = pd.DataFrame(rows)
    out = {"shot": args.shot, "stations": len(df), "render": render,
           "x_err_over_sigma": _rms_z(df, "x_err", "x_sig")}
    for v in ("top", "side"):
        for key, e, s in (("pose_u", "eu", "su"), ("pose_v", "ev", "sv"),
                          ("pose_angle", "ephi", "sphi"), ("affine_a", "eaff", "saff"),
                          ("plane_a", "ea", "sa"), ("plane_b", "eb", "sb")):
            out[f"{v}_{key}"] = _rms_z(df, f"{v}_{e}", f"{v}_{s}")
    zt, zs = df.top_ea / df.top_sa, df.side_ea / df.side_sa
    out["corr_top_side_x"] = float(np.corrcoef(zt, zs)[0, 1])
    out["x_top_minus_side_over_sigma"] = float(np.sqrt(np.mean(
        (df.top_ea - df.side_ea) ** 2 / (df.top_sa**2 + df.side_sa**2))))
    print(f"{args.shot}: {len(df)} stations; errors / sigma")
    print(f"  station x {out['x_err_over_sigma']:.3f}; the views' x errors correlate "
          f"{out['corr_top_side_x']:+.3f} (x_top - x_side: "
          f"{out['x_top_minus_side_over_sigma']:.3f})")
    for v in ("top", "side"):
        print(f"  {v:4s} pose u {out[f'{v}_pose_u']:.3f}  v {out[f'{v}_pose_v']:.3f}  angle "
              f"{out[f'{v}_pose_angle']:.3f} | affine a {out[f'{v}_affine_a']:.3f} | plane "
              f"a {out[f'{v}_plane_a']:.3f}  b {out[f'{v}_plane_b']:.3f}")
    # which parts of the two views' x errors move together (pose u in px, affine along x)
    parts = {"top pose u": df.top_eu, "top affine a": df.top_eaff,
             "side pose u": df.side_eu, "side affine a": df.side_eaff}
    corr = pd.DataFrame(parts).corr()
    print("  correlations of the x parts:")
    print("\n".join("    " + line for line in corr.round(2).to_string().splitlines()))
    out["corr_parts"] = {f"{a} / {b}": float(corr.loc[a, b]) for i, a in enumerate(parts)
                         for b in list(parts)[i + 1:]}
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
