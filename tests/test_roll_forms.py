"""Seed 001's roll equations (Eqs. 21-25) written as aero-model forms and flown on the roll
bearing: the linear analysis's trim, frequency and damping (Eqs. 23-25) come out of the 6-DOF
simulation.

Truth: seed 001 Eq. 22, I_x gamma'' = L_dA dA + L_p gamma' + L_ga alpha gamma, a linear
constant-coefficient equation whose solution is gamma_T + K exp(-lambda t) cos(omega t +
delta) with gamma_T = -C_l_dA dA / (C_l_ga alpha) (Eq. 23), omega^2 + lambda^2 = -C_l_ga alpha
q S d / I_x (Eq. 24, with the damping's share of the frequency kept) and lambda = -C_lp (d /
2V) q S d / (2 I_x) (Eq. 25); a damped cosine fitted by scipy to the simulated roll.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import curve_fit

from cadra.aero import model_from_dict
from cadra.validation.roll_bearing import (
    ALPHA,
    SLOW_FINNER,
    SLOW_SPEED_M_S,
    bearing,
    roll_history,
)

U = SLOW_SPEED_M_S

ONE_DEG = math.radians(1.0)


def eq22_model(Cl_dA=0.02, dA_rad=ONE_DEG, Cl_ga=-0.5, Clp=-3.0):
    """Eq. 22 as forms: the fin-cant drive, the induced roll moment's tangent at the trim
    (C~_l_gamma_alpha gamma alpha: ``sigma`` is alpha on the bearing), linear damping."""
    return model_from_dict({
        "format": "cadra.aero/1", "name": "eq22", "angle_plane": "sigma",
        "coefficients": {"CD": "0.5", "CL": "2*sin(sigma)", "Cm": "-0.5*sin(sigma)",
                         "Cl": "Cl_dA*dA + Cl_ga*phi*sigma", "Clp": "Clp"},
        "parameters": {"Cl_dA": {"value": Cl_dA}, "dA": {"value": dA_rad, "vary": False},
                       "Cl_ga": {"value": Cl_ga}, "Clp": {"value": Clp}},
    })


def test_eq22_on_the_roll_bearing_gives_eqs_23_to_25():
    Cl_dA, dA, Cl_ga, Clp = 0.02, math.radians(1.0), -0.5, -3.0
    model = eq22_model(Cl_dA, dA, Cl_ga, Clp)
    t = np.linspace(0.0, 1.5, 1501)
    body = bearing(SLOW_FINNER, U)
    phi, _ = roll_history(model, 20.0, t, body)
    qSd = 0.5 * body.density_kg_m3 * U**2 * body.area_m2 * body.d_m
    Ix = body.inertia_body_kg_m2[0, 0]

    def damped(tt, trim, K, lam, om, delta):
        return trim + K * np.exp(-lam * tt) * np.cos(om * tt + delta)

    trim_23 = -Cl_dA * dA / (Cl_ga * ALPHA)
    lam_25 = -Clp * body.d_m / (2 * U) * qSd / (2 * Ix)
    om_24 = math.sqrt(-Cl_ga * ALPHA * qSd / Ix - lam_25**2)
    p0 = (trim_23, math.radians(20.0) - trim_23, lam_25 * 1.1, om_24 * 0.98, 0.0)
    (trim, K, lam, om, delta), _cov = curve_fit(damped, t, phi, p0=p0, xtol=1e-14, ftol=1e-14)
    assert trim == pytest.approx(trim_23, rel=1e-6)
    assert lam == pytest.approx(lam_25, rel=1e-5)
    assert om == pytest.approx(om_24, rel=1e-6)
    # Eq. 24 and 25 read back the coefficients from the fitted motion
    assert (om**2 + lam**2) * Ix / qSd / ALPHA == pytest.approx(-Cl_ga, rel=1e-5)
    assert -2 * Ix * lam / (body.d_m / (2 * U) * qSd) == pytest.approx(Clp, rel=1e-5)
    assert np.max(np.abs(phi - damped(t, trim, K, lam, om, delta))) < 1e-7
