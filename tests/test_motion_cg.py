"""cadra.motion cg transfer (seed 001 eqs. 13-14; eq. 14 garbled in the OCR, derived in
cadra.motion.coefficients.transfer_cg) against a kinematic evaluation of the aerodynamics about
two points, a round trip, and a body "fitted" about three pivots."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from cadra.motion import (
    FlightConditions,
    MomentDerivatives,
    fit_cg_series,
    fit_pitch,
    pitch_coefficients,
    transfer_cg,
)

BASE = MomentDerivatives(Cm_alpha=-4.0, Cmq_sum=-15.0, CZ_alpha=-3.0, CZq_sum=-3.0)


def test_transfer_round_trip():
    there = transfer_cg(BASE, 0.37)
    back = transfer_cg(there, -0.37)
    for name in ("Cm_alpha", "Cmq_sum", "CZ_alpha", "CZq_sum"):
        assert getattr(back, name) == pytest.approx(getattr(BASE, name), abs=1e-12)
    assert there.Cm_alpha == pytest.approx(-4.0 + 0.37 * -3.0)    # eq. 13 as printed


def test_transfer_matches_the_aerodynamics_evaluated_about_the_old_point():
    """Pitching about the new point N (x calibres ahead of O) at q̂ = α̇̂: the old point sees
    α_O = α + 2x q̂, and the moment about N is C_m,O + x C_Z (C_Z along z_b)."""
    rng = np.random.default_rng(4)
    for x in (-0.8, 0.25, 1.3):
        new = transfer_cg(BASE, x)
        for alpha, qhat in rng.normal(0, 0.05, (5, 2)):
            alpha_o = alpha + 2 * x * qhat
            cz_o = BASE.CZ_alpha * alpha_o + BASE.CZq_sum * qhat
            cm_o = BASE.Cm_alpha * alpha_o + BASE.Cmq_sum * qhat
            assert new.Cm_alpha * alpha + new.Cmq_sum * qhat == pytest.approx(cm_o + x * cz_o,
                                                                             abs=1e-14)
            assert new.CZ_alpha * alpha + new.CZq_sum * qhat == pytest.approx(cz_o, abs=1e-14)


def test_body_fitted_about_three_pivots_transfers_within_sigma():
    """Seed 001 Table I in miniature: 1-DOF pitch histories about three pivot positions
    (the coefficients there from transfer_cg), each fitted with noise; the eq. 13/14 lines
    through the three fits give back the base values within their sigmas."""
    cond = FlightConditions(mass_kg=1.0, Ix_kg_m2=1e-3, I_kg_m2=5e-3, d_m=0.05,
                            density_kg_m3=1.2, speed_m_s=50.0)
    qsd, d2v = cond.q_inf * cond.S * cond.d_m, cond.d_m / (2 * cond.speed_m_s)
    rng = np.random.default_rng(21)
    t = np.linspace(0.0, 3.0, 600)
    xs = np.array([-0.5, 0.0, 0.6])
    cma, cma_s, cmq, cmq_s = [], [], [], []
    for x in xs:
        c = transfer_cg(BASE, x)

        def rhs(_, y, c=c):
            return [y[1], qsd / cond.I_kg_m2 * (c.Cm_alpha * y[0] + d2v * c.Cmq_sum * y[1])]

        a = solve_ivp(rhs, (0, 3), [0.1, 0.0], t_eval=t, method="DOP853", rtol=1e-11,
                      atol=1e-13).y[0]
        fit = fit_pitch(t, a + rng.normal(0, np.radians(0.1), t.size), trim=False)
        lc = pitch_coefficients(fit, cond)
        cma.append(lc.Cm_alpha)
        cma_s.append(lc.Cm_alpha_sigma)
        cmq.append(lc.Cmq_sum)
        cmq_s.append(lc.Cmq_sum_sigma)
    f = fit_cg_series(xs, cma, cma_s, cmq, cmq_s)
    assert abs(f.Cm_alpha - BASE.Cm_alpha) < 2.5 * f.Cm_alpha_sigma
    assert abs(f.CZ_alpha - BASE.CZ_alpha) < 2.5 * f.CZ_alpha_sigma
    assert abs(f.Cmq_sum - BASE.Cmq_sum) < 2.5 * f.Cmq_sum_sigma
    assert abs(f.CZq_sum - BASE.CZq_sum) < 2.5 * f.CZq_sum_sigma
    assert f.CZ_alpha_sigma < 0.2 * abs(BASE.CZ_alpha)


def test_cg_bad_input():
    with pytest.raises(ValueError, match="^x_over_d"):
        transfer_cg(BASE, float("nan"))
    with pytest.raises(ValueError, match="^x_over_d"):
        fit_cg_series([0.0, 1.0], [1, 2], [1, 1], [1, 2], [1, 1])
    with pytest.raises(ValueError, match="^cmq_sum_sigma"):
        fit_cg_series([0.0, 1.0, 2.0], [1, 2, 3], [1, 1, 1], [1, 2, 3], [1, 0, 1])
    with pytest.raises(ValueError, match="^density_kg_m3"):
        FlightConditions(1.0, 1e-3, 5e-3, 0.05, -1.2, 50.0)
