"""Stage one on point-source (direct-shadowgraph) stations against the renderer's exact truth.

The harness of ``tools/validate_point_source.py`` (docs/validation.md). A *station case* is a
body at a known 3-D pose in front of one station of the bundled point-source range
(``facilities/brl_spark.toml``): both views rendered through the station's own conical optics
(:meth:`cadra.optics.projection.PointSourceProjection.outline`, each film placed at random as
the simulator places it), then measured by :func:`cadra.imaging.station.measure_station`.

Scored per case:

- each view's reference point and image axis angle (px, deg) against the scene's truth, with
  the fit's own sigma, and the Otsu-and-moments baseline on the same image
  (:mod:`cadra.validation.otsu`, given the exact outline's centroid offset and the nose
  direction closest to the truth: generous to it);
- the station's 3-D reference point and inclinations against the pose rendered;
- the Cramér–Rao bound of a few cases, derived for the perspective case: each view's bound
  on the shadow's pose (:func:`cadra.synthetic.crb.pose_crb` on the exact conical outline),
  with the film map's error the wires leave added in 3-D, carried to 3-D through the same
  rays and planes from the sparks the measurement combines by
  (:func:`cadra.imaging.combine.combine_views`);
- the same images measured as if the optics were parallel (the station's views with their
  sparks taken away): how far that assumption moves the 3-D point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from cadra.body import body_from_spec
from cadra.conventions import (
    axis_from_inclinations,
    body_to_facility_matrix,
    inclinations_from_axis,
    quat_from_axis_roll,
)
from cadra.facility.reference import Station
from cadra.imaging.combine import ViewPose, combine_views
from cadra.imaging.roll import wrap_period
from cadra.imaging.station import measure_station
from cadra.synthetic.render import RenderConfig, render
from cadra.synthetic.simulate import FilmPlacement, film_affine, view_scene
from cadra.validation.stage1_bench import ratio_se

#: The bodies scored: a sphere and the M2 capsule of the parallel bench's size, the M-80.
BODIES = {"sphere": {"kind": "sphere", "d_m": 0.03556},
          "capsule": {"kind": "capsule", "preset": "M2"},
          "bullet": {"kind": "bullet", "preset": "M80"}}
#: The finned body whose roll is scored: seed 001's Basic Finner at the sample shot's size
#: (d = 7 mm, 2.1 cm tip to tip; sample_shots/specs/finner_1.toml)
FINNER = {"kind": "finner", "preset": "basic_finner", "d_cm": 0.7}
#: The flight velocity of every case, m/s (motion blur over the exposure, the clutter's axis).
SPEED_M_S = 830.0


@dataclass(frozen=True, eq=False)
class StationCase:
    """Both views of one station rendered at a known pose, with their truth."""

    station: Station
    body_spec: dict
    r_ref_F: np.ndarray
    axis_F: np.ndarray
    images: dict          # view name -> rendered image (uint8)
    truth: dict           # view name -> the scene's truth (view_scene) + scene, config, affine
    roll_rad: float = math.nan    # the roll about the nose axis (quat_from_axis_roll's)


def station_case(station: Station, body_spec: dict, r_ref_F, axis_F, rng: np.random.Generator,
                 config: RenderConfig | None = None, roll_rad: float | None = None
                 ) -> StationCase:
    """Render both views of ``station`` with the body at ``r_ref_F`` (m), nose ``axis_F``."""
    config = RenderConfig() if config is None else config
    body = body_from_spec(body_spec)
    r = np.asarray(r_ref_F, dtype=float)
    a = np.asarray(axis_F, dtype=float) / np.linalg.norm(axis_F)
    roll = rng.uniform(0.0, 2 * math.pi) if roll_rad is None else roll_rad
    R = body_to_facility_matrix(quat_from_axis_roll(a, roll))
    images, truth = {}, {}
    for name, view in station.views.items():
        affine = film_affine(view.image_to_plane, FilmPlacement(), rng, view.width_px,
                             view.height_px)
        scene, tr = view_scene(body, view, affine, R, r, np.array([SPEED_M_S, 0.0, 0.0]))
        cfg = config.replace(seed=int(rng.integers(1 << 30)))
        images[name] = render(scene, cfg, rng)
        truth[name] = {**tr, "scene": scene, "config": cfg, "affine": affine}
    return StationCase(station, dict(body_spec), r, a, images, truth, float(roll))


def random_case(station: Station, body_spec: dict, rng: np.random.Generator, *,
                offset_m=None, max_angle_deg: float = 10.0,
                config: RenderConfig | None = None) -> StationCase:
    """A case at a random pose: the reference point within +-10 mm of the station's point of
    the line of flight in x, y and z (or at ``offset_m`` = (y, z) from it, x still random),
    inclinations uniform in +-``max_angle_deg``, random roll."""
    lim = math.radians(max_angle_deg)
    r = np.array([station.x_m, 0.0, 0.0]) + rng.uniform(-0.01, 0.01, 3)
    if offset_m is not None:
        r[1:] = offset_m
    a = axis_from_inclinations(*rng.uniform(-lim, lim, 2))
    return station_case(station, body_spec, r, a, rng, config)


def parallel_station(station: Station) -> Station:
    """The station as a reduction that assumes collimated light would calibrate it from these
    images: each view parallel, its wires where their shadows fall on the film, brought to
    the line of flight by the magnification there (the scale such a reduction calibrates at
    the line of flight), the film map likewise. Nothing but the depth of each point (its own
    magnification) is then wrong: the assumption's error is what the harness measures."""
    from cadra.facility.reference import Wire

    views = {}
    for n, v in station.views.items():
        proj = v.optics()
        centre = np.array([station.x_m, 0.0, 0.0])
        lam0 = float(proj.magnification(centre))
        c_ab = np.asarray(proj.plane_point(centre), dtype=float)

        def to_flight(p, proj=proj, lam0=lam0, c_ab=c_ab, v=v):
            q = np.array(p, dtype=float)
            q[list(v.axes)] = c_ab + (proj.plane_point(q) - c_ab) / lam0
            return q
        wires = tuple(Wire(name=w.name, p0_m=to_flight(w.p0_m), p1_m=to_flight(w.p1_m),
                           diameter_m=w.diameter_m * float(proj.magnification(
                               0.5 * (w.p0_m + w.p1_m))) / lam0) for w in v.wires)
        M = np.array(v.image_to_plane, dtype=float)
        M[:, :2] /= lam0
        M[:, 2] = c_ab + (M[:, 2] - c_ab) / lam0
        views[n] = replace(v, projection="parallel", source_position_m=None,
                           film_distance_m=None, wires=wires, image_to_plane=M,
                           scale_m_per_px=v.scale_m_per_px / lam0)
    return replace(station, views=views)


