"""Synthetic shots end to end: spec -> spark times -> scenes/images -> files, and bad input."""

import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest

from cadra.cli import cadra1, cadra2
from cadra.dynamics.observe import observe
from cadra.imaging.render import illumination_field, read_image, render_clean
from cadra.imaging.render_config import RenderConfig
from cadra.simulate import (
    SpecError,
    load_shot_spec,
    simulate_shot,
    spec_from_dict,
    station_scenes,
    write_shot,
)

SPECS = Path(__file__).resolve().parents[1] / "sample_shots" / "specs"


def spec_dict(name, **changes):
    data = tomllib.loads((SPECS / f"{name}.toml").read_text())
    data.update(changes)
    return data


@pytest.fixture(scope="module")
def m2_shot():
    return simulate_shot(load_shot_spec(SPECS / "m2_2429.toml"))


def test_sparks_fire_at_the_light_sheets(m2_shot):
    shot = m2_shot
    x_ref = observe(shot.states, shot.rigid.ref_from_cg_body_m())["x_m"]
    x_station = np.array([shot.facility.station(s).x_m for s in shot.stations])
    offsets = x_ref - x_station
    # the trigger offsets drawn from the spec's distribution (mean 4 mm, sd 2 mm)
    assert np.all(np.abs(offsets - 0.004) < 0.008)
    assert shot.times_s[0] == 0.0 and np.all(np.diff(shot.times_s) > 0)
    # 16 stations 1.524 m apart at ~230 m/s: ~6.6 ms between sparks
    assert np.allclose(np.diff(shot.times_s), 1.524 / shot.truth.airspeed_m_s[1:], rtol=0.02)


def test_slanted_gun_keeps_lifting_model_centred(m2_shot):
    z = m2_shot.truth.z_m.to_numpy()
    # lift up, lowest point mid-range, excursion centred on the axis (seed 004 Fig. 5)
    assert abs(z.max() + z.min()) < 0.005
    assert np.argmin(z) in range(5, 11)
    assert z.max() - z.min() < 0.08


def test_table3_conditions_reproduced(m2_shot):
    t = m2_shot.truth
    # Table 3 shot 2429: V = 236.3 m/s and M = 0.69 "measured midway along the test section"
    assert t.airspeed_m_s.iloc[7:9].mean() == pytest.approx(236.3, rel=0.03)
    assert t.mach.iloc[7:9].mean() == pytest.approx(0.69, abs=0.03)


def test_sphere_image_centroid_is_the_truth_reference_point():
    """Geometry chain (trajectory -> silhouette -> film affine -> pixels) against the exact
    shadow: for a sphere the reference point is the centre, the shadow's centroid."""
    spec = spec_from_dict(spec_dict("sphere_2", n_stations=3))
    shot = simulate_shot(spec)
    cfg = RenderConfig(seed=1, diffraction_fringe=0.0, bow_shock=False, wake=False,
                       scratches=0, dust=0)
    for k in range(3):
        for item in station_scenes(shot, k, np.random.default_rng(k)):
            scene = item["scene"]
            scene = type(scene)(width_px=scene.width_px, height_px=scene.height_px,
                                bodies=scene.bodies, motion_blur_px=scene.motion_blur_px)
            img = render_clean(scene, cfg)
            shadow = 1.0 - img / illumination_field(scene.width_px, scene.height_px, cfg)
            vv, uu = np.mgrid[0:img.shape[0], 0:img.shape[1]]
            w = shadow.sum()
            u_c, v_c = (uu * shadow).sum() / w, (vv * shadow).sum() / w
            assert u_c == pytest.approx(item["truth"]["u_ref_px"], abs=0.01)
            assert v_c == pytest.approx(item["truth"]["v_ref_px"], abs=0.01)
            # radius of the shadow: d / 2 at the nominal 0.127 mm/px (film scale within 0.3 %)
            r_px = np.sqrt(w / (1 - cfg.shadow_level) / np.pi)
            assert r_px == pytest.approx(0.01 / 1.27e-4, rel=0.003)


