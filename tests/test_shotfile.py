"""Shot file: round trip, validation naming the key, atomic writes, seed 004 Table 2 -> SI."""

import dataclasses
import tomllib

import numpy as np
import pytest

from cadra import units
from cadra.atomic import atomic_output_dir, atomic_write_bytes, atomic_write_text
from cadra.io.seed004 import load_seed004_table, seed004_row, seed004_shot_file
from cadra.io.shotfile import (
    MassProperties,
    ShotFileError,
    StationRecord,
    dumps_shot,
    load_shot,
    save_shot,
    shot_to_dict,
)

#: Model-axis x of the M2 base centre from its reference point, for these tests only (the
#: real value comes from cadra.body; the conversion is what is tested here).
BASE_X_M = -0.0125


def _stations(n=4):
    return tuple(StationRecord(station=k, time_s=(k - 1) * 6.45e-3,
                               images={"top": f"images/st{k:02d}_top.png",
                                       "side": f"images/st{k:02d}_side.png"})
                 for k in range(1, n + 1))


def _shot(**changes):
    shot = seed004_shot_file(2429, _stations(), base_x_from_reference_m=BASE_X_M)
    return dataclasses.replace(shot, **changes)


def _write_dict(tmp_path, data, name="shot.toml"):
    """Write a raw shot-file dict (bypassing validation) for load tests."""
    import tomli_w

    path = tmp_path / name
    path.write_text(tomli_w.dumps(data))
    return path


def _dir_listing(d):
    return sorted(p.name for p in d.iterdir())


# --------------------------------------------------------------------------- Table 2 -> SI


def test_table2_row_to_shotfile_si_values():
    """Seed 004 Table 2/3, M2 shot 2429 -> ShotFile in SI (model axes)."""
    shot = seed004_shot_file(2429, _stations(), base_x_from_reference_m=BASE_X_M)
    assert shot.shot_id == "M2-2429"
    assert shot.model == {"kind": "capsule", "preset": "M2", "d_cm": 3.556, "h_cm": 2.337}
    m = shot.mass
    assert m.mass_kg == pytest.approx(0.101020, rel=1e-15)
    np.testing.assert_allclose(m.cg_model_m, [BASE_X_M + 0.01389, 0.0, -0.00173], rtol=1e-15)
    np.testing.assert_allclose(m.inertia_model_kg_m2,
                               np.diag([106.852e-7, 83.709e-7, 82.135e-7]), rtol=1e-15)
    assert shot.pressure_pa == pytest.approx(340.1 * 133.322368, rel=1e-8)
    assert shot.temperature_k == 294.7
    assert shot.nominal_velocity_m_s == 236.3
    atm = shot.atmosphere()
    assert atm.density == pytest.approx(0.536, abs=5e-4)        # Table 3
    assert atm.mach(236.3) == pytest.approx(0.69, abs=5e-3)     # Table 3


def test_seed004_table_loader():
    df = load_seed004_table()
    assert list(df.columns)[:3] == ["model", "shot", "d_cm"] and df.columns[-1] == "notes"
    row = seed004_row(2433)
    assert row["pressure_torr"] == 400.0 and row["z_cg_cm"] == -0.170
    assert seed004_row(2425)["z_cg_cm"] == -0.173  # copied as written (below the axis)
    with pytest.raises(KeyError):
        seed004_row(9999)
    df.loc[0, "mass_g"] = -1.0  # a copy: the cached table is untouched
    assert load_seed004_table().loc[0, "mass_g"] == 96.615


# --------------------------------------------------------------------------- round trip