def _otsu_error(case: StationCase, name: str, sphere: bool) -> list[float]:
    """The Otsu + moments baseline's error on one view: u, v px (and the axis, deg)."""
    from cadra.validation.otsu import baseline_error

    tr = case.truth[name]
    return baseline_error(case.images[name], tr["scene"].bodies[0],
                          (tr["u_ref_px"], tr["v_ref_px"]),
                          math.radians(tr["axis_angle_image_deg"]), sphere)


def truth_inclinations(case: StationCase) -> tuple[float, float]:
    """(theta, psi) of the case's axis, rad."""
    return inclinations_from_axis(case.axis_F)


def score_case(case: StationCase, result, sphere: bool) -> dict:
    """Errors and sigmas of one measured case (:func:`measure_station`'s result): per view
    (px, deg) and in 3-D (m, rad); None entries where the station failed."""
    out = {"ok": result.pose is not None and result.status != "failed",
           "reason": result.reason, "warnings": list(result.warnings)}
    if not out["ok"]:
        return out
    for name in ("top", "side"):
        f, tr = result.views[name].fit, case.truth[name]
        err = [f.ref_px[0] - tr["u_ref_px"], f.ref_px[1] - tr["v_ref_px"]]
        sig = [f.sigma_ref_px[0], f.sigma_ref_px[1]]
        if not sphere:
            err.append(math.degrees(math.remainder(
                f.axis_angle_px_rad - math.radians(tr["axis_angle_image_deg"]), 2 * math.pi)))
            sig.append(math.degrees(f.sigma_axis_px_rad))
        out[name] = {"error": err, "sigma": sig, "otsu": _otsu_error(case, name, sphere)}
    p = result.pose
    out["error_3d"] = [p.x_m - case.r_ref_F[0], p.y_m - case.r_ref_F[1], p.z_m - case.r_ref_F[2]]
    out["sigma_3d"] = [p.sigma_x_m, p.sigma_y_m, p.sigma_z_m]
    if not sphere:
        theta, psi = truth_inclinations(case)
        out["error_3d"] += [p.theta_rad - theta, p.psi_rad - psi]
        out["sigma_3d"] += [p.sigma_theta_rad, p.sigma_psi_rad]
    if getattr(result, "roll", None) is not None and math.isfinite(case.roll_rad):
        # a cruciform's roll is known modulo its 90 deg period
        best = result.roll.best
        out["roll_error_deg"] = math.degrees(wrap_period(best.roll_rad - case.roll_rad))
        out["roll_sigma_deg"] = math.degrees(best.sigma_rad)
    return out


