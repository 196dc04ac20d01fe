"""Stage one's roll of a finned body (cadra.imaging.roll; docs/stage1.md, "Roll of a finned
body") against the renderer's exact truth: the sample shot FINNER-1 rendered at default
realism, its truth roll from the simulated attitude."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
import shapely

from cadra.body import outline_polygon
from cadra.conventions import body_to_facility_matrix, quat_from_axis_roll
from cadra.facility.reference import VIEW_AXES
from cadra.imaging.combine import StationPose
from cadra.imaging.roll import (
    PERIOD_RAD,
    RollCandidate,
    StationRoll,
    ViewRollModel,
    measure_station_roll,
    resolve_roll_track,
    view_outline_px,
)
from cadra.imaging.shot import with_roll_track
from cadra.imaging.station import StationResult, measure_station
from cadra.imaging.wires.mask import wire_mask
from cadra.synthetic.crb_roll import roll_crb
from cadra.synthetic.render_config import RenderConfig
from cadra.synthetic.simulate import (
    load_shot_spec,
    render_station_views,
    simulate_shot,
    station_scenes,
)

SPEC = Path(__file__).resolve().parents[1] / "sample_shots" / "specs" / "finner_1.toml"
#: the silhouette fit's edge profile (s0, a0, s4, a4) on default-realism renders of this body
PROFILE = (0.78, 0.098, -0.009, -0.008)


def wrap90(x_deg):
    return (x_deg + 45.0) % 90.0 - 45.0


@pytest.fixture(scope="module")
def shot():
    return simulate_shot(load_shot_spec(SPEC))


def truth_geometry(shot, k):
    """The attitude, the reference point and the nose axis at station index k (F)."""
    y = shot.states[k]
    R = body_to_facility_matrix(y[6:10])
    return R, y[0:3] + R @ shot.rigid.ref_from_cg_body_m(), R[:, 0]


def truth_view_pose(projection, view_name, r_ref, axis):
    """Stage one's view pose (a, b, phi) and tilt of the true state."""
    P = projection.plane_basis
    i, j = VIEW_AXES[view_name]
    e_out = np.zeros(3)
    e_out[3 - i - j] = 1.0
    pose = (P[0] @ r_ref, P[1] @ r_ref, math.atan2(P[1] @ axis, P[0] @ axis))
    return pose, math.asin(axis @ e_out)


def test_view_outline_is_the_renderers_outline(shot):
    """Rebuilt from stage one's view pose (a, b, phi, tilt) and the roll, the outline is the
    one the renderer drew from the 3-D attitude; 90 deg more roll gives it again, 10 deg not."""
    for k in (2, 11):
        R, r_ref, axis = truth_geometry(shot, k)
        for item in station_scenes(shot, k, np.random.default_rng(k)):
            view = shot.facility.stations[k].views[item["view"]]
            proj = view.optics(item["affine"])
            pose, tilt = truth_view_pose(proj, item["view"], r_ref, axis)
            roll = math.radians(item["truth"]["roll_deg"])
            drawn = shapely.Polygon(item["scene"].bodies[0])
            for extra, same in ((0.0, True), (PERIOD_RAD, True), (math.radians(10.0), False)):
                mine = shapely.Polygon(view_outline_px(shot.body, proj, item["view"], pose,
                                                       tilt, roll + extra, n_points=4096))
                diff = drawn.symmetric_difference(mine).area / drawn.area
                assert (diff < 1e-6) if same else (diff > 1e-3)


@pytest.mark.parametrize("k", [3, 9])
def test_roll_from_default_realism_renders_at_the_true_pose(shot, k):
    """Both views of a station rendered at default realism; the roll fitted with the pose at
    the truth: the best candidate is the true roll modulo 90 deg within 4 sigma + 0.005 deg,
    its sigma within 0.7-4x the Cramér–Rao bound, and the mirror solution far worse."""
    R, r_ref, axis = truth_geometry(shot, k)
    rng = np.random.default_rng(100 + k)
    models, crbs = {}, {}
    items = render_station_views(shot, k, rng, RenderConfig(seed=k))
    for item in items:
        view = shot.facility.stations[k].views[item["view"]]
        proj = view.optics(item["affine"])
        pose, tilt = truth_view_pose(proj, item["view"], r_ref, axis)

        def outline(g, proj=proj, name=item["view"], pose=pose, tilt=tilt):
            return view_outline_px(shot.body, proj, name, pose, tilt, g)

        img = item["image"].astype(float) / 255.0
        mask = wire_mask(view, item["affine"], img.shape, 4.0)
        models[item["view"]] = ViewRollModel(img, outline, mask, PROFILE)
        crbs[item["view"]] = roll_crb(outline, math.radians(item["truth"]["roll_deg"]),
                                      (item["truth"]["u_ref_px"], item["truth"]["v_ref_px"]),
                                      RenderConfig(seed=k),
                                      motion_blur_px=item["scene"].motion_blur_px,
                                      width_px=view.width_px, height_px=view.height_px)
    sr = measure_station_roll(models)
    truth = items[0]["truth"]["roll_deg"]
    best = sr.best
    err = wrap90(math.degrees(best.roll_rad) - truth)
    sigma = math.degrees(best.sigma_rad)
    assert abs(err) < 4.0 * sigma + 0.005
    crb = 1.0 / math.sqrt(sum(c.sigma_roll_rad ** -2 for c in crbs.values()))
    assert 0.7 < best.sigma_rad / crb < 4.0
    assert len(sr.candidates) >= 2 and sr.candidates[1].chi2_excess > 100.0
    mirror = math.degrees(sr.candidates[1].roll_rad)
    assert abs(wrap90(mirror + truth)) < 1.0       # the mirror roll -gamma


