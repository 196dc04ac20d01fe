"""Stage one's comparison with a known truth."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from cadra.imaging.truth_compare import compare_with_truth
from cadra.report.stage1 import comparison_markdown


def _tables(n=9, seed=1):
    rng = np.random.default_rng(seed)
    truth = pd.DataFrame({"station": np.arange(1, n + 1), "t_s": np.linspace(0, 0.05, n),
                          "x_m": np.linspace(0, 12, n), "y_m": rng.normal(0, 1e-3, n),
                          "z_m": rng.normal(0, 1e-3, n), "theta_deg": rng.normal(0, 5, n),
                          "psi_deg": rng.normal(0, 5, n)})
    sig = {"x_m": 2e-7, "y_m": 3e-7, "z_m": 3e-7, "theta_deg": 1e-3, "psi_deg": 1.5e-3}
    z = rng.normal(size=(n, 5))
    meas = truth[["station", "t_s"]].copy()
    meas["status"] = "ok"
    for j, c in enumerate(sig):
        meas[c] = truth[c] + z[:, j] * sig[c]
        meas[f"sigma_{c}"] = sig[c]
    return meas, truth, z, sig


def test_errors_in_units_and_sigmas_and_shot_wide_means():
    meas, truth, z, sig = _tables()
    meas.loc[3, "status"] = "failed"        # left out
    cmp = compare_with_truth(meas, truth.iloc[::-1])   # order of the truth does not matter
    ok = np.arange(9) != 3
    ps = cmp.per_station
    assert ps["station"].tolist() == [s for s in range(1, 10) if s != 4]
    for j, c in enumerate(("x", "y", "z", "theta", "psi")):
        unit = "deg" if c in ("theta", "psi") else "m"
        col = f"{c}_{unit}"
        np.testing.assert_allclose(ps[f"{c}_error_{unit}"], z[ok, j] * sig[col], rtol=1e-6,
                                   atol=1e-9 * sig[col])
        np.testing.assert_allclose(ps[f"{c}_error_sigma"], z[ok, j], rtol=1e-6, atol=1e-6)
        row = cmp.summary.set_index("channel").loc[c]
        assert row["n"] == 8 and row["unit"] == unit
        assert row["mean_z"] == pytest.approx(z[ok, j].mean(), abs=1e-6)
        assert row["mean_z_sigma"] == pytest.approx(1 / math.sqrt(8))
        assert row["rms_z"] == pytest.approx(np.sqrt(np.mean(z[ok, j] ** 2)), abs=1e-6)
        assert row["chi2_p"] == pytest.approx(stats.chi2.sf(np.sum(z[ok, j] ** 2), 8),
                                              rel=1e-5)


def test_a_shot_wide_offset_shows_in_the_mean_and_a_big_error_is_listed():
    meas, truth, _, sig = _tables(n=16, seed=2)
    meas["z_m"] += 2.0 * sig["z_m"]                      # every station 2 sigma high
    meas.loc[5, "theta_deg"] += 9.0 * sig["theta_deg"]   # one station far off
    cmp = compare_with_truth(meas, truth)
    row = cmp.summary.set_index("channel").loc["z"]
    assert row["mean_z"] == pytest.approx(2.0, abs=3 / math.sqrt(16))
    assert row["mean_z"] / row["mean_z_sigma"] > 4
    text = "\n".join(comparison_markdown(cmp))
    assert "station 6 theta: +" in text and "| z | 16 |" in text


def test_unmatched_stations_and_no_station_column():
    meas, truth, _, _ = _tables()
    cmp = compare_with_truth(meas, truth[truth["station"] != 2])
    assert cmp.unmatched == [2] and 2 not in cmp.per_station["station"].tolist()
    assert "Stations without a truth row (not compared): [2]" in comparison_markdown(cmp)
    with pytest.raises(ValueError, match="no 'station' column"):
        compare_with_truth(meas, truth.drop(columns="station"))


def test_roll_errors_modulo_turns_or_the_fins_period():
    """A roll measured continuously (whole turns on) and a cruciform's roll known only to a
    quarter turn (its fins look alike): the errors are what is left modulo the period."""
    meas, truth, _, _ = _tables()
    n = len(truth)
    truth["phi_deg"] = np.linspace(100.0, 170.0, n)
    err = np.linspace(-0.02, 0.03, n)
    meas["phi_deg"] = truth["phi_deg"] + err + 720.0          # two turns on
    meas["sigma_phi_deg"] = 0.01
    cmp = compare_with_truth(meas, truth)
    np.testing.assert_allclose(cmp.per_station["phi_error_deg"], err, atol=1e-9)
    meas["phi_deg"] = truth["phi_deg"] + err - 90.0 * 3       # three fins off
    assert np.all(np.abs(compare_with_truth(meas, truth).per_station["phi_error_deg"])
                  > 80.0)
    cmp = compare_with_truth(meas, truth, roll_period_rad=math.pi / 2)
    np.testing.assert_allclose(cmp.per_station["phi_error_deg"], err, atol=1e-9)
    np.testing.assert_allclose(cmp.per_station["phi_error_sigma"], err / 0.01, atol=1e-6)