def crb_3d(case: StationCase, sphere: bool, result=None) -> dict:
    """The Cramér–Rao bound of a case: each view's (u, v, angle) in px and deg, and carried to
    3-D through the views' rays and planes (x, y, z in m; theta, psi in rad).

    The image-model bound is the shadow's, for a film map known exactly; a station's 3-D point
    also carries the film map's error, which the wires fix. With ``result`` (the case's
    measured station) each view's in-plane bound is widened, in quadrature, by the wires' map
    sigma at the model as stage one states it (``WireMeasurement.position_sigma_m``, whose
    honesty tools/validate_wire_sigma.py checks): ``bound_3d`` then compares the 3-D error with
    everything the station's two images can know."""
    from cadra.synthetic.crb import pose_crb

    views, per_view = {}, {}
    for name, view in case.station.views.items():
        tr = case.truth[name]
        c = pose_crb(tr["scene"].bodies[0], (tr["u_ref_px"], tr["v_ref_px"]), tr["config"],
                     motion_blur_px=tr["scene"].motion_blur_px, width_px=view.width_px,
                     height_px=view.height_px, fit_angle=not sphere)
        proj = view.optics(tr["affine"])
        ab = proj.plane_point(case.r_ref_F)
        d = proj.plane_point_jacobian(case.r_ref_F) @ case.axis_F
        J = proj.to_plane_jacobian(np.array([tr["u_ref_px"], tr["v_ref_px"]]))
        cov_ab = J @ np.diag([c.sigma_u_px ** 2, c.sigma_v_px ** 2]) @ J.T
        if result is not None:
            view_result = result.views[name]
            cov_ab = cov_ab + np.diag(np.square(view_result.wires.position_sigma_m(
                view_result.fit.ref_px)))
        s_phi = 0.0 if sphere else float(c.sigma_phi_rad)
        views[name] = ViewPose(float(ab[0]), float(ab[1]), math.atan2(d[1], d[0]),
                               math.sqrt(cov_ab[0, 0]), math.sqrt(cov_ab[1, 1]), s_phi,
                               projection=proj)
        per_view[name] = [c.sigma_u_px, c.sigma_v_px] + ([] if sphere
                                                         else [math.degrees(s_phi)])
    p = combine_views(views["top"], views["side"])
    bound = [p.sigma_x_m, p.sigma_y_m, p.sigma_z_m]
    if not sphere:
        bound += [p.sigma_theta_rad, p.sigma_psi_rad]
    return {"views": per_view, "bound_3d": bound}


def run_cases(station: Station, body_spec: dict, n: int, seed: int, *, offsets=None,
              n_crb: int = 0, parallel: bool = False, config: RenderConfig | None = None
              ) -> dict:
    """Render, measure and score ``n`` random cases (``offsets``: (y, z) pairs cycled
    through), the bound of the first ``n_crb``, and (``parallel``) each case measured as if
    its optics were parallel."""
    rng = np.random.default_rng(seed)
    body = body_from_spec(body_spec)
    sphere = body.kind == "sphere"
    scores, bounds, parallel_errors, parallel_flagged = [], [], [], []
    flat = parallel_station(station) if parallel else None
    for i in range(n):
        off = None if offsets is None else offsets[i % len(offsets)]
        case = random_case(station, body_spec, rng, offset_m=off, config=config)
        res = measure_station(station, case.images, body_spec, overlays=False)
        scores.append(score_case(case, res, sphere))
        if i < n_crb and scores[-1]["ok"]:
            bounds.append(crb_3d(case, sphere, res))
        if flat is not None:
            res_flat = measure_station(flat, case.images, body_spec, overlays=False)
            parallel_flagged.append(res_flat.status == "failed")
            parallel_errors.append(None if res_flat.pose is None else
                                   [res_flat.pose.x_m - case.r_ref_F[0],
                                    res_flat.pose.y_m - case.r_ref_F[1],
                                    res_flat.pose.z_m - case.r_ref_F[2]])
    return {"scores": scores, "bounds": bounds, "parallel_errors": parallel_errors,
            "parallel_flagged": parallel_flagged, "sphere": sphere}