def test_write_shot_files_and_check(tmp_path):
    spec = spec_from_dict(spec_dict("m2_2429", n_stations=2))
    shot = simulate_shot(spec)
    out = write_shot(shot, tmp_path / "m2", images=True, progress=False)
    assert sorted(p.name for p in out.iterdir()) == [
        "images", "shot.toml", "truth.csv", "truth_images.csv"]
    assert len(list((out / "images").glob("*.png"))) == 4
    img = read_image(out / "images" / "st01_side.png")
    assert img.dtype == np.uint8 and img.shape == (1200, 1600)
    assert cadra1.main([str(out / "shot.toml"), "--check"]) == 0
    # nothing overwritten
    with pytest.raises(FileExistsError):
        write_shot(shot, out, images=False, progress=False)
    # a missing image is named by the check
    (out / "images" / "st02_top.png").unlink()
    assert cadra1.main([str(out / "shot.toml"), "--check"]) == 1


def test_regeneration_is_deterministic(tmp_path):
    spec = spec_from_dict(spec_dict("m1_2384", n_stations=4))
    a = write_shot(simulate_shot(spec), tmp_path / "a", images=False, progress=False)
    b = write_shot(simulate_shot(spec), tmp_path / "b", images=False, progress=False)
    for name in ("shot.toml", "truth.csv"):
        assert (a / name).read_bytes() == (b / name).read_bytes()


def test_interrupted_write_leaves_nothing(tmp_path, monkeypatch):
    import cadra.imaging.render as render_mod

    spec = spec_from_dict(spec_dict("m2_2429", n_stations=3))
    shot = simulate_shot(spec)
    calls = {"n": 0}
    real = render_mod.write_image

    def failing(path, image, **kw):
        calls["n"] += 1
        if calls["n"] == 3:
            raise OSError("disk full (simulated)")
        return real(path, image, **kw)

    monkeypatch.setattr(render_mod, "write_image", failing)
    with pytest.raises(OSError, match="disk full"):
        write_shot(shot, tmp_path / "out", images=True, progress=False)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("change, key", [
    ({"mass": {"mass_g": -5.0}}, "mass.mass_g"),
    ({"mass": {"inertia_g_cm2": [[1, 2, 0], [2, 1, 0], [0, 0, 1]]}}, "mass.inertia_g_cm2"),
    ({"range": {"pressure_torr": 0.0}}, "range.pressure_torr"),
    ({"range": {"temperature_k": 29.5}}, "range.temperature_k"),
    ({"aero_model": "no_such_model"}, "aero_model"),
    ({"launch": {"speed_m_s": -10.0}}, "launch.speed_m_s"),
    ({"effects": {"wind_facility_m_s": [1.0, 2.0]}}, "effects.wind_facility_m_s"),
    ({"aim": "up"}, "aim"),
    ({"colour": "red"}, "colour"),
])
def test_bad_spec_is_refused_naming_the_key_and_nothing_is_written(tmp_path, change, key):
    data = spec_dict("m2_2429")
    data.pop("seed004_shot") if "mass" in change or "range" in change else None
    if "mass" in change:
        data["mass"] = {"mass_g": 101.0, "x_cg_from_ref_cm": -0.44, "z_cg_cm": -0.173,
                        "inertia_g_cm2": [106.9, 83.7, 82.1], **change["mass"]}
        data.setdefault("range", {"pressure_torr": 340.0, "temperature_k": 294.7})
        data["launch"]["speed_m_s"] = 236.3
    elif "range" in change:
        data["mass"] = {"mass_g": 101.0, "x_cg_from_ref_cm": -0.44, "z_cg_cm": -0.173,
                        "inertia_g_cm2": [106.9, 83.7, 82.1]}
        data["range"] = {"pressure_torr": 340.0, "temperature_k": 294.7, **change["range"]}
        data["launch"]["speed_m_s"] = 236.3
    elif "launch" in change:
        data["launch"].update(change["launch"])
    else:
        data.update(change)
    with pytest.raises(SpecError, match=key.replace(".", r"\.")):
        simulate_shot(spec_from_dict(data))
    # the CLI refuses it too and writes nothing
    import tomli_w

    spec_path = tmp_path / "bad.toml"
    spec_path.write_text(tomli_w.dumps(data))
    out = tmp_path / "out"
    assert cadra2.main(["simulate", str(spec_path), "-o", str(out), "-q"]) == 1
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]


def test_cli_refuses_to_overwrite(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("precious")
    assert cadra2.main(["simulate", str(SPECS / "sphere_1.toml"), "-o", str(out), "-q",
                        "--no-images"]) == 1
    assert (out / "keep.txt").read_text() == "precious"
    shutil.rmtree(out)
