"""tools/validate_tricyclic.py's cases (cadra.validation.tricyclic, tricyclic_gap): seed 002
Table 2 (Jaffe's tricyclic fits to 6-DOF simulations of Run 21, a 60 deg blunt cone flown
free in a wind tunnel) and the gap diagnosis of what the tricyclic fit can only leave as a
residual.

Truths: the paper's text (V falls ~6 % over the flight, p changes < 1 %, the trim 0.67 deg,
one nonrolling iteration reproduces the 6-DOF's phi_hat: its Fig. 9), the nonrolling angle
integrated from the simulated body's own angular velocity (not from eq. 8), the unperturbed
twin of each perturbed simulation, and the injected effect and its size.
"""

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from cadra.motion import fit_epicyclic
from cadra.validation import tricyclic as vt
from cadra.validation.tricyclic_gap import diagnose

CASES = {c.key: c for c in vt.CASES + vt.SINGLES}


@pytest.fixture(scope="module")
def records():
    return {k: vt.simulate(CASES[k]) for k in ("linear", "linear_pv", "cubic", "cubic_cg",
                                                "cubic_cg_iyz", "cubic_cg_iyz_prod")}


@pytest.fixture(scope="module")
def fits(records):
    return {k: vt.tricyclic_fits(r) for k, r in records.items()}


def test_run21_flight_is_the_papers(records):
    """Seed 002: 'V ... changed about 6 % during a typical flight due to deceleration',
    'p changed less than 1 %'; the no-drag twin holds V (and so p/V) constant."""
    r = records["linear"]
    assert 0.05 < 1 - r.speed[-1] / r.speed[0] < 0.07
    assert np.ptp(r.spin) / np.mean(r.spin) < 0.01
    assert np.isclose(np.mean(r.spin), 2 * np.pi * vt.SPIN_RPS, rtol=0.01)
    flat = records["linear_pv"]
    assert np.ptp(flat.speed) / np.mean(flat.speed) < 1e-3
    # the movie: 2000 frames/s, within the paper's 125-250 frames
    assert 125 <= r.t.size <= 250 and np.allclose(np.diff(r.t), 1 / 2000)
    # the stream: q = 178 lb/ft^2 at 2220 ft/s
    assert np.isclose(0.5 * r.body.density_kg_m3 * vt.V_M_S**2, 178 * 47.880259, rtol=1e-3)


def _nonrolling_angle_from_rates(rec):
    """phi_hat from the body's angular velocity: the fixed-plane frame (lateral axis kept
    horizontal) turns about the body axis a at the rate e2' . e3, e2 = (z x a)/|z x a|,
    e3 = a x e2; nonrolling axes do not turn about a. Integrated over the frames."""
    from cadra.dynamics.observe import rotation_fb_batch

    R = rotation_fb_batch(rec.states[:, 6:10])
    a = R[:, :, 0]
    a_dot = np.cross(np.einsum("nij,nj->ni", R, rec.states[:, 10:13]), a)
    z = np.array([0.0, 0.0, 1.0])
    u = np.cross(z, a)
    u_dot = np.cross(z, a_dot)
    nu = np.linalg.norm(u, axis=1)[:, None]
    e2 = u / nu
    e2_dot = (u_dot - e2 * np.sum(e2 * u_dot, axis=1)[:, None]) / nu
    rate = np.sum(e2_dot * np.cross(a, e2), axis=1)
    return cumulative_trapezoid(rate, rec.t, initial=0.0)


def test_one_nonrolling_iteration_gives_the_6dof_phi_hat(records):
    """Seed 002 Fig. 9: phi_hat after one iteration (eq. 8 on the fixed-plane fit) against
    the 6-DOF's own. Here: the fitted phi_hat of the 12-constant fit against the rotation of
    the fixed-plane frame about the body axis, integrated from the body rates."""
    rec = records["linear_pv"]
    fit = fit_epicyclic(rec.x, rec.alpha_f, rec.beta_f, trim_rate=0.0, curvature=True,
                           nonrolling=True, variable="distance")
    exact = _nonrolling_angle_from_rates(rec)
    assert abs(exact[-1]) > 0.3                      # a real rotation (rad) ...
    # the transverse air velocity's components turn as w_NR = e^{i phi} w_F with phi the
    # fixed-plane frame's own turn about the axis (e2 = cos phi n2 + sin phi n3)
    assert np.max(np.abs(fit.nonrolling - exact)) < 0.01 * np.max(np.abs(exact))