def test_measure_station_measures_the_finner_and_its_roll(shot, tmp_path):
    """The whole station (wires, pose fit with the fins, roll): pose within 3 um and 0.01 deg
    of the truth, the roll within 0.05 deg modulo 90, the templates at the measured roll."""
    k = 6
    items = render_station_views(shot, k, np.random.default_rng(7), RenderConfig(seed=7))
    images = {item["view"]: item["image"] for item in items}     # in memory, no file
    res = measure_station(shot.facility.station(shot.stations[k]), images, shot.spec.model,
                          overlays=False)
    assert res.status == "ok", res.reason
    t = shot.truth.iloc[k]
    p = res.pose
    assert np.abs([p.x_m - t.x_m, p.y_m - t.y_m, p.z_m - t.z_m]).max() < 3e-6
    assert abs(math.degrees(p.theta_rad) - t.theta_deg) < 0.01
    assert abs(math.degrees(p.psi_rad) - t.psi_deg) < 0.01
    truth = items[0]["truth"]["roll_deg"]
    assert abs(wrap90(math.degrees(res.roll.best.roll_rad) - truth)) < 0.05
    for v in res.views.values():
        assert abs(wrap90(math.degrees(v.roll_rad) - truth)) < 0.1


# --------------------------------------------------------------------------- continuity


def _station_roll(true_rad, mirror_excess, rng):
    """Candidates of a station whose roll is ``true_rad``: the truth (mod 90 deg) and its
    mirror, chi^2 excess of the mirror ``mirror_excess`` (negative: the mirror fits better)."""
    sig = 1e-4
    t = true_rad % PERIOD_RAD + rng.normal(0.0, sig)
    m = (-true_rad) % PERIOD_RAD
    cands = [(max(0.0, -mirror_excess), t), (max(0.0, mirror_excess), m)]
    cands.sort()
    return StationRoll(candidates=tuple(RollCandidate(roll_rad=v, sigma_rad=sig,
                                                      chi2_excess=e, views={})
                                        for e, v in cands),
                       grid_rad=np.zeros(0), chi2=np.zeros(0))


def test_continuity_unwraps_a_roll_up_and_picks_the_true_branch():
    """A roll-up from rest to 35 deg per station: the track is the truth up to a common
    multiple of 90 deg, the first station in [-45, 45) deg, even where the mirror fits a
    station slightly better (station 8) or the first station's best is the mirror."""
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 0.033, 16)
    p_ss, tau = 250.0, 0.017
    phi = math.radians(-30.0) + p_ss * (t - tau * (1.0 - np.exp(-t / tau)))
    for first_mirror_better in (False, True):
        excess = [400.0] * 16
        excess[8] = -3.0
        if first_mirror_better:
            excess[0] = -2.0
        rolls = [_station_roll(phi[k], excess[k], rng) for k in range(16)]
        track, sig, chosen = resolve_roll_track(t, rolls)
        offset = track - phi
        assert np.ptp(offset) < 1e-3
        assert abs(offset[0] / PERIOD_RAD - round(offset[0] / PERIOD_RAD)) < 1e-3
        assert -0.25 * math.pi <= track[0] < 0.25 * math.pi
        assert np.all(sig == 1e-4)


def test_continuity_skips_stations_without_a_roll():
    rng = np.random.default_rng(4)
    t = np.arange(6) * 0.002
    phi = 0.3 + 150.0 * t
    rolls = [_station_roll(x, 100.0, rng) for x in phi]
    rolls[2] = None
    track, sig, chosen = resolve_roll_track(t, rolls)
    assert math.isnan(track[2]) and chosen[2] == -1
    ok = np.isfinite(track)
    assert np.ptp((track - phi)[ok]) < 1e-3


