"""The aerodynamic roll angle phi and roll lock-in on a roll bearing (seed 001 Eqs. 27 and 31).

Truths: numpy's atan2 for phi in every quadrant and a complex step against a central
difference; seed 001 Eq. 27 integrated by scipy as a scalar ODE, against the 6-DOF roll
bearing with the same coefficients as aero-model forms; the limit cycle of Eq. 27 from the
energy balance of its own (pendulum) motion, by quadrature, against the amplitude at which the
simulated oscillation neither grows nor decays.
"""

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp
from scipy.optimize import brentq

from cadra.conventions import aero_roll_angle
from cadra.dynamics.eom import air_data
from cadra.dynamics.observe import air_angles
from cadra.dynamics.setup import RigidBody
from cadra.validation.roll_bearing import (
    SLOW_FINNER,
    SLOW_SPEED_M_S,
    bearing,
    lockin_model,
    release_state,
    roll_history,
)

# a finned model in a low-density tunnel: roll inertia large against rho S d^3, so the roll
# damping per cycle is small (lambda / omega ~ 0.005) and the averaging of Eq. 31 applies
FINNER, U = SLOW_FINNER, SLOW_SPEED_M_S


def test_phi_is_atan2_of_the_cross_flow_in_every_quadrant():
    rng = np.random.default_rng(1)
    phys = RigidBody(**FINNER).phys()
    R = np.eye(3)
    for _ in range(200):
        y = np.zeros(13)
        y[6] = 1.0
        y[3:6] = [50.0, *rng.normal(0, 10, 2)]
        y[3:6] *= [1, -1, -1]          # F = diag(1, -1, -1) E: body v, w from F's y, z
        v_b, variables = np.empty(3), np.empty(9)
        R = np.diag([1.0, -1.0, -1.0])
        air_data(y, phys, R, v_b, variables)
        assert variables[8] == pytest.approx(np.arctan2(v_b[1], v_b[2]), abs=1e-14)
        assert variables[8] == pytest.approx(aero_roll_angle(v_b), abs=1e-14)
    # complex step on the cross-flow, on both sides of the +-pi cut's neighbourhood
    for vw in ([3.0, -4.0], [-3.0, -4.0], [3.0, 4.0], [-0.5, 7.0]):
        y = np.zeros(13, dtype=complex)
        y[6] = 1.0
        y[3:6] = [50.0, -vw[0], -vw[1]]
        h = 1e-20
        y[4] += -1j * h                  # d/d(v)
        v_b, variables = np.empty(3, complex), np.empty(9, complex)
        air_data(y, phys.astype(complex), np.diag([1.0, -1.0, -1.0]).astype(complex), v_b,
                 variables)
        v, w = vw
        assert variables[8].imag / h == pytest.approx(w / (v * v + w * w), rel=1e-12)


def slow_bearing():
    return bearing(FINNER, U)


def test_release_puts_phi_where_asked():
    body = slow_bearing()
    for phi0 in (20.0, 70.0, -130.0):
        y0 = release_state(body, np.radians(phi0))
        assert air_angles(y0[None, :], body)["phi_rad"][0] == pytest.approx(np.radians(phi0))


def eq27_constants():
    body = slow_bearing()
    q = 0.5 * body.density_kg_m3 * U**2
    qSd = q * body.area_m2 * body.d_m
    Ix = body.inertia_body_kg_m2[0, 0]
    return qSd / Ix, qSd / Ix * body.d_m / (2 * U)


def test_roll_bearing_matches_seed001_eq27():
    """From 70 deg (seed 001 Table IV), the 6-DOF roll bearing and Eq. 27 integrated as a
    scalar ODE agree to 1e-7 rad over 20 roll cycles."""
    Cla, Clp0, Clp2 = 0.5, -2.0, 15.0
    t = np.linspace(0.0, 2.0, 2001)
    phi, states = roll_history(lockin_model(Cla, Clp0, Clp2), 70.0, t, slow_bearing())
    a, b = eq27_constants()

    def rhs(_t, s):
        g, gd = s
        return [gd, b * (Clp0 + Clp2 * (g - np.pi / 4) ** 2) * gd + a * Cla * np.sin(4 * g)]

    ref = solve_ivp(rhs, (0, t[-1]), [np.radians(70.0), 0.0], t_eval=t, rtol=1e-12,
                    atol=1e-14, method="DOP853").y[0]
    assert np.max(np.abs(phi - ref)) < 1e-7
    # locked in: the oscillation about 45 deg decays, slowly at this damping (25 deg is
    # inside Eq. 31's 41.8 deg): its peak falls in every half second
    dev = np.abs(phi - np.pi / 4)
    peaks = [dev[(t >= lo) & (t < lo + 0.5)].max() for lo in (0.0, 0.5, 1.0, 1.5)]
    assert np.all(np.diff(peaks) < 0) and peaks[-1] < np.radians(24.7)
    # the nose axis never moved
    assert np.ptp(states[:, 11]) == 0.0 and np.ptp(states[:, 12]) == 0.0


