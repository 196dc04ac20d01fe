"""Atmosphere against seed 004 Table 3 (every shot), with Table 2's per-shot diameter.

Named truth: seed 004 (Brown et al., HFFAF Orion capsule), Table 3 "Shot flight and launch
parameters" (rho, M, Re_D from P, T, V) and Table 2 (d). "A nominal viscosity for air, at
295 K, was used to compute Re_D."

Findings (also in cadra/data/README.md):

* rho: P/(R T) with R = 287.05 reproduces every printed rho to its rounding (+-0.0005) plus
  1.5e-4 -- the table sits systematically ~0.03 % above R = 287.05 (as if R ~ 286.95) -- except
  shot 2431, printed 0.538 where P, T give 0.5373 (a 0.13 % excess; known print/rounding
  inconsistency, asserted explicitly below).
* M: sqrt(1.4 R T) reproduces every printed M to +-0.005.
* Re: with rho from P, T and the shot's own d, a constant mu in [1.80945e-5, 1.80976e-5] Pa s
  reproduces all 24 rows to half a unit of the last printed digit; the handbook value
  1.81e-5 (SEED004_NOMINAL_VISCOSITY_PA_S) to half a unit + 0.02 %. Sutherland at 295 K
  (1.8222e-5) is 0.7 % higher, so it gives every Re ~0.7 % low.
* Shot 2433's Re (2.83e5 at V = 227.0 m/s, vs 2.39e5 for 2428 at 226.6 m/s) is NOT an OCR
  error: 2433 flew at 400 torr (rho = 0.634), the others at 340 torr; it is reproduced.
"""

import math

import numpy as np
import pytest

from cadra import units
from cadra.atmosphere import (
    SEED004_NOMINAL_VISCOSITY_PA_S,
    SEED004_NOMINAL_VISCOSITY_T_K,
    Atmosphere,
    density,
    speed_of_sound,
    sutherland_viscosity,
)
from cadra.io.seed004 import load_seed004_table

TABLE = load_seed004_table()
SHOTS = [int(s) for s in TABLE["shot"]]

#: Rows whose printed density is inconsistent with their P and T beyond rounding:
#: shot -> (printed, value computed from P, T with R = 287.05).
KNOWN_DENSITY_INCONSISTENCIES = {2431: (0.538, 0.53731)}

RHO_ROUNDING = 0.0005
RHO_SLACK = 1.5e-4        # the table's systematic ~0.03 % offset from R = 287.05
MACH_ROUNDING = 0.005
RE_SLACK_REL = 2e-4       # 1.81e-5 vs the best constant (1.8096e-5)


def _row(shot):
    return TABLE[TABLE["shot"] == shot].iloc[0]


def _atm(row, **kw):
    return Atmosphere.from_pt(units.torr_to_pa(row["pressure_torr"]), row["temperature_k"], **kw)


def _re_half_unit(printed_re):
    """Half a unit of the last printed digit: 'x.yz e5' -> 500, '1y.z e5' -> 5000."""
    return 5000.0 if printed_re >= 1e6 else 500.0


def test_table_has_all_24_shots():
    assert len(TABLE) == 24
    assert TABLE["model"].value_counts().to_dict() == {"M1": 12, "M2": 10, "M3": 2}


def test_basic_physics():
    assert density(101325.0, 288.15) == pytest.approx(1.2250, abs=1e-4)   # ISA sea level
    assert speed_of_sound(288.15) == pytest.approx(340.29, abs=3e-3)  # ISA: 340.294
    assert sutherland_viscosity(273.15) == pytest.approx(1.716e-5, rel=1e-12)
    assert sutherland_viscosity(288.15) == pytest.approx(1.7894e-5, rel=1e-3)   # ISA value
    atm = Atmosphere.from_pt(101325.0, 288.15)
    assert atm.mach(atm.speed_of_sound) == 1.0
    assert atm.reynolds(10.0, 0.1) == pytest.approx(1.225 * 10 * 0.1 / 1.7894e-5, rel=1e-3)
    assert atm.dynamic_pressure(100.0) == pytest.approx(0.5 * atm.density * 1e4)
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ValueError):
            Atmosphere.from_pt(bad, 295.0)
        with pytest.raises(ValueError):
            Atmosphere.from_pt(1e5, bad)