def test_with_roll_track_sets_the_poses_phi():
    """The shot driver's step: each station's pose gets the tracked roll and its sigma; a
    shot without rolls (a body of revolution) is returned unchanged."""
    rng = np.random.default_rng(5)
    pose = StationPose(*([0.0] * 12))
    times = {1: 0.0, 2: 0.002, 3: 0.004}
    phi = {s: 0.2 + 100.0 * t for s, t in times.items()}
    real = [StationResult(s, "ok", "", pose, roll=_station_roll(phi[s], 50.0, rng))
            for s in (3, 1, 2)]          # any order: the track follows the times
    out = with_roll_track(real, times)
    got = {r.station: r.pose.phi_rad for r in out}
    assert np.ptp([got[s] - phi[s] for s in times]) < 1e-3
    assert all(r.pose.sigma_phi_rad == 1e-4 for r in out)
    plain = [dataclasses.replace(r, roll=None) for r in real]
    assert all(math.isnan(r.pose.phi_rad) for r in with_roll_track(plain, times))


# --------------------------------------------------------------------------- the bound


def test_roll_bound_scales_with_the_noise_and_repeats_every_90_deg(shot):
    """The Cramér–Rao bound of one view's roll: all noise sources doubled double it (the
    quantization's share aside: 16-bit), and rolling by 90 deg gives the same bound."""
    k = 5
    R, r_ref, axis = truth_geometry(shot, k)
    item = station_scenes(shot, k, np.random.default_rng(0))[0]
    view = shot.facility.stations[k].views[item["view"]]
    proj = view.optics(item["affine"])

    def outline(g):
        Rg = body_to_facility_matrix(quat_from_axis_roll(axis, g))
        return proj.from_plane(outline_polygon(shot.body, Rg, r_ref, proj.plane_basis))

    roll = math.radians(item["truth"]["roll_deg"])
    ref = (item["truth"]["u_ref_px"], item["truth"]["v_ref_px"])
    cfg = RenderConfig(bit_depth=16)
    noisy = cfg.replace(read_noise_sigma=2 * cfg.read_noise_sigma,
                        shot_noise_sigma=2 * cfg.shot_noise_sigma,
                        film_grain_sigma=2 * cfg.film_grain_sigma)
    a = roll_crb(outline, roll, ref, cfg)
    b = roll_crb(outline, roll, ref, noisy)
    c = roll_crb(outline, roll + PERIOD_RAD, ref, cfg)
    assert b.sigma_roll_rad / a.sigma_roll_rad == pytest.approx(2.0, rel=0.01)
    assert c.sigma_roll_rad == pytest.approx(a.sigma_roll_rad, rel=1e-3)
    assert a.sigma_roll_known_pose_rad <= a.sigma_roll_rad


def test_local_level_carries_a_tilted_beam_into_the_shadow():
    """The beam's level under a shadow (a first-order normalized convolution): a tilted
    plane is reproduced exactly where it is masked (a weighted mean would lean toward its
    unshadowed side by the gradient times ~0.8 sigma)."""
    from cadra.imaging.roll import _local_linear_level

    v, u = np.indices((120, 160), dtype=float)
    beam = 0.8 + 1e-3 * u - 6e-4 * v
    w = np.ones_like(beam)
    w[40:80, 50:110] = 0.0                       # a shadow 40 px tall
    level = _local_linear_level(beam * w + 0.05 * (1 - w), w, 10.0)
    assert np.abs(level - beam)[35:85, 45:115].max() < 1e-9


def test_trajectory_rows_carry_the_tracked_roll():
    """Through the trajectory file's rows (cadra.io.trajectory.station_rows): the tracked roll
    and its sigma in degrees in phi_deg, sigma_phi_deg; NaN for a body of revolution."""
    from cadra.io.trajectory import station_rows

    rng = np.random.default_rng(6)
    pose = StationPose(*([0.0] * 12))
    times = {1: 0.0, 2: 0.002}
    phi = {1: 0.1, 2: 0.5}
    real = [StationResult(s, "ok", "", pose, roll=_station_roll(phi[s], 50.0, rng))
            for s in times]
    rows = station_rows(with_roll_track(real, times), times)
    assert rows["phi_deg"].to_numpy() == pytest.approx(np.degrees([0.1, 0.5]), abs=0.02)
    assert rows["sigma_phi_deg"].to_numpy() == pytest.approx(np.degrees([1e-4, 1e-4]))
    plain = station_rows([dataclasses.replace(r, roll=None) for r in real], times)
    assert plain["phi_deg"].isna().all()