def test_round_trip(tmp_path):
    shot = _shot(notes='multi-line\nnote with "quotes" and unicode: σ')
    path = tmp_path / "sub" / "shot.toml"
    save_shot(shot, path)
    back = load_shot(path)
    assert back.source_path == str(path)
    # everything but the SI floats is identical; those agree to an ulp (g <-> kg, cm <-> m)
    assert dataclasses.replace(back, source_path=None, mass=shot.mass) == shot
    assert back.mass.mass_kg == pytest.approx(shot.mass.mass_kg, rel=1e-15)
    np.testing.assert_allclose(back.mass.cg_model_m, shot.mass.cg_model_m, rtol=1e-15,
                               atol=1e-18)
    np.testing.assert_allclose(back.mass.inertia_model_kg_m2, shot.mass.inertia_model_kg_m2,
                               rtol=1e-15)
    # and the file is a fixed point: saving what was loaded writes the same text
    assert dumps_shot(back) == path.read_text()
    assert back.image_path(3, "side") == tmp_path / "sub" / "images" / "st03_side.png"
    assert back.station(2).images["top"] == "images/st02_top.png"
    np.testing.assert_allclose(back.times_s, [0.0, 6.45e-3, 12.9e-3, 19.35e-3])
    with pytest.raises(KeyError):
        back.image_path(9, "top")
    with pytest.raises(KeyError):
        back.image_path(1, "front")
    # a shot built from arbitrary SI values (as the simulator does) round-trips to ~1 ulp
    rng = np.random.default_rng(7)
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    inertia = Q @ np.diag([1.07e-5, 8.37e-6, 8.21e-6]) @ Q.T
    inertia = 0.5 * (inertia + inertia.T)
    sim = _shot(mass=MassProperties(0.1010123456789, rng.normal(size=3) * 0.01, inertia),
                pressure_pa=45342.123456789, temperature_k=294.71234,
                nominal_velocity_m_s=None, model={"kind": "sphere", "d_cm": 2.54})
    save_shot(sim, tmp_path / "sim.toml")
    back = load_shot(tmp_path / "sim.toml")
    assert back.mass.mass_kg == pytest.approx(sim.mass.mass_kg, rel=1e-15)
    np.testing.assert_allclose(back.mass.cg_model_m, sim.mass.cg_model_m, rtol=1e-15)
    np.testing.assert_allclose(back.mass.inertia_model_kg_m2, sim.mass.inertia_model_kg_m2,
                               rtol=1e-14, atol=1e-20)
    assert back.pressure_pa == pytest.approx(sim.pressure_pa, rel=1e-15)
    assert back.nominal_velocity_m_s is None and back.model == {"kind": "sphere", "d_cm": 2.54}


def test_component_form_of_inertia(tmp_path):
    data = shot_to_dict(_shot())
    data["mass"].pop("inertia_g_cm2")
    data["mass"].update(Ixx_g_cm2=106.852, Iyy_g_cm2=83.709, Izz_g_cm2=82.135,
                        Ixz_g_cm2=-0.5)
    shot = load_shot(_write_dict(tmp_path, data))
    I = units.kg_m2_to_g_cm2(shot.mass.inertia_model_kg_m2)
    np.testing.assert_allclose(I, [[106.852, 0, -0.5], [0, 83.709, 0], [-0.5, 0, 82.135]])


def test_refuses_overwrite(tmp_path):
    path = tmp_path / "shot.toml"
    save_shot(_shot(), path)
    before = path.read_text()
    with pytest.raises(FileExistsError):
        save_shot(_shot(shot_id="other"), path)
    assert path.read_text() == before
    save_shot(_shot(shot_id="other"), path, overwrite=True)
    assert load_shot(path).shot_id == "other"
    assert _dir_listing(tmp_path) == ["shot.toml"]  # no temporary files left


# --------------------------------------------------------------------------- bad input


