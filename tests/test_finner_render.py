"""The finned body in the renderer, the shot file and the sample shot.

Truth: the renderer's exact coverage of the outline polygon (docs/renderer.md) against the
polygon's own area and centroid (shapely), and against the hand outline of a side view at
zero incidence (docs/bodies.md, "Roll convention": the fins reach h(gamma) from the axis).
"""

import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import shapely

from cadra.aero import resolve_model
from cadra.atmosphere import Atmosphere
from cadra.body import body_from_spec, finner_mass_properties, finner_preset, finner_silhouette
from cadra.conventions import body_to_facility_matrix, quat_from_axis_roll, quat_to_euler
from cadra.io.facility_file import load_facility
from cadra.io.shotfile import ShotFileError, load_shot, shot_from_dict
from cadra.synthetic.render import Scene, illumination_field, render_clean
from cadra.synthetic.render_config import RenderConfig
from cadra.synthetic.simulate import (
    SpecError,
    load_shot_spec,
    roll_from_matrix,
    simulate_shot,
    spec_from_dict,
    station_scenes,
    view_scene,
    write_shot,
)

ROOT = Path(__file__).resolve().parents[1]
SPECS = ROOT / "sample_shots" / "specs"
RNG = np.random.default_rng(20261125)
#: the sample shot's finner: the Basic Finner at d = 0.7 cm (fits the HFFAF's field of view)
FB = finner_preset(d_m=0.007)
#: default optics and fringe, no clutter and no film defects: what moment tests need
QUIET = RenderConfig(scratches=0, dust=0, bow_shock=False, wake=False)


@pytest.fixture(scope="module")
def hffaf():
    return load_facility("hffaf")


def attitude(axis, roll_deg):
    return body_to_facility_matrix(quat_from_axis_roll(np.asarray(axis, float),
                                                       np.radians(roll_deg)))


def body_only(scene):
    """The scene's body alone (no wires, no mark): its shadow is the body's."""
    return Scene(width_px=scene.width_px, height_px=scene.height_px, bodies=scene.bodies,
                 motion_blur_px=scene.motion_blur_px)


def opacity_moments(scene, config):
    """Area (px^2) and centroid (u, v) of the rendered shadow's opacity."""
    img = render_clean(body_only(scene), config)
    opacity = (1.0 - img / illumination_field(scene.width_px, scene.height_px, config)) / (
        1.0 - config.shadow_level)
    vv, uu = np.indices(opacity.shape)
    area = opacity.sum()
    return area, np.array([(uu * opacity).sum() / area, (vv * opacity).sum() / area])


def scene_at(hffaf, view_name, R, r_ref=(-0.035, 0.0, 0.0), v=(690.0, 0.0, 0.0)):
    view = hffaf.stations[0].views[view_name]
    return view_scene(FB, view, view.image_to_plane, R, np.asarray(r_ref, float),
                      np.asarray(v, float))


def hand_side_area_px2(roll_deg, scale_m_per_px):
    """Side-on area at zero incidence: cone triangle + cylinder rectangle + the two fin strips
    beyond the body, 2 c (h - d/2) with h(gamma) of docs/bodies.md."""
    d, c, b, t = FB.diameter_m, FB.fin_chord_m, FB.fin_span_m, FB.fin_thickness_m
    g = np.radians(roll_deg)
    cg, sg = abs(np.cos(g)), abs(np.sin(g))
    h = (0.5 * d + b) * max(cg, sg) + 0.5 * t * min(cg, sg)
    nose = 0.5 * d / np.tan(np.radians(10.0))
    area = 0.5 * d * nose + d * (FB.length_m - nose) + 2.0 * c * (h - 0.5 * d)
    return area / scale_m_per_px**2


@pytest.mark.parametrize("view_name", ["side", "top"])
@pytest.mark.parametrize("roll_deg", [0.0, 22.5, 45.0, 68.0, 137.0])
def test_side_on_render_has_the_hand_area(hffaf, view_name, roll_deg):
    """Axis along x (in both views' planes): the rendered shadow's area (default blur and
    fringe, which keep the area) is the hand outline's to 1e-6 (float32 background), and its
    centroid the polygon's (shapely) to 2e-3 px."""
    scene, truth = scene_at(hffaf, view_name, attitude([1.0, 0.0, 0.0], roll_deg))
    assert truth["roll_deg"] == pytest.approx(roll_deg - 360.0 * (roll_deg > 180.0), abs=1e-9)
    area, cen = opacity_moments(scene, QUIET)
    scale = hffaf.stations[0].views[view_name].scale_m_per_px
    assert area == pytest.approx(hand_side_area_px2(roll_deg, scale), rel=1e-6)
    poly = shapely.Polygon(scene.bodies[0])
    assert np.abs(cen - [poly.centroid.x, poly.centroid.y]).max() < 2e-3