def _rms(a) -> np.ndarray:
    return np.sqrt(np.mean(np.square(np.asarray(a, dtype=float)), axis=0))


def summarize(run: dict) -> dict:
    """The figures of one :func:`run_cases`: rms errors, sigma / rms, rms / bound, the
    baseline's rms over CADRA's (per view, over both views' u, v and axis; with its bootstrap
    standard error, images resampled together), the same in 3-D,
    and the parallel assumption's mean and largest 3-D error, and how often stage one's
    two-view check flags its stations (the views' x disagree)."""
    ok = [s for s in run["scores"] if s["ok"]]
    out = {"n": len(run["scores"]), "n_ok": len(ok)}
    if not ok:
        return out
    err = np.array([s[v]["error"] for s in ok for v in ("top", "side")])
    sig = np.array([s[v]["sigma"] for s in ok for v in ("top", "side")])
    otsu = np.array([s[v]["otsu"] for s in ok for v in ("top", "side")])
    rms = _rms(err)
    out.update(view_rms=rms.tolist(), view_sigma_ratio=(np.sqrt(np.mean(sig ** 2, axis=0))
                                                        / rms).tolist(),
               otsu_rms=_rms(otsu).tolist(), otsu_ratio=(_rms(otsu) / rms).tolist(),
               otsu_ratio_se=ratio_se(otsu, err).tolist())
    e3, s3 = np.array([s["error_3d"] for s in ok]), np.array([s["sigma_3d"] for s in ok])
    rms3 = _rms(e3)
    out.update(rms_3d=rms3.tolist(), mean_3d=np.mean(e3, axis=0).tolist(),
               sigma_ratio_3d=(np.sqrt(np.mean(s3 ** 2, axis=0)) / rms3).tolist())
    if run["bounds"]:
        b_view = _rms([b["views"][v] for b in run["bounds"] for v in ("top", "side")])
        b3 = _rms([b["bound_3d"] for b in run["bounds"]])
        out.update(view_crb=b_view.tolist(), view_crb_ratio=(rms / b_view).tolist(),
                   crb_3d=b3.tolist(), crb_ratio_3d=(rms3 / b3).tolist())
    rolls = [(s["roll_error_deg"], s["roll_sigma_deg"]) for s in ok if "roll_error_deg" in s]
    if rolls:
        e, sg = np.array(rolls).T
        out.update(n_roll=len(rolls), roll_rms_deg=float(_rms(e)),
                   roll_sigma_ratio=float(_rms(sg) / _rms(e)),
                   roll_pull_rms=float(_rms(e / sg)))
    par = [p for p in run["parallel_errors"] if p is not None]
    if par:
        par = np.array(par)
        out.update(parallel_mean_3d=np.mean(par, axis=0).tolist(),
                   parallel_max_abs_3d=np.max(np.abs(par), axis=0).tolist(),
                   parallel_rms_3d=_rms(par).tolist(),
                   parallel_flagged_frac=float(np.mean(run["parallel_flagged"])))
    return out


#: The point-source range the harness flies its end-to-end rounds through.
FACILITY = "brl_spark"


