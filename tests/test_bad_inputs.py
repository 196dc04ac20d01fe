"""Every bad input a clear message (issue 17 items 3 and 6): aero model files, trajectory files
and shot files. Each test asserts that the project's own error type is raised and that its
message names the file and the culprit (key, coefficient and term, station and column).
"""

from __future__ import annotations

import re
import warnings

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
    with the reference evaluator (was a RecursionError)."""
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