def test_rendered_finner_at_random_attitudes_matches_its_exact_outline(hffaf):
    """Random axes (up to 8 deg off the range axis) and rolls, both views, with motion blur:
    the rendered shadow's area and centroid are the exact outline polygon's (shapely)."""
    for _ in range(4):
        axis = np.array([1.0, *RNG.uniform(-0.14, 0.14, 2)])
        roll = RNG.uniform(-180.0, 180.0)
        r_ref = np.array([-0.035, *RNG.uniform(-0.01, 0.01, 2)])
        for view_name in ("side", "top"):
            scene, truth = scene_at(hffaf, view_name, attitude(axis, roll), r_ref)
            assert truth["roll_deg"] == pytest.approx(roll, abs=1e-9)
            area, cen = opacity_moments(scene, QUIET)
            poly = shapely.Polygon(scene.bodies[0])
            assert poly.is_valid
            assert area == pytest.approx(poly.area, rel=1e-6)
            assert np.abs(cen - [poly.centroid.x, poly.centroid.y]).max() < 2e-3


def test_roll_turns_the_fins_in_the_image(hffaf):
    """Rolling by 90 deg gives the same image (cruciform), by 30 deg another one: the
    changed opacity covers at least the fin strips' area change of the hand outline."""
    axis = [1.0, 0.05, -0.03]
    imgs = {}
    for roll in (10.0, 100.0, 40.0):
        scene, _ = scene_at(hffaf, "side", attitude(axis, roll))
        imgs[roll] = render_clean(body_only(scene), QUIET)
    assert np.abs(imgs[10.0] - imgs[100.0]).max() < 1e-6
    scale = hffaf.stations[0].views["side"].scale_m_per_px
    change = np.abs(imgs[10.0] - imgs[40.0]).sum() / (QUIET.background_level
                                                       * (1.0 - QUIET.shadow_level))
    hand = abs(hand_side_area_px2(10.0, scale) - hand_side_area_px2(40.0, scale))
    assert change > 0.9 * hand > 100.0


# --------------------------------------------------------------------------- shot files


def test_sample_finner_shot_file_loads_with_uniform_solid_mass():
    """The committed sample shot names the finner; its mass properties are the uniform steel
    solid of finner_mass_properties (model axes = body axes on the diagonal)."""
    shot = load_shot(ROOT / "sample_shots" / "finner_1" / "shot.toml")
    fb = body_from_spec(shot.model)
    assert fb.kind == "finner" and fb.diameter_m == pytest.approx(0.007)
    mp = finner_mass_properties(fb, 7850.0)
    assert shot.mass.mass_kg == pytest.approx(mp.mass_kg, rel=1e-12)
    assert shot.mass.cg_model_m == pytest.approx([mp.cg_s_m, 0.0, 0.0], abs=1e-15)
    assert np.allclose(shot.mass.inertia_model_kg_m2, mp.inertia_kg_m2, rtol=1e-12,
                       atol=1e-12 * mp.itrans_kg_m2)   # off-diagonals: 0 written, 1e-24 rounding


def test_finner_shot_density_check_uses_the_fins():
    """A mass in kg written as g is refused for a finner as for the other bodies; the volume
    the density is taken over includes the fins."""
    data = tomllib.loads((ROOT / "sample_shots" / "finner_1" / "shot.toml").read_text())
    data["mass"]["mass_g"] = 0.018
    with pytest.raises(ShotFileError, match=r"mass\.mass_g: .*density"):
        shot_from_dict(data)
    data["mass"]["mass_g"] = 1.0
    fb = body_from_spec(data["model"])
    vol_cm3 = finner_mass_properties(fb, 1.0).mass_kg * 1e6
    msg = f"{vol_cm3:.4g} cm^3"
    data["mass"]["mass_g"] = 0.05 * vol_cm3
    with pytest.raises(ShotFileError, match=msg.replace(".", r"\.").replace("^", r"\^")):
        shot_from_dict(data)


def test_spec_uniform_density_excludes_the_mass_keys():
    data = tomllib.loads((SPECS / "finner_1.toml").read_text())
    data["mass"]["mass_g"] = 18.0
    with pytest.raises(SpecError, match="mass.mass_g: give either uniform_density_g_cm3"):
        spec_from_dict(data)
    data["mass"] = {"uniform_density_g_cm3": -1.0}
    with pytest.raises(SpecError, match="mass.uniform_density_g_cm3"):
        spec_from_dict(data)


# --------------------------------------------------------------------------- sample shot


@pytest.fixture(scope="module")
def finner_shot():
    return simulate_shot(load_shot_spec(SPECS / "finner_1.toml"))