def e2e_draws(draws: int, verbose: bool = True) -> dict:
    """Two M-80 rounds (the sample specs ``m80_1``, ``m80_2``, flown through the point-source
    range instead) per draw, from images through stage one and the 6-DOF fit as
    ``tools/validate_m80.py`` runs them on the parallel range (:mod:`cadra.validation.m80`:
    the fit started from the rounds' linear theory and the spin from the twist). Draw k
    reseeds the specs by 1000 k. Returns the pulls per free coefficient, the fraction within
    2 sigma, and chi^2/nu per draw with its expected scatter sqrt(2/nu)."""
    import dataclasses

    from cadra.imaging.shot import measure_shot
    from cadra.synthetic.simulate import load_shot_spec, render_images, simulate_shot
    from cadra.validation.m80 import (
        FREE,
        SPECS,
        SPECS_DIR,
        linear_theory,
        six_dof,
        start_from_linear,
        truth_model,
    )

    truth = truth_model()
    pulls = {n: [] for n in FREE}
    chi2, scatter, failures = [], [], []
    for k in range(draws):
        shots = []
        for name in SPECS:
            spec = load_shot_spec(SPECS_DIR / f"{name}.toml")
            spec = dataclasses.replace(spec, facility=FACILITY, seed=spec.seed + 1000 * k)
            flown = render_images(simulate_shot(spec), progress=False)
            stage1 = measure_shot(flown.shot_file(), images=flown.images, workers=1,
                                  progress=False, overlays=False)
            shots.append(stage1.shot_data())
        res = six_dof(shots, start_from_linear([linear_theory(s) for s in shots]), truth)
        if not res.converged:
            failures.append(f"draw {k}: {res.status}")
            continue
        for n, v, sg in zip(res.aero_names, res.aero_values, res.aero_sigma, strict=True):
            pulls[n].append(float((v - truth.parameter(n).value) / sg))
        chi2.append(float(res.reduced_chi2))
        scatter.append(float(math.sqrt(2.0 / res.dof)))
        if verbose:
            print(f"draw {k}: chi2/nu {res.reduced_chi2:.3f} (+-{scatter[-1]:.3f}); pulls "
                  + ", ".join(f"{n} {pulls[n][-1]:+.2f}" for n in FREE), flush=True)
    every = np.array([p for n in FREE for p in pulls[n]])
    return {"draws": draws, "failures": failures,
            "within_2sigma_frac": float(np.mean(np.abs(every) <= 2)) if every.size else None,
            "n_pulls": int(every.size),
            "pulls": {n: [round(p, 3) for p in v] for n, v in pulls.items()},
            "pull_std": {n: float(np.std(v)) for n, v in pulls.items() if v},
            "chi2_nu": chi2, "chi2_nu_scatter": scatter,
            "chi2_nu_median": float(np.median(chi2)) if chi2 else None,
            "chi2_nu_max_dev_sigmas": (float(np.max(np.abs(np.array(chi2) - 1)
                                                    / np.array(scatter))) if chi2 else None)}


def calibration_e2e(verbose: bool = True) -> dict:
    """The sphere calibration from point-source images: the three biased sphere sample shots
    (``sample_shots/specs/sphere_bias_{1,2,3}.toml``, their station biases injected in the
    rendered scenes) flown through the point-source range, measured by stage one and
    calibrated (:func:`cadra.calibration.sphere.estimate_station_biases`); the recovered
    biases against the injected ones, as ``tools/bench_calibration.py --e2e`` scores them on
    the parallel range."""
    import dataclasses

    from cadra.calibration.sphere import estimate_station_biases
    from cadra.imaging.shot import measure_shot
    from cadra.synthetic.simulate import load_shot_spec, render_images, simulate_shot
    from cadra.validation.calibration_trials import recovery
    from cadra.validation.m80 import SPECS_DIR

    shots, injected = [], {}
    for k in (1, 2, 3):
        spec = load_shot_spec(SPECS_DIR / f"sphere_bias_{k}.toml")
        spec = dataclasses.replace(spec, facility=FACILITY)
        injected = spec.station_biases
        flown = render_images(simulate_shot(spec), progress=False)
        shots.append(measure_shot(flown.shot_file(), images=flown.images, workers=1,
                                  progress=False, overlays=False).shot_data())
    est = estimate_station_biases(shots, facility=FACILITY)
    b = np.array([injected.get(int(s), (0.0, 0.0, 0.0, 0.0)) for s in est.stations])
    return {**recovery(est, b, verbose),
            "all_within_2sigma_frac": float(np.mean(np.abs((est.bias - b) / est.sigma) <= 2)),
            "chi2_nu": float(est.chi2 / est.dof)}


__all__ = ["BODIES", "FACILITY", "StationCase", "calibration_e2e", "crb_3d", "e2e_draws",
           "parallel_station", "random_case", "run_cases", "score_case", "station_case",
           "summarize"]