def test_nonrolling_correction_lowers_the_rms(fits):
    """Table 2: the NR correction lowers every program's rms; with p/V constant and linear
    aerodynamics it leaves a small fraction of the 10-constant fit's (paper 0.2306 ->
    0.0550)."""
    for key, r in fits.items():
        assert r["10+NR"] < r["10"], key
        assert r["12+NR"] < r["12"], key
    pv = fits["linear_pv"]
    assert pv["10+NR"] < 0.45 * pv["10"]
    assert pv["10+NR"] < 0.1


def test_twelve_constants_take_the_cubic_drift(fits):
    """Table 2: the cubic moment's 10-constant fit leaves 0.80 deg, the 12-constant fit with
    NR 0.05 (15x lower; ours at least 8x), and varying p/V is what the linear case's
    10-constant fit adds over its p/V-constant twin."""
    c = fits["cubic"]
    assert c["10"] > 0.5
    assert c["10"] / c["12+NR"] > 8.0
    assert fits["linear"]["10"] > 1.5 * fits["linear_pv"]["10"]
    assert fits["linear"]["12+NR"] < 1.2 * fits["linear_pv"]["12+NR"]


def test_mass_asymmetries_raise_the_rms_over_their_twins(fits):
    """Table 2's last columns: Iy != Iz (2 %) raises the 12 + NR rms over the cg case
    (paper +0.17 deg), the products of inertia raise it again (paper +0.13)."""
    cg, iyz, prod = (fits[k]["12+NR"] for k in ("cubic_cg", "cubic_cg_iyz",
                                                  "cubic_cg_iyz_prod"))
    assert iyz - cg > 0.1
    assert prod - iyz > 0.05


def test_trim_arm_is_the_tables_067_deg(records):
    """The cg offset's trim arm, fitted (12 + NR) at the spin rate: the table's 0.67 deg
    (the offset is set for it: this guards the setting), and the linear record has none."""
    for key, lo, hi in (("cubic_cg", 0.6, 0.74), ("cubic", 0.0, 0.05)):
        rec = records[key]
        p = float(np.mean(rec.spin) / np.mean(rec.speed))
        f = fit_epicyclic(rec.x, rec.alpha_f, rec.beta_f, trim_rate=p, curvature=True,
                             nonrolling=True, variable="distance")
        assert lo < np.degrees(f.arm(0).K) < hi, key


def test_diagnosis_names_the_cg_offset(tmp_path):
    """The gap diagnosis of the cubic + cg case (0.1 deg, 0.1 mm noise) names the lateral
    cg offset alone, at the injected size across the axis (0.0853 mm) within 5 %, and the
    fit with it sits at the noise floor."""
    r = diagnose(CASES["cubic_cg"], 0.1, 1, tmp_path)
    assert r["named"] == ["lateral cg offset"], r["verdict"]
    assert r["reduced_chi2"][0] > 3.0 and r["reduced_chi2"][1] < 1.2
    cg = r["sizes"]["lateral cg offset"]
    assert abs(np.hypot(cg["cg_offset_y_m"], cg["cg_offset_z_m"]) / vt.CG_OFFSET_M - 1) < 0.05


@pytest.mark.slow
def test_diagnosis_names_every_mass_asymmetry(tmp_path):
    """cg offset + Iy != Iz + products (Table 2's last mass case): all three named (80 s)."""
    r = diagnose(CASES["cubic_cg_iyz_prod"], 0.1, 3, tmp_path)
    assert set(r["named"]) == {"lateral cg offset", "inertia asymmetry",
                               "products of inertia"}, r["verdict"]
    assert not r["unexplained"] and r["reduced_chi2"][1] < 1.15


@pytest.mark.slow
def test_diagnosis_of_the_varied_density_is_unexplained(tmp_path):
    """A density varying in time at the pitch period is not in the gap library (its density
    candidate is a gradient along the range): the diagnosis names the cg offset and leaves
    the rest unexplained above the noise floor; it does not name a density effect."""
    r = diagnose(CASES["cubic_cg_density"], 0.1, 4, tmp_path)
    assert "lateral cg offset" in r["named"], r["verdict"]
    assert "density gradient" not in r["named"]
    assert r["unexplained"] and r["reduced_chi2"][1] > 1.15
