"""Every bad input a clear message: aero model files, trajectory files and shot files. Each
test asserts that the project's own error type is raised and that its message names the file
and the culprit (key, coefficient and term, station and column).
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from cadra.aero import load_model, model_from_dict, parse_expression
from cadra.aero.expr import ExpressionError
from cadra.aero.model import ModelFileError
from cadra.aero.nesting import MAX_DEPTH

# --- aero model files ----------------------------------------------------------------------


def _model(expr: str, source: str = "m.toml", **values):
    params = {"a": {"value": 1.0}, **{k: {"value": v} for k, v in values.items()}}
    return model_from_dict({"angle_plane": "sigma", "coefficients": {"CD": expr},
                            "parameters": params}, source)


def test_a_700_term_sum_loads_and_evaluates():
    """A long polynomial is legitimate: 700 terms (700 levels deep) load, compile and agree
    with the reference evaluator (no RecursionError)."""
    model = _model(" + ".join(["a*sin(sigma)"] * 700))
    got = model.evaluate(0.1, 0.0, 0.1, 0.5)["CD"]
    assert got == pytest.approx(700 * np.sin(0.1), rel=1e-12)


def test_900_unary_minuses_load():
    assert _model("-" * 900 + "a").evaluate(0.1, 0.0, 0.1, 0.5)["CD"] == 1.0


@pytest.mark.parametrize("text", ["+".join(["a"] * (MAX_DEPTH + 100)), "-" * 5000 + "a",
                                  "a" + "**a" * 3000])
def test_too_deep_is_a_clear_error(text):
    with pytest.raises(ExpressionError, match=r"m\.toml: coefficients\.CD: .*nested more than "
                                              rf"{MAX_DEPTH} levels"):
        _model(text)


def test_huge_integer_literal():
    with pytest.raises(ExpressionError, match=r"m\.toml: coefficients\.CD: integer of 401 "
                                              r"digits is too large"):
        _model("a*" + "9" * 401)
    with pytest.raises(ExpressionError, match="coefficients.CD: number too large"):
        _model("a*1e400")


def test_huge_integer_parameter_value():
    with pytest.raises(ModelFileError, match=r"m\.toml: parameters\.b\.value: integer of 401"):
        _model("a + b", b=10**400)


def test_binary_model_file_names_the_file(tmp_path):
    p = tmp_path / "binary.toml"
    p.write_bytes(bytes(range(256)))
    with pytest.raises(ModelFileError, match=re.escape(str(p)) + ": not a text file"):
        load_model(p)


@pytest.mark.parametrize(("expr", "term"), [("a + 1/0", "1.0 / 0.0 is inf"),
                                            ("a*exp(1000)", "exp(1000.0) is inf"),
                                            ("a + log(-1)", "log(-1.0) is nan")])
def test_nonfinite_constant_term_is_refused_at_load(expr, term):
    with pytest.raises(ModelFileError, match=r"m\.toml: coefficients\.CD: the term "
                                             + re.escape(term)):
        _model(expr)


def test_nonfinite_everywhere_is_refused_at_load():
    with pytest.raises(ModelFileError, match=r"m\.toml: coefficients\.CD: not finite at any "
                                             r".*the term log\(-mach\) is nan"):
        _model("a*log(-mach)")
    # non-finite at some points only (a supersonic form) is legitimate
    m = _model("a*sqrt(mach**2 - 1)")
    note = m.nonfinite_note()
    assert note.startswith("; coefficient CD is not finite at ")
    assert "sqrt(mach ** 2.0 - 1.0) is nan" in note
    assert _model("a*sin(sigma)").nonfinite_note() == ""


def test_depth_check_leaves_the_recursion_limit_alone():
    import sys

    before = sys.getrecursionlimit()
    parse_expression(" + ".join(["a"] * 500))
    assert sys.getrecursionlimit() == before


def test_deep_model_compiles_in_a_thread():
    """The raised limit is per call, also off the main thread (the fitting's workers)."""
    import threading

    out = {}

    def work():
        out["cd"] = _model(" + ".join(["a*mach"] * 700)).evaluate(0.1, 0.0, 0.1, 0.5)["CD"]

    t = threading.Thread(target=work)
    t.start()
    t.join()
    assert out["cd"] == pytest.approx(350.0)


def test_no_warnings_from_the_load_check():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _model("a*sqrt(mach - 1) + a/sin(sigma)")


# --- trajectory files ----------------------------------------------------------------------

SHOT = "sample_shots/m2_2429/shot.toml"


def _trajectory(tmp_path, n=6, edit=None):
    """A trajectory file of the first ``n`` stations of the M2-2429 sample's truth; ``edit``
    changes the table (file units) before it is written."""
    from cadra.validation.truth_files import write_trajectory_file

    return write_trajectory_file("sample_shots/m2_2429/truth.csv", None,
                                 tmp_path / "trajectory.csv", shot_id="M2-2429",
                                 rows=slice(None, n), edit=edit)


def _set(row, column, value):
    def edit(t):
        t.loc[row, column] = value
    return edit


@pytest.mark.parametrize(("column", "value", "what"), [
    ("t_s", "abc", "'abc' is not a number"),
    ("theta_deg", "ten", "'ten' is not a number"),
    ("x_m", float("inf"), "inf is not finite"),
    ("sigma_y_m", float("inf"), "inf is not finite"),
    ("sigma_z_m", -1e-4, "-0.0001 is not a sigma"),
    ("sigma_theta_deg", 0.0, "0 is not a sigma"),
    ("x_m", 1e300, "> 10000 is implausible"),
    ("psi_deg", -4000.0, "> 180 is implausible"),
])
def test_bad_trajectory_cell_names_station_and_column(tmp_path, column, value, what):
    from cadra.io.trajectory import TrajectoryFileError, load_trajectory

    p = _trajectory(tmp_path, edit=_set(2, column, value))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no RuntimeWarning flood either
        with pytest.raises(TrajectoryFileError,
                           match=re.escape(f"{p}: station 3, column {column}: ") + ".*"
                           + re.escape(what)):
            load_trajectory(p)


def test_all_sigmas_zero_is_refused_naming_the_first(tmp_path):
    from cadra.flight.data import FitDataError, load_shot_data

    def zero(t):
        for c in ("sigma_x_m", "sigma_y_m", "sigma_z_m", "sigma_theta_deg", "sigma_psi_deg"):
            t[c] = 0.0

    p = _trajectory(tmp_path, edit=zero)
    with pytest.raises(FitDataError, match=re.escape(f"{p}: station 1, column sigma_x_m: 0 is "
                                                     "not a sigma")):
        load_shot_data(SHOT, p)


def test_nan_still_means_not_measured(tmp_path):
    """A value and its sigma both empty: not measured. A measured value whose sigma alone is
    empty is refused, naming the station and column (it was dropped without a word)."""
    from cadra.flight.data import FitDataError, load_shot_data

    def lose(t):
        t.loc[1, "theta_deg"] = np.nan
        t.loc[1, "sigma_theta_deg"] = np.nan

    sd = load_shot_data(SHOT, _trajectory(tmp_path, edit=lose))
    assert np.isnan(sd.meas[1, 3])
    assert sd.n_observations == 6 * 5 - 1

    def half(t):
        t.loc[2, "sigma_psi_deg"] = np.nan

    with pytest.raises(FitDataError, match="column sigma_psi_deg: is empty: a measured psi_deg"):
        load_shot_data(SHOT, _trajectory(tmp_path / "half", edit=half))


@pytest.mark.parametrize(("n", "what"), [(0, "no stations"),
                                         (1, "1 measured station(s) with a position"),
                                         (2, "2 measured station(s) with a position")])
def test_too_few_stations_is_a_clear_error(tmp_path, n, what):
    from cadra.flight.data import FitDataError, load_shot_data

    p = _trajectory(tmp_path, n=n)
    with pytest.raises(FitDataError, match=re.escape(f"{p}: {what}")):
        load_shot_data(SHOT, p)


def test_binary_and_garbled_trajectory_files(tmp_path):
    from cadra.io.trajectory import TrajectoryFileError, load_trajectory

    p = tmp_path / "t.csv"
    p.write_bytes(b"# format: cadra-trajectory-1\n" + bytes(range(128, 256)))
    with pytest.raises(TrajectoryFileError, match=re.escape(f"{p}: not a text file")):
        load_trajectory(p)
    p.write_text("# format: cadra-trajectory-1\n")
    with pytest.raises(TrajectoryFileError, match=re.escape(f"{p}: not a CSV table")):
        load_trajectory(p)


def test_truth_table_missing_or_invalid(tmp_path):
    from cadra.io.trajectory import TrajectoryFileError, load_truth

    with pytest.raises(TrajectoryFileError, match="nope.csv: truth table not found"):
        load_truth(tmp_path / "nope.csv")
    p = tmp_path / "truth.csv"
    p.write_text("x_m,y_m,z_m,theta_deg\n0,0,0,1\n")
    with pytest.raises(TrajectoryFileError, match=r"truth\.csv: truth table lacks column\(s\) "
                                                  r"\['psi_deg'\]"):
        load_truth(p)
    p.write_text("x_m,y_m,z_m,theta_deg,psi_deg\n0,0,0,1,0\n1,0,zz,1,0\n")
    with pytest.raises(TrajectoryFileError, match=r"truth\.csv: row 2, column z_m: 'zz'"):
        load_truth(p)
    assert len(load_truth("sample_shots/m2_2429/truth.csv")) > 3


# --- shot files ----------------------------------------------------------------------------

SHOT_TEXT = Path(SHOT).read_text(encoding="utf-8")
SPHERE_TEXT = Path("sample_shots/sphere_1/shot.toml").read_text(encoding="utf-8")


def _shot(tmp_path, text, name="shot.toml"):
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def test_mass_in_kg_is_caught_by_load_and_check(tmp_path):
    from cadra.io.shot_check import check_shot
    from cadra.io.shotfile import ShotFileError, load_shot

    p = _shot(tmp_path, SHOT_TEXT.replace("mass_g = 101.02", "mass_g = 0.10102"))
    with pytest.raises(ShotFileError, match=re.escape(f"{p}: mass.mass_g: 0.10102 g") + ".*"
                       r"density of 0\.00828 g/cm\^3, outside \[0\.1, 25\] -- a mass in kg"):
        load_shot(p)
    assert check_shot(p)[0].startswith(f"shot file: {p}: mass.mass_g: ")


def test_diameter_ten_times_too_large(tmp_path):
    from cadra.io.shot_check import check_shot
    from cadra.io.shotfile import ShotFileError, load_shot

    # the mass as written: the density check names the slip
    p = _shot(tmp_path, SPHERE_TEXT.replace("d_cm = 2.0", "d_cm = 20.0"))
    with pytest.raises(ShotFileError, match=r"mass\.mass_g: .* a model dimension in the "
                                            r"wrong unit"):
        load_shot(p)
    # the mass scaled too (a consistent but wrong body): the field of view catches it
    p = _shot(tmp_path, SPHERE_TEXT.replace("d_cm = 2.0", "d_cm = 20.0")
              .replace("mass_g = 32.882", "mass_g = 32882.0")
              .replace("13.153", "131530.0"), "big.toml")
    load_shot(p)
    problems = check_shot(p)
    assert problems[0] == ("model.d_cm = 20.0: the model's diameter, 20 cm, is more than 0.5 "
                           "of the field of view of station 1 top (15.24 cm: 1600x1200 px at "
                           "0.127 mm/px); a model that large cannot be measured: check the unit")


def test_unknown_view_name_is_refused_naming_the_known_views(tmp_path):
    from cadra.io.shot_check import check_shot
    from cadra.io.shotfile import ShotFileError, load_shot

    text = SHOT_TEXT.replace('station = 2\ntime_s = 0.006438140799976919\nimages = {}',
                             'station = 2\ntime_s = 0.006438140799976919\n'
                             'images = { tpo = "a.png", side = "b.png" }')
    assert 'tpo = "a.png"' in text
    p = _shot(tmp_path, text)
    with pytest.raises(ShotFileError, match=re.escape(f"{p}: stations[1].images.tpo: unknown "
                                                      "view (known: side, top)")):
        load_shot(p)
    assert check_shot(p) == [f"shot file: {p}: stations[1].images.tpo: unknown view (known: "
                             "side, top)"]
    assert not any("unknown view" in p for p in check_shot(SHOT))


@pytest.mark.parametrize("content", [None, "x_m,y_m\n1,2\n", "x_m,y_m,z_m,theta_deg,psi_deg\n"
                                     "0,0,0,zz,0\n"])
def test_cadra1_truth_missing_or_invalid_is_one_line(tmp_path, capsys, content):
    from cadra.cli.cadra1 import main

    truth = tmp_path / "truth.csv"
    if content is not None:
        truth.write_text(content)
    code = main([SHOT, "-o", str(tmp_path / "out"), "--truth", str(truth), "-q",
                 "--workers", "1"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith(f"cadra1: {truth}: ") and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_a_body_without_volume_is_refused(tmp_path):
    """A 4e-243 cm sphere (volume 0; an input of tools/fuzz_parsers.py): refused, not a
    division by zero."""
    from cadra.io.shotfile import ShotFileError, load_shot

    p = _shot(tmp_path, SPHERE_TEXT.replace("d_cm = 2.0", "d_cm = 0.378e-242"))
    with pytest.raises(ShotFileError, match=re.escape(f"{p}: model: the body's volume, 0 cm^3")):
        load_shot(p)