def test_sample_shot_regenerates_the_committed_files(tmp_path, finner_shot):
    """tools/make_sample_shots.py wrote sample_shots/finner_1 from its spec: the same table,
    every number equal to the file's printed precision. truth.csv prints 12 significant
    digits; a value whose 13th digit sits on a rounding boundary prints one unit apart
    when the double differs in its last bit between CPUs (FMA contraction in the compiled
    integrator), so the numbers are compared to one unit of their 12th digit, not as bytes
    (seen: z of one station, -5.12542616912e-05 here against ...911e-05 in the file)."""
    out = write_shot(finner_shot, tmp_path / "finner_1", images=False, progress=False)
    sample = ROOT / "sample_shots" / "finner_1"
    new, old = pd.read_csv(out / "truth.csv"), pd.read_csv(sample / "truth.csv")
    assert list(new.columns) == list(old.columns) and len(new) == len(old)
    for c in new.columns:
        a, b = new[c].to_numpy(), old[c].to_numpy()
        if not np.issubdtype(b.dtype, np.number):
            assert list(a) == list(b), c
            continue
        unit = 10.0 ** (np.floor(np.log10(np.maximum(np.abs(b), 1e-300))) - 11)
        assert np.all(np.abs(a - b) <= unit * 1.001), c     # parsed decimals: not exact
    strip = [line for line in (out / "shot.toml").read_text().splitlines()
             if not line.startswith("notes")]
    assert strip == [line for line in (sample / "shot.toml").read_text().splitlines()
                     if not line.startswith("notes")]


def test_canted_fins_roll_the_model_up_as_first_order_theory_says(finner_shot):
    """p' = (q S d / I_x) (Cl_delta delta + Clp p d / 2V): from rest the roll rate rises
    toward p_ss = -Cl_delta delta 2V / (Clp d) with tau = 2 I_x V / (q S d^2 (-Clp)). Station
    to station, p follows p_ss + (p_k - p_ss) exp(-dt / tau) within 0.1 % of p_ss (V and so
    p_ss, tau drift by ~1.5 % along the range)."""
    shot = finner_shot
    values = dict(zip(resolve_model("basic_finner").names,
                      resolve_model("basic_finner").values(), strict=True))
    t = shot.truth
    rho = Atmosphere.from_pt(shot.spec.pressure_pa, shot.spec.temperature_k).density
    d = FB.diameter_m
    S = np.pi * d * d / 4.0
    ix = shot.spec.inertia_model_kg_m2[0][0]
    p = t["p_rad_s"].to_numpy()
    assert p[0] > 0 and np.all(np.diff(p) > 0)            # rolling up from rest
    for k in range(len(t) - 1):
        V = 0.5 * (t.airspeed_m_s[k] + t.airspeed_m_s[k + 1])
        q = 0.5 * rho * V * V
        p_ss = -values["Cl_delta"] * values["delta_cant"] * 2.0 * V / (values["Clp_0"] * d)
        tau = 2.0 * ix * V / (q * S * d * d * -values["Clp_0"])
        dt = t.t_s[k + 1] - t.t_s[k]
        pred = p_ss + (p[k] - p_ss) * np.exp(-dt / tau)
        assert abs(p[k + 1] - pred) < 1e-3 * p_ss      # 2e-6 measured; 10 % off Clp: 1.4e-2
    # the roll angle in the truth's quaternions grows by the integral of p
    roll = np.unwrap([quat_to_euler(r)[2] for r in t[["q0", "q1", "q2", "q3"]].to_numpy()])
    trap = np.concatenate([[0.0], np.cumsum(0.5 * (p[1:] + p[:-1]) * np.diff(t.t_s))])
    assert np.abs(roll - roll[0] - trap).max() < 0.02 * (roll[-1] - roll[0])


def test_station_scenes_draw_the_finner_at_the_truth_roll(finner_shot):
    """The scenes of the sample shot: each view's polygon is the exact outline at the state
    of the truth table (roll included), and the truth names that roll."""
    shot = finner_shot
    for k in (0, 7, 15):
        row = shot.truth.iloc[k]
        q = row[["q0", "q1", "q2", "q3"]].to_numpy(dtype=float)
        R = body_to_facility_matrix(q)
        for item in station_scenes(shot, k, np.random.default_rng(k)):
            assert item["truth"]["roll_deg"] == pytest.approx(
                np.degrees(quat_to_euler(q)[2]), abs=1e-9)
            assert roll_from_matrix(R) == pytest.approx(quat_to_euler(q)[2], abs=1e-12)
            view = shot.facility.stations[k].views[item["view"]]
            r_ref = np.array([row.x_m, row.y_m, row.z_m])
            proj = view.optics(item["affine"])
            poly = proj.from_plane(finner_silhouette(FB, R, r_ref, proj.plane_basis))
            drawn = shapely.Polygon(item["scene"].bodies[0])
            assert drawn.symmetric_difference(shapely.Polygon(poly)).area < 1e-6 * drawn.area