BAD_OBJECTS = [
    (dict(pressure_pa=0.0), "range.pressure_torr"),
    (dict(pressure_pa=units.torr_to_pa(76000.0)), "range.pressure_torr"),
    (dict(temperature_k=29.5), "range.temperature_k"),
    (dict(temperature_k=2950.0), "range.temperature_k"),
    (dict(mass=MassProperties(-0.1, [0, 0, 0], np.eye(3) * 1e-5)), "mass.mass_g"),
    (dict(mass=MassProperties(200.0, [0, 0, 0], np.eye(3) * 1e-5)), "mass.mass_g"),
    (dict(mass=MassProperties(0.1, [0, 0, 0], np.diag([1e-5, 1e-5, -1e-6]))),
     "mass.inertia_g_cm2: tensor is not positive definite"),
    (dict(mass=MassProperties(0.1, [0, 0, 0], np.diag([1e-5, 3e-6, 3e-6]))),
     "mass.inertia_g_cm2: principal moments"),
    (dict(mass=MassProperties(0.1, [0, 0, 0], [[1e-5, 1e-6, 0], [0, 1e-5, 0], [0, 0, 1e-5]])),
     "mass.inertia_g_cm2: tensor is not symmetric"),
    (dict(mass=MassProperties(0.1, [2.0, 0, 0], np.eye(3) * 1e-5)),
     "mass.cg_from_reference_cm"),
    (dict(model={"kind": "capsule", "preset": "M2", "d_cm": 0.0}), "model.d_cm"),
    (dict(model={"kind": "sphere", "d_cm": 254.0}), "model.d_cm"),
    (dict(model={"kind": "brick"}), "model.kind"),
    (dict(model={"preset": "M2"}), "model.kind: missing"),
    (dict(shot_id=""), "shot_id"),
    (dict(facility=""), "facility"),
    (dict(stations=()), "stations"),
    (dict(stations=(StationRecord(1, 0.0, {}), StationRecord(2, -1e-3, {}))),
     "stations[1].time_s"),
    (dict(stations=(StationRecord(1, 0.0, {}), StationRecord(1, 1e-3, {}))),
     "stations: station 1 appears more than once"),
    (dict(stations=(StationRecord(1, 0.0, {"top": ""}),)), "stations[0].images.top"),
    (dict(nominal_velocity_m_s=-5.0), "nominal_velocity_m_s"),
]


@pytest.mark.parametrize("changes, key", BAD_OBJECTS)
def test_save_refuses_bad_shot_and_writes_nothing(tmp_path, changes, key):
    path = tmp_path / "out" / "shot.toml"
    with pytest.raises(ShotFileError) as exc:
        save_shot(_shot(**changes), path)
    assert key in str(exc.value)
    assert not path.exists()
    assert not (tmp_path / "out").exists() or _dir_listing(tmp_path / "out") == []


def _drop(section, key):
    def f(d):
        (d[section] if section else d).pop(key)
    return f


def _set(section, key, value):
    def f(d):
        (d[section] if section else d)[key] = value
    return f


