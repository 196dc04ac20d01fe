"""Plausibility checks where a unit slip is likely, and non-finite numbers refused by location:
the inertia tensor's magnitude, a station bias's size, a history number
beyond a float, and the model's diameter against the image scale at load time. Each test
asserts the message names the culprit (key, station and channel, line and entry)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from cadra.io.shotfile import ShotFileError, load_shot
from cadra.validation.fuzz import bias_tables
from cadra.validation.truth_files import sphere_trajectory

ROOT = Path(__file__).resolve().parents[1]
SPHERE = ROOT / "sample_shots" / "sphere_1" / "shot.toml"
M2 = ROOT / "sample_shots" / "m2_2429" / "shot.toml"


def _write(tmp_path: Path, text: str, name: str = "shot.toml") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


# --- inertia tensor -------------------------------------------------------------------------


@pytest.mark.parametrize("tensor, culprit", [
    ("[[1e308, 1e308, 0.0], [1e308, 1e308, 0.0], [0.0, 0.0, 13.153]]", "[0][0] = 1e+308"),
    ("[[13.153, 0.0, 0.0], [0.0, 13.153, -1e308], [0.0, -1e308, 13.153]]", "[1][2] = -1e+308"),
    ("[[13.153, 0.0, 0.0], [0.0, 13.153, 0.0], [0.0, 0.0, 2e9]]", "[2][2] = 2e+09"),
])
def test_inertia_beyond_plausible_is_refused_before_the_numerics(tmp_path, tensor, culprit):
    """Components like 1e308 are refused by magnitude before the symmetry and eigenvalue
    checks, where they would overflow (a RuntimeWarning, an error under this suite's
    warnings-as-errors)."""
    text = SPHERE.read_text().replace(
        "[[13.153, 0.0, 0.0], [0.0, 13.153, 0.0], [0.0, 0.0, 13.153]]", tensor)
    p = _write(tmp_path, text)
    with pytest.raises(ShotFileError, match=re.escape(
            f"{p}: mass.inertia_g_cm2: component {culprit} g cm^2 is not a model's moment of "
            "inertia (|I| <= 1e+09 g cm^2, 100 kg at 1 m; check the unit)")):
        load_shot(p)


def test_inertia_components_beyond_plausible(tmp_path):
    text = SPHERE.read_text().replace(
        "inertia_g_cm2 = [[13.153, 0.0, 0.0], [0.0, 13.153, 0.0], [0.0, 0.0, 13.153]]",
        "Ixx_g_cm2 = 1e308\nIyy_g_cm2 = 1e308\nIzz_g_cm2 = 13.0\nIxy_g_cm2 = 1e308")
    p = _write(tmp_path, text)
    with pytest.raises(ShotFileError, match=re.escape(
            f"{p}: mass.Ixx_g_cm2/Iyy_g_cm2/Izz_g_cm2: component [0][0] = 1e+308 g cm^2 is not")):
        load_shot(p)


def test_validate_inertia_raises_no_warning():
    from cadra.io.shotfile import validate_inertia

    with np.errstate(all="raise"):
        for big in (1e308, -1e308, 1e200, 1.5e9):
            with pytest.raises(ShotFileError, match="is not a model's moment of inertia"):
                validate_inertia(np.full((3, 3), big), "k")
        validate_inertia(np.diag([1e9, 1e9, 1e9]), "k")  # the bound itself is accepted


# --- station history: non-finite numbers by location ----------------------------------------


def _two_entry_history(tmp_path):
    from cadra.calibration.history import append_entry

    first, second = bias_tables()[:2]
    append_entry(first, tmp_path)
    return append_entry(second, tmp_path)


@pytest.mark.parametrize("column, index, text", [
    ("bias_y_m", 2, "1e400"), ("sigma_z_m", 0, "-1e999"), ("bias_time_s", 2, "NaN"),
    ("sigma_x_m", 1, "Infinity"), ("sigma_x_m", 1, "-Infinity")])
def test_history_nonfinite_named_by_entry_and_key(tmp_path, column, index, text):
    """A number beyond a float (1e400 parses to inf) is named by the entry and key holding it,
    not refused as if the line were corrupted ("line 2: not valid JSON ... refusing to
    guess")."""
    from cadra.calibration.history import HISTORY_FILENAME, load_history
    from cadra.calibration.table import StationHistoryError

    path = _two_entry_history(tmp_path)
    first, second = path.read_text().splitlines()
    values = re.search(rf'"{column}":\[([^\]]*)\]', second).group(1).split(",")
    values[index] = text
    second = second.replace(re.search(rf'"{column}":\[[^\]]*\]', second).group(0),
                            f'"{column}":[{",".join(values)}]')
    path.write_text(f"{first}\n{second}\n")
    with pytest.raises(StationHistoryError, match=re.escape(
            f"{HISTORY_FILENAME}: line 2 (entry 2): key {column}[{index}]: {text} is not a "
            "finite number")):
        load_history(tmp_path, "hffaf")


# --- bias tables: absurd but finite biases --------------------------------------------------


def _csv_with(tmp_path, station: int, column: str, value: str) -> Path:
    """A valid 16-station bias-table CSV with one cell replaced."""
    from cadra.calibration.table import save_bias_table

    text = save_bias_table(bias_tables()[0], tmp_path / "ok.csv",
                           overwrite=True).read_text()
    head = [line for line in text.splitlines() if line.startswith("#")]
    rows = [line.split(",") for line in text.splitlines() if not line.startswith("#")]
    col = rows[0].index(column)
    row = next(r for r in rows[1:] if r[0] == str(station))
    row[col] = value
    p = tmp_path / "t.csv"
    p.write_text("\n".join(head + [",".join(r) for r in rows]) + "\n")
    return p


@pytest.mark.parametrize("station, column, value, shown", [
    (5, "bias_x_m", "1e30", "x: bias 1e+30 m is not a plausible station bias (|bias| <= 0.1 m"),
    (7, "bias_z_m", "-0.25", "z: bias -0.25 m is not a plausible station bias (|bias| <= 0.1 m"),
    (3, "bias_time_s", "0.02", "time: bias 0.02 s is not a plausible station bias (|bias| <= "
                               "0.001 s"),
])
def test_bias_table_absurd_bias_names_station_and_channel(tmp_path, station, column, value,
                                                          shown):
    """A finite but absurd bias (1e30 m, 25 cm, 20 ms) is refused, not loaded and applied."""
    from cadra.calibration.table import StationHistoryError, load_bias_table

    p = _csv_with(tmp_path, station, column, value)
    with pytest.raises(StationHistoryError, match=re.escape(
            f"{p}: station {station} {shown}; check the unit)")):
        load_bias_table(p)
    load_bias_table(_csv_with(tmp_path, station, column, "0.0009" if "time" in column
                              else "-0.09"))   # inside the bounds: accepted


def test_history_absurd_bias_names_line_station_and_channel(tmp_path):
    from cadra.calibration.history import HISTORY_FILENAME, load_history
    from cadra.calibration.table import StationHistoryError, _sha256, canonical_json

    path = _two_entry_history(tmp_path)
    first, second = path.read_text().splitlines()
    obj = json.loads(second)
    obj.pop("sha256")
    obj["bias_y_m"][2] = 1e30
    path.write_text(f"{first}\n{canonical_json({**obj, 'sha256': _sha256(canonical_json(obj))})}"
                    "\n")
    with pytest.raises(StationHistoryError, match=re.escape(
            f"{HISTORY_FILENAME}: line 2: station 3 y: bias 1e+30 m is not a plausible station "
            "bias (|bias| <= 0.1 m; check the unit)")):
        load_history(tmp_path, "hffaf")


def test_absurd_bias_table_is_refused_by_cadra2_fit(tmp_path, capsys):
    """The CLI path: ``cadra2 fit --bias-table FILE`` refuses it with exit status 1 before any
    fit, one line naming the file, station and channel; nothing written."""
    from cadra.cli.cadra2 import main

    table = _csv_with(tmp_path, 4, "bias_x_m", "1e30")
    traj = sphere_trajectory(tmp_path / "stage1")
    status = main(["fit", str(traj), "--model", "sphere", "--bias-table", str(table),
                   "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert status == 1
    assert err == (f"cadra2 fit: {table}: station 4 x: bias 1e+30 m is not a plausible station "
                   "bias (|bias| <= 0.1 m; check the unit)\n")
    assert not (tmp_path / "out").exists()


# --- the model's size against the image scale, at load time ---------------------------------

#: the sphere sample with a diameter 10x too large and the mass and inertia scaled with it: a
#: consistent body (the density check passes) that does not fit the field of view
BIG_SPHERE = (SPHERE.read_text().replace("d_cm = 2.0", "d_cm = 20.0")
              .replace("mass_g = 32.882", "mass_g = 32882.0").replace("13.153", "131530.0"))
SIZE_MESSAGE = ("model.d_cm = 20.0: the model's diameter, 20 cm, is more than 0.5 of the field "
                "of view of station 1 top (15.24 cm: 1600x1200 px at 0.127 mm/px); a model "
                "that large cannot be measured: check the unit")


def test_cadra1_refuses_a_model_larger_than_the_field_of_view(tmp_path, capsys):
    """Not only ``cadra1 --check``: ``cadra1`` itself refuses it before measuring, exit 2,
    one line naming the file, the key and the figures, nothing written."""
    from cadra.cli.cadra1 import main

    shot = _write(tmp_path, BIG_SPHERE, "big.toml")
    status = main([str(shot), "-o", str(tmp_path / "out"), "--workers", "1", "-q"])
    assert status == 2
    assert capsys.readouterr().err == f"cadra1: {shot}: {SIZE_MESSAGE}\n"
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("command", ["fit", "calibrate"])
def test_cadra2_refuses_a_model_larger_than_the_field_of_view(tmp_path, capsys, command):
    """``cadra2`` loading the same shot (through its trajectory file) refuses it with exit
    status 1 (input refused), naming the key, before any fit; nothing written."""
    from cadra.cli.cadra2 import main

    shot = _write(tmp_path, BIG_SPHERE, "big.toml")
    traj = sphere_trajectory(tmp_path / "stage1", shot_file=shot)
    extra = ["--model", "sphere"] if command == "fit" else ["--stations-root", str(tmp_path)]
    status = main([command, str(traj), *extra, "-o", str(tmp_path / "out")])
    assert status == 1
    assert capsys.readouterr().err == f"cadra2 {command}: {shot}: {SIZE_MESSAGE}\n"
    assert not (tmp_path / "out").exists()
    assert not (tmp_path / "stations").exists()


def test_check_model_size_is_the_check_of_cadra1_check(tmp_path):
    """One home: ``--check`` lists the same line the load-time check raises."""
    from cadra.io.shot_check import check_model_size, check_shot

    shot = _write(tmp_path, BIG_SPHERE, "big.toml")
    assert SIZE_MESSAGE in check_shot(shot)
    with pytest.raises(ShotFileError, match=re.escape(f"{shot}: {SIZE_MESSAGE}")):
        check_model_size(load_shot(shot))
    check_model_size(load_shot(SPHERE))   # the sample fits