def test_nominal_viscosity_options():
    atm = Atmosphere.from_pt(45000.0, 293.0, nominal_viscosity_t_k=295.0)
    assert atm.viscosity == sutherland_viscosity(295.0)
    atm2 = Atmosphere.from_pt(45000.0, 293.0, viscosity_pa_s=1.81e-5)
    assert atm2.viscosity == 1.81e-5
    assert atm2.reynolds(200.0, 0.03) == pytest.approx(
        atm2.density * 200 * 0.03 / 1.81e-5, rel=1e-15)
    assert Atmosphere.from_pt(45000.0, 293.0).reynolds(200.0, 0.03, viscosity=2e-5) == \
        pytest.approx(atm.density * 200 * 0.03 / 2e-5, rel=1e-15)


@pytest.mark.parametrize("shot", SHOTS)
def test_table3_density(shot):
    row = _row(shot)
    rho = _atm(row).density
    if shot in KNOWN_DENSITY_INCONSISTENCIES:
        printed, computed = KNOWN_DENSITY_INCONSISTENCIES[shot]
        assert row["density_kg_m3"] == printed
        assert rho == pytest.approx(computed, abs=1e-5)
        assert abs(rho - printed) > RHO_ROUNDING + RHO_SLACK  # still inconsistent: keep noted
    else:
        assert abs(rho - row["density_kg_m3"]) <= RHO_ROUNDING + RHO_SLACK, (shot, rho)


@pytest.mark.parametrize("shot", SHOTS)
def test_table3_mach(shot):
    row = _row(shot)
    m = _atm(row).mach(row["velocity_m_s"])
    assert abs(m - row["mach"]) <= MACH_ROUNDING + 1e-9, (shot, m)


@pytest.mark.parametrize("shot", SHOTS)
def test_table3_reynolds_nominal_viscosity(shot):
    """Re_D = rho V d / mu_nominal with d from Table 2 (this shot's own model)."""
    row = _row(shot)
    atm = _atm(row, viscosity_pa_s=SEED004_NOMINAL_VISCOSITY_PA_S)
    re = atm.reynolds(row["velocity_m_s"], units.cm_to_m(row["d_cm"]))
    tol = _re_half_unit(row["reynolds"]) + RE_SLACK_REL * row["reynolds"]
    assert abs(re - row["reynolds"]) <= tol, (shot, re, row["reynolds"])


def test_shot_2433_reynolds_is_consistent_not_ocr():
    r33, r28 = _row(2433), _row(2428)
    # similar speed, different pressure: the Re ratio is the density ratio
    assert r33["pressure_torr"] == 400.0 and r28["pressure_torr"] == 340.0
    ratio_re = r33["reynolds"] / r28["reynolds"]
    ratio_rho_v = (_atm(r33).density * r33["velocity_m_s"]) / (
        _atm(r28).density * r28["velocity_m_s"])
    assert ratio_re == pytest.approx(ratio_rho_v, rel=5e-3)


def test_table3_reynolds_sutherland_295k_is_0p7_percent_low():
    """Sutherland's law at 295 K: a constant ~0.7 % bias vs the table (documented)."""
    mu295 = sutherland_viscosity(SEED004_NOMINAL_VISCOSITY_T_K)
    assert mu295 == pytest.approx(1.8222e-5, rel=1e-4)
    ratios = []
    for shot in SHOTS:
        row = _row(shot)
        atm = _atm(row, nominal_viscosity_t_k=SEED004_NOMINAL_VISCOSITY_T_K)
        assert atm.viscosity == mu295
        ratios.append(atm.reynolds(row["velocity_m_s"], units.cm_to_m(row["d_cm"]))
                      / row["reynolds"])
    ratios = np.array(ratios)
    assert np.all(np.abs(ratios - 1.0) < 0.012)
    assert np.median(ratios) == pytest.approx(1.8096e-5 / mu295, abs=1.5e-3)


def test_best_constant_viscosity_interval():
    """The set of constant mu reproducing every Re to half a unit is non-empty (and where)."""
    lo, hi = 0.0, math.inf
    for shot in SHOTS:
        row = _row(shot)
        rvd = _atm(row).density * row["velocity_m_s"] * units.cm_to_m(row["d_cm"])
        half = _re_half_unit(row["reynolds"])
        lo = max(lo, rvd / (row["reynolds"] + half))
        hi = min(hi, rvd / (row["reynolds"] - half))
    assert lo < hi
    assert lo == pytest.approx(1.80945e-5, rel=1e-4) and hi == pytest.approx(1.80976e-5, rel=1e-4)
    assert abs(SEED004_NOMINAL_VISCOSITY_PA_S / hi - 1.0) < RE_SLACK_REL