BAD_FILES = [
    (_drop(None, "shot_id"), "shot_id: missing"),
    (_drop(None, "schema_version"), "schema_version: missing"),
    (_drop(None, "facility"), "facility: missing"),
    (_drop(None, "mass"), "mass: missing"),
    (_drop(None, "stations"), "stations: missing"),
    (_drop("mass", "mass_g"), "mass.mass_g: missing"),
    (_drop("mass", "cg_from_reference_cm"), "mass.cg_from_reference_cm: missing"),
    (_drop("mass", "inertia_g_cm2"), "mass.inertia_g_cm2: missing"),
    (_drop("range", "temperature_k"), "range.temperature_k: missing"),
    (_drop("range", "pressure_torr"), "range.pressure_torr: missing"),
    (_drop("model", "kind"), "model.kind: missing"),
    (_set("range", "pressure_torr", 0.0), "range.pressure_torr"),
    (_set("range", "pressure_torr", 76000.0), "range.pressure_torr"),
    (_set("range", "pressure_torr", "340"), "range.pressure_torr: expected a number"),
    (_set("range", "temperature_k", 29.5), "range.temperature_k"),
    (_set("range", "temperature_k", 2950.0), "range.temperature_k"),
    (_set("mass", "mass_g", -101.0), "mass.mass_g: must be positive"),
    (_set("mass", "mass_g", 2e5), "mass.mass_g"),
    (_set("mass", "cg_from_reference_cm", [1.0, 2.0]), "mass.cg_from_reference_cm"),
    (_set("mass", "inertia_g_cm2", [[1.0, 0, 0], [0, 1.0, 0]]), "mass.inertia_g_cm2"),
    (_set("mass", "inertia_g_cm2", [[100.0, 0, 0], [0, 80.0, 0], [0, 0, -1.0]]),
     "mass.inertia_g_cm2: tensor is not positive definite"),
    (_set("mass", "inertia_g_cm2", [[200.0, 0, 0], [0, 80.0, 0], [0, 0, 80.0]]),
     "mass.inertia_g_cm2: principal moments"),
    (_set("mass", "inertia_g_cm2", [[100.0, 0, "x"], [0, 80.0, 0], [0, 0, 80.0]]),
     "mass.inertia_g_cm2[0][2]: expected a number"),
    # M2's inertia in kg m^2 under the g cm^2 key (1.07e-5 kg m^2 = 106.9 g cm^2), and one
    # whose radius of gyration is larger than the model (g mm^2 read as g cm^2, x100)
    (_set("mass", "inertia_g_cm2", [[1.06852e-5, 0, 0], [0, 8.3709e-6, 0], [0, 0, 8.2135e-6]]),
     "is a radius of gyration of 0.000285 cm for 101.02 g, outside [0.01, 1]"),
    (_set("mass", "inertia_g_cm2", [[10685.2, 0, 0], [0, 8370.9, 0], [0, 0, 8213.5]]),
     "mass.inertia_g_cm2: a principal moment of 8214 g cm^2 is a radius of gyration"),
    (_set("model", "d_cm", 0.0), "model.d_cm"),
    (_set("model", "kind", "brick"), "model.kind"),
    # a known kind with another kind's keys: the body spec names the key
    (_set("model", "kind", "finner"), "model.h_cm: unknown key for a finner spec"),
    (_set(None, "schema_version", 2), "schema_version"),
    (_set(None, "colour", "red"), "colour: unknown key"),
    (_set("mass", "mass_kg", 0.1), "mass.mass_kg: unknown key"),
    (_set(None, "stations", [{"station": 1, "time_s": 0.0, "images": {}},
                             {"station": 2, "images": {}}]), "stations[1].time_s: missing"),
    (_set(None, "stations", [{"station": 0, "time_s": 0.0}]), "stations[0].station"),
    (_set(None, "stations", [{"station": 1, "time_s": 6450.0}]), "stations[0].time_s"),
]


@pytest.mark.parametrize("mutate, key", BAD_FILES)
def test_load_refuses_bad_file_naming_the_key(tmp_path, mutate, key):
    data = shot_to_dict(_shot())
    mutate(data)
    path = _write_dict(tmp_path, data)
    with pytest.raises(ShotFileError) as exc:
        load_shot(path)
    assert key in str(exc.value)
    assert str(path) in str(exc.value)


def test_load_errors_for_unreadable_files(tmp_path):
    with pytest.raises(ShotFileError, match="cannot read"):
        load_shot(tmp_path / "missing.toml")
    (tmp_path / "bad.toml").write_text("shot_id = \n")
    with pytest.raises(ShotFileError, match="not valid TOML"):
        load_shot(tmp_path / "bad.toml")


def test_dumps_is_valid_toml_and_documented_layout():
    text = dumps_shot(_shot())
    data = tomllib.loads(text)
    assert data["schema_version"] == 1
    assert data["mass"]["mass_g"] == 101.02
    assert data["mass"]["cg_from_reference_cm"] == pytest.approx(
        [1.389 + units.m_to_cm(BASE_X_M), 0.0, -0.173], rel=1e-15)
    assert data["mass"]["inertia_g_cm2"][1][1] == 83.709
    assert data["range"] == {"pressure_torr": 340.1, "temperature_k": 294.7}
    assert "[[stations]]" in text and "[mass]" in text


# --------------------------------------------------------------------------- atomic helpers