def energy_balance_amplitude(Clp0, Clp2):
    """The limit-cycle amplitude of Eq. 27 in the slow-damping limit: the work of the
    damping over one cycle of the undamped motion (a pendulum in 4 gamma, not a harmonic
    oscillator) vanishes. None when there is no root below the separatrix (45 deg)."""
    def work(K):
        return quad(lambda e: (Clp0 + Clp2 * e * e)
                    * np.sqrt(max(np.cos(4 * e) - np.cos(4 * K), 0.0)), 0.0, K, limit=200)[0]
    grid = np.linspace(0.02, np.pi / 4 - 1e-4, 80)
    w = [work(K) for K in grid]
    for k in range(len(grid) - 1):
        if np.sign(w[k]) != np.sign(w[k + 1]):
            return brentq(work, grid[k], grid[k + 1], xtol=1e-10)
    return None


def simulated_limit_cycle(model, lo_deg, hi_deg, cycles=6):
    """Bisect the release amplitude about 45 deg at which the oscillation neither grows nor
    decays over ``cycles`` cycles."""
    a, _ = eq27_constants()
    period = 2 * np.pi / np.sqrt(4 * a * float(model.parameter("Cla").value))
    t = np.linspace(0.0, cycles * period, 40 * cycles + 1)

    def growth(K_deg):
        phi, _ = roll_history(model, 45.0 + K_deg, t, slow_bearing())
        return np.max(np.abs(phi[t > (cycles - 1.2) * period] - np.pi / 4)) - np.radians(K_deg)

    return brentq(growth, lo_deg, hi_deg, xtol=1e-3)


def test_limit_cycle_at_small_amplitude_matches_eq31_and_the_energy_balance():
    """C_lp2 chosen so that Eq. 31 puts the cycle at 10 deg, where sin 4 gamma is nearly
    linear: the simulated cycle agrees with the energy balance within 1 % and with Eq. 31
    within 2 %."""
    Clp0 = -2.0
    K31 = np.radians(10.0)
    Clp2 = -4 * Clp0 / K31**2            # Eq. 31: K = 2 sqrt(-C_lp0 / C_lp2)
    K_eb = np.degrees(energy_balance_amplitude(Clp0, Clp2))
    K_sim = simulated_limit_cycle(lockin_model(0.5, Clp0, Clp2), 7.0, 13.0)
    assert K_sim == pytest.approx(K_eb, rel=0.01)
    assert K_sim == pytest.approx(10.0, rel=0.02)


def test_seed001_limit_cycle_of_41_8_deg_is_not_one_of_eq27():
    """Seed 001's Eq. 31 puts the limit cycle of C_lp0 = -2, C_lp2 = 15 at 41.8 deg, but that
    is the harmonic approximation; at 4 K = 167 deg the motion is a pendulum near its
    separatrix and the damping's work stays negative up to 45 deg: there is no cycle, and a
    release at 43 deg (above 41.8) decays, as the energy balance says and Eq. 31 does not."""
    assert np.degrees(2 * np.sqrt(2.0 / 15.0)) == pytest.approx(41.8, abs=0.05)
    assert energy_balance_amplitude(-2.0, 15.0) is None
    a, _ = eq27_constants()
    period = 2 * np.pi / np.sqrt(4 * a * 0.5)
    t = np.linspace(0.0, 10 * period, 801)
    phi, _ = roll_history(lockin_model(0.5, -2.0, 15.0), 45.0 + 43.0, t, slow_bearing())
    amp = np.abs(phi - np.pi / 4)
    assert np.max(amp[t > 8 * period]) < np.radians(43.0 - 1.0)
