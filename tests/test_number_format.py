"""One look for ``value ± sigma``: the console and
every report table use :func:`cadra.numfmt.pm`; the single-fit and quasi-linear tables of
``cadra2 single``, the fit report's coefficient table, the calibration and gap reports used
their own formats (``1.2346 ± 0.012``, ``+0.1235 ± 0.0123``, ``nan ± nan``)."""

from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd
import pytest

from cadra.aero import resolve_model
from cadra.numfmt import pm


@pytest.mark.parametrize("value, sigma, text", [
    (1.234567, 0.01234, "1.235 ± 0.012"),
    (-1.55749, 0.00648, "-1.5575 ± 0.0065"),
    (123456.0, 1234.0, "1.235e+05 ± 1.2e+03"),
    (0.5, None, "0.5"),
    (0.5, 0.0, "0.5 ± 0"),
    (float("nan"), 0.1, "not determined"),
    (0.5, float("inf"), "0.5 (σ not determined)"),
])
def test_pm_rule(value, sigma, text):
    assert pm(value, sigma) == text


def _single_table(n: int) -> pd.DataFrame:
    """A ``single_fits`` table of ``n`` converged shots of the ``sphere`` model whose CD_A1
    lies exactly on 0.9 + 0.02 * alpha_rms."""
    alpha = np.array([1.0, 3.0, 5.0, 7.0])[:n]
    return pd.DataFrame({
        "shot_id": [f"S{k}" for k in range(n)], "status": "converged", "converged": True,
        "message": "", "reduced_chi2": 1.1, "alpha_rms_deg": alpha,
        "CD_A1": 0.9 + 0.02 * alpha + np.array([1.234567e-3, 0, 0, 0])[:n],
        "CD_A1_sigma": 0.01234, "CD_A2": -0.1234567, "CD_A2_sigma": 0.000876})


def test_single_fit_report_uses_the_one_format(tmp_path):
    from cadra.report.studies import write_single_fits

    lines = write_single_fits(_single_table(1), resolve_model("sphere"), tmp_path / "one")
    row = next(line for line in lines if line.startswith("| S0 |"))
    # was "| S0 | converged | 1.1 | 0.92123 ± 0.012 | -0.12346 ± 0.00088 |"
    assert row == "| S0 | converged | 1.1 | 0.921 ± 0.012 | -0.12346 ± 0.00088 |"
    assert (tmp_path / "one" / "report.md").read_text().count(row) == 1


def test_quasi_linear_table_uses_the_one_format(tmp_path):
    from cadra.report.studies import write_single_fits
    from cadra.studies.single import quasi_linear_summary

    table = _single_table(4)
    lines = write_single_fits(table, resolve_model("sphere"), tmp_path / "four")
    q = quasi_linear_summary(table, "CD_A1", "alpha_rms_deg")
    row = next(line for line in lines if line.startswith("| CD_A1 | alpha_rms_deg |"))
    slope, intercept = row.split(" | ")[2:4]
    assert slope == pm(q["slope"], q["slope_sigma"])
    assert intercept == pm(q["intercept"], q["intercept_sigma"])
    # sigma to 2 significant digits, the value to the same decimal place
    m = re.fullmatch(r"(-?\d+\.(\d+)) ± (\d+\.(\d+))", slope)
    assert m and len(m.group(2)) == len(m.group(4))
    assert float(m.group(3)) == pytest.approx(q["slope_sigma"], rel=0.05)
    assert float(m.group(1)) == pytest.approx(q["slope"], abs=float(m.group(3)) / 10)


def test_fit_report_coefficients_not_nan(tmp_path):
    from cadra.report.fit import coefficient_markdown

    table = pd.DataFrame({"coefficient": ["CD", "Cma"], "form": ["A1", "A1"],
                          "A1": [0.81234, -0.25], "A1_sigma": [0.0123, math.nan],
                          "A1_held": [False, False], "other": ["", ""]})
    text = coefficient_markdown(table)
    assert "| CD | `A1` | 0.812 ± 0.012 |" in text
    assert "| Cma | `A1` | -0.25 (σ not determined) |" in text   # was "-0.25 ± inf"
    assert "nan" not in text