def test_atomic_writes(tmp_path):
    p = tmp_path / "a" / "b.txt"
    atomic_write_text(p, "one")
    with pytest.raises(FileExistsError):
        atomic_write_text(p, "two")
    assert p.read_text() == "one"
    atomic_write_bytes(p, b"three", overwrite=True)
    assert p.read_bytes() == b"three"
    assert _dir_listing(p.parent) == ["b.txt"]


def test_atomic_output_dir(tmp_path):
    out = tmp_path / "run"
    with atomic_output_dir(out) as tmp:
        (tmp / "x.txt").write_text("x")
        assert not out.exists()
    assert (out / "x.txt").read_text() == "x"
    with pytest.raises(FileExistsError):
        with atomic_output_dir(out):
            pass
    with pytest.raises(RuntimeError), atomic_output_dir(out, overwrite=True) as tmp:
        (tmp / "y.txt").write_text("y")
        raise RuntimeError("failed half way")
    assert _dir_listing(out) == [".cadra-output", "x.txt"]  # the old output is untouched
    with atomic_output_dir(out, overwrite=True) as tmp:
        (tmp / "y.txt").write_text("y")
    assert _dir_listing(out) == [".cadra-output", "y.txt"]
    assert _dir_listing(tmp_path) == ["run"]  # no temporaries left
    # a folder CADRA did not write is never replaced, even when told to
    mine = tmp_path / "thesis"
    mine.mkdir()
    (mine / "chapter1.tex").write_text("precious")
    with pytest.raises(ValueError, match="a folder CADRA did not write"):
        with atomic_output_dir(mine, overwrite=True) as tmp:
            (tmp / "report.md").write_text("x")
    assert _dir_listing(mine) == ["chapter1.tex"]


@pytest.mark.parametrize(("table", "message"), [
    ({"kind": "sting", "stream_m_s": 50.0}, "not a test mode"),
    ({"stream_m_s": 50.0}, "test_mode.kind"),
    ({"kind": "gimbal", "stream_m_s": 50.0, "pivot_cm": [0, 0, 0]}, "test_mode.pivot_cm"),
    ({"kind": "gimbal"}, "needs a stream"),
    ({"kind": "tunnel", "stream_m_s": 50.0, "pivot_from_cg_cm": [1.0, 0, 0]}, "has no pivot"),
    ({"kind": "pitch_pivot", "stream_m_s": 50.0, "pivot_from_cg_cm": [150.0, 0, 0]},
     "not a pivot on the model"),
    ({"kind": "range", "stream_m_s": -3.0}, "test_mode.stream_m_s"),
])
def test_test_mode_table_refused_naming_the_key(tmp_path, table, message):
    data = shot_to_dict(_shot())
    data["test_mode"] = table
    path = _write_dict(tmp_path, data)
    with pytest.raises(ShotFileError, match=message):
        load_shot(path)


def test_test_mode_round_trip_pivot_in_model_axes(tmp_path):
    """The pivot is written in model axes (y port, z up) and held in body axes (y stbd,
    z down): a pivot 1 cm ahead and 0.5 cm up of the cg is (0.01, 0, -0.005) m in body axes,
    and the file reads back identically."""
    from cadra.dynamics.modes import TestMode

    data = shot_to_dict(_shot())
    data["test_mode"] = {"kind": "gimbal", "stream_m_s": 40.0,
                         "pivot_from_cg_cm": [1.0, 0.0, 0.5]}
    shot = load_shot(_write_dict(tmp_path, data))
    assert shot.test_mode == TestMode(kind="gimbal", stream_m_s=40.0,
                                      pivot_from_cg_body_m=(0.01, 0.0, -0.005))
    save_shot(shot, tmp_path / "again.toml")
    assert load_shot(tmp_path / "again.toml").test_mode == shot.test_mode
    assert shot_to_dict(shot)["test_mode"] == data["test_mode"]


def test_test_mode_range_without_stream_loads(tmp_path):
    data = shot_to_dict(_shot())
    data["test_mode"] = {"kind": "range"}
    assert load_shot(_write_dict(tmp_path, data)).test_mode.kind == "range"
