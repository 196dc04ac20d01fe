"""Regression tests for what the property-based parser tests (tests/test_fuzz_parsers.py,
tools/fuzz_parsers.py) found in the facility file, shot specifications, truth tables, bias
tables and station histories: one concrete input each, refused with the file's own error
class, the message naming the file and the key, row or column."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from cadra.calibration.history import HISTORY_FILENAME, append_entry, load_history
from cadra.calibration.table import (
    StationHistoryError,
    _sha256,
    canonical_json,
    load_bias_table,
    save_bias_table,
)
from cadra.io.facility_file import FacilityFileError, load_facility
from cadra.io.spec_file import SpecError, load_shot_spec
from cadra.io.trajectory import TrajectoryFileError, load_truth
from cadra.validation.fuzz import bias_tables

ROOT = Path(__file__).resolve().parents[1]


# --- bias-table CSV -------------------------------------------------------------------------


@pytest.fixture
def table_text(tmp_path):
    """A valid bias-table CSV (16 stations) written by ``save_bias_table``."""
    return save_bias_table(bias_tables()[0], tmp_path / "ok.csv").read_text()


def _cell(text: str, row: int, column: str, value: str) -> str:
    """``text`` with data row ``row`` (1-based), column ``column`` set to ``value``."""
    lines = text.splitlines()
    k = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    j = lines[k].split(",").index(column)
    cells = lines[k + row].split(",")
    cells[j] = value
    lines[k + row] = ",".join(cells)
    return "\n".join(lines) + "\n"


def test_bias_table_not_utf8(tmp_path, table_text):
    p = tmp_path / "t.csv"
    p.write_bytes(table_text.encode() + b"\xb7\xff\n")
    with pytest.raises(StationHistoryError, match=r"t\.csv: not a text file \(not UTF-8: "
                                                  r"byte 0xb7"):
        load_bias_table(p)


@pytest.mark.parametrize("body, why", [("", "No columns"), ("station,bias_x_m\n1,2\n1,2,3,4\n",
                                                            "Expected 2 fields")])
def test_bias_table_not_csv(tmp_path, table_text, body, why):
    head = "".join(line + "\n" for line in table_text.splitlines() if line.startswith("#"))
    p = tmp_path / "t.csv"
    p.write_text(head + body)
    with pytest.raises(StationHistoryError, match=rf"t\.csv: not a CSV table .*{why}"):
        load_bias_table(p)


@pytest.mark.parametrize("row, column, value, message", [
    # a text cell: named by row and column
    (2, "bias_y_m", "exp(1)", r"row 2, column bias_y_m: 'exp\(1\)' is not a number"),
    # 1e300 as a station id: refused by row, not a RuntimeWarning (invalid cast) out of numpy
    (3, "station", "1e300", r"stations: row 3: 1e\+300 is not a station id"),
    # a 400-digit integer: refused by station and channel, not an OverflowError (int too
    # large to convert to float)
    (4, "sigma_time_s", "9" * 400, r"station 4 time: sigma inf must be > 0 and finite"),
    (5, "bias_x_m", "-inf", r"station 5 x: bias -inf is not finite"),
])
def test_bias_table_bad_cell_is_named(tmp_path, table_text, row, column, value, message):
    p = tmp_path / "t.csv"
    p.write_text(_cell(table_text, row, column, value))
    with pytest.raises(StationHistoryError, match=r"t\.csv: " + message):
        load_bias_table(p)


# --- station history ------------------------------------------------------------------------


def _history_with(tmp_path, change) -> Path:
    """A one-entry history whose entry is changed by ``change(dict)`` and signed again."""
    path = append_entry(bias_tables()[1], tmp_path)
    obj = json.loads(path.read_text())
    obj.pop("sha256")
    change(obj)
    path.write_text(canonical_json({**obj, "sha256": _sha256(canonical_json(obj))}) + "\n")
    return path


def test_history_integer_beyond_float(tmp_path):
    """A 332-digit integer: refused by line and key, not an OverflowError (int too large to
    convert to float)."""
    _history_with(tmp_path, lambda d: d["bias_x_m"].__setitem__(1, 2**1100))
    with pytest.raises(StationHistoryError, match=rf"{HISTORY_FILENAME}: line 1: "
                                                  r"bias_x_m\[1\]: an integer of 332 digits"):
        load_history(tmp_path, "hffaf")


def test_history_station_beyond_int64(tmp_path):
    """2**70 as a station id: refused, not an OverflowError (Python int too large to convert to
    C long)."""
    _history_with(tmp_path, lambda d: d["stations"].__setitem__(0, 2**70))
    with pytest.raises(StationHistoryError, match=rf"{HISTORY_FILENAME}: line 1: stations: "
                                                  rf"{2**70} is not a station id"):
        load_history(tmp_path, "hffaf")


def test_history_number_beyond_float(tmp_path):
    """``1e400`` (inf when parsed) in a line: named by line, entry and key (neither a
    ValueError from the canonical JSON, "Out of range float values are not JSON compliant",
    nor "not valid JSON")."""
    path = append_entry(bias_tables()[1], tmp_path)
    path.write_text(re.sub(r'"bias_x_m":\[[^,\]]+', '"bias_x_m":[1e400', path.read_text()))
    with pytest.raises(StationHistoryError, match=re.escape(
            f"{HISTORY_FILENAME}: line 1 (entry 1): key bias_x_m[0]: 1e400 is not a finite "
            "number")):
        load_history(tmp_path, "hffaf")


# --- truth table ----------------------------------------------------------------------------


def test_truth_integer_beyond_float(tmp_path):
    """A 401-digit integer in a truth table: refused, not an OverflowError from pandas (a Python
    int in an object column)."""
    lines = (ROOT / "sample_shots" / "m2_2429" / "truth.csv").read_text().splitlines()
    cells = lines[2].split(",")
    cells[lines[0].split(",").index("y_m")] = "9" * 401
    lines[2] = ",".join(cells)
    p = tmp_path / "truth.csv"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(TrajectoryFileError, match=r"truth\.csv: row 2, column y_m: .* is not "
                                                  r"a finite number"):
        load_truth(p)


def test_truth_inf_shown_plainly(tmp_path):
    p = tmp_path / "truth.csv"
    p.write_text("station,x_m,y_m,z_m,theta_deg,psi_deg\n1,0,0,0,0,0\n2,0,0,inf,0,0\n")
    with pytest.raises(TrajectoryFileError, match=r"truth\.csv: row 2, column z_m: inf is not "
                                                  r"a finite number"):
        load_truth(p)


# --- facility file --------------------------------------------------------------------------

FACILITY = (ROOT / "facilities" / "hffaf.toml").read_text()


@pytest.mark.parametrize("old, new, culprit", [
    # a shear of 1e300 with the right determinant: refused, not a RuntimeWarning (overflow in
    # matmul)
    ("[0.0, -0.000127, 0.0761365]]", "[1e300, -0.000127, 0.0761365]]",
     r"stations\[0\]\.views\.top\.image_to_plane\[1\]\[0\]: 1e\+300 is implausibly large"),
    ("[[0.000127, 0.0, -0.1015365]", "[[0.000127, 0.0, -1e300]",
     r"stations\[0\]\.views\.top\.image_to_plane\[0\]\[2\]: -1e\+300 is implausibly large"),
    ("x_m = 0.0", "x_m = 1e300", r"stations\[0\]\.x_m: 1e\+300 is not a position in metres"),
    ("scale_m_per_px = 0.000127", "scale_m_per_px = 1e-200",
     r"view_defaults\.scale_m_per_px: 1e-200 m/px is implausibly small"),
])
def test_facility_implausible_numbers(tmp_path, old, new, culprit):
    assert old in FACILITY
    p = tmp_path / "fac.toml"
    p.write_text(FACILITY.replace(old, new, 1))
    with pytest.raises(FacilityFileError, match=rf"fac\.toml: {culprit}"):
        load_facility(p)


# --- shot specification ---------------------------------------------------------------------


def test_spec_inertia_beyond_plausible(tmp_path):
    """[1e308, 1e308, 1e308]: refused, not a RuntimeWarning (overflow) in the inertia check."""
    text = (ROOT / "sample_shots" / "specs" / "sphere_bias_1.toml").read_text()
    p = tmp_path / "spec.toml"
    p.write_text(re.sub(r"^inertia_g_cm2 = .*$", "inertia_g_cm2 = [1e308, 1e308, 1e308]",
                        text, count=1, flags=re.M))
    with pytest.raises(SpecError, match=r"spec\.toml: mass\.inertia_g_cm2: 1e\+308 g cm\^2 is "
                                        r"implausibly large"):
        load_shot_spec(p)
