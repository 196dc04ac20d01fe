"""Seed 003's global segmented roll fit (cadra.studies.segmented_roll; docs/segmented_roll.md).

Truths: seed 003's own derived figures (the steady spins +0.0280, -0.0212 and the unstable
-0.0068 of Table 2's C00 + C10 p + C30 p^3, text under Fig. 8) against the bundled model's
roll-averaged Cl by quadrature; Eq. 5 written out in numpy and integrated by scipy as a scalar
ODE against the 6-DOF roll bearing flying the model; the zero-rate peaks of the exact
simulated run against those found on its noisy record; the Wald-Wolfowitz runs count by hand
and on white and correlated noise; a global fit of simulated segments against the truth that
made them (pulls), and of noise-free segments from a wrong start (exact).
"""

import math

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import solve_ivp

from cadra.aero import resolve_model
from cadra.dynamics.observe import air_angles, observe
from cadra.dynamics.setup import propagate_states
from cadra.dynamics.trajectory import Launch
from cadra.report.roll import write_roll
from cadra.stats import runs_of_sign
from cadra.studies.segmented_roll import (
    PAPER_TABLE2,
    STEPS,
    TABLE_ORDER,
    RollRecord,
    choose_segments,
    coefficient_table,
    correlation_table,
    paper_correlation,
    roll_constants,
    segment_table,
    segmented_fit,
    steady_spins,
    zero_rate_points,
)
from cadra.validation import seed003_runs as case

MODEL = resolve_model("seed003_romof")
TRUTH = {n: float(MODEL.parameter(n).value) for n in TABLE_ORDER}


@pytest.fixture(scope="module")
def body():
    return case.seed003_body()


@pytest.fixture(scope="module")
def run1(body):
    return case.simulate_run("run1", body, MODEL)


def eq5(gamma, p, c):
    """Seed 003 Eq. 5's bracket (the asymmetry terms inside Q), written out."""
    s = c["C00"] + c["C01"] * np.cos(4 * gamma) + c["C02"] * np.cos(8 * gamma)
    s = s + sum(c[f"S0{k}"] * np.sin(4 * k * gamma) for k in range(1, 6))
    s = s + p * (c["C10"] + c["C11"] * np.cos(4 * gamma) + c["C12"] * np.cos(8 * gamma))
    return s + c["C30"] * p**3 + c["C_ac"] * np.cos(gamma) + c["C_as"] * np.sin(gamma)


def test_the_model_is_eq5_with_table2():
    rng = np.random.default_rng(3)
    g, p = rng.uniform(-7, 7, 500), rng.uniform(-0.04, 0.04, 500)
    cl = MODEL.evaluate(1.0, 0.0, 1.0, 0.1, p_hat=p, phi=g)["Cl"]
    np.testing.assert_allclose(cl, eq5(g, p, TRUTH), rtol=1e-12, atol=1e-14)
    assert {n: v[0] for n, v in PAPER_TABLE2.items()} == TRUTH


def test_steady_spins_of_table2_are_the_papers():
    """Seed 003 under Fig. 8: C_l averaged over 360 deg of roll vanishes at p = +0.0280 and
    -0.0212 (stable) and -0.0068 (unstable). The averaged Cl comes from the model by
    quadrature over the roll angle, so the asymmetry and 4k gamma terms must average out."""
    tab = steady_spins(MODEL)
    assert tab["p_hat"].to_numpy() == pytest.approx([-0.0212, -0.0068, 0.0280], abs=6e-5)
    assert tab["stable"].tolist() == [True, False, True]
    g = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    for p in tab["p_hat"]:
        mean_cl = MODEL.evaluate(1.0, 0.0, 1.0, 0.1, p_hat=p, phi=g)["Cl"].mean()
        assert abs(mean_cl) < 1e-12
    # the slope's sign from the averaged Cl a little off the root
    for p, stable in zip(tab["p_hat"], tab["stable"], strict=True):
        up = MODEL.evaluate(1.0, 0.0, 1.0, 0.1, p_hat=p + 1e-4, phi=g)["Cl"].mean()
        assert (up < 0) == stable
    # a held term that is not there counts as 0; no C_j0 at all is refused
    assert steady_spins({"C00": 0.03, "C10": -1.0})["p_hat"].tolist() == pytest.approx([0.03])
    with pytest.raises(ValueError, match="no C_j0"):
        steady_spins({"S01": 1.0})


def test_roll_bearing_flies_eq5(body, run1):
    """The 6-DOF roll bearing with the model = Eq. 5 as a scalar ODE with gamma = phi, the
    aircraft roll, and Q = q A d / I_x: the conventions (p = phi', C00 > 0 spins positive)."""
    Q, kd = roll_constants(body)
    assert Q == pytest.approx(case.Q_INF * body.area_m2 * body.d_m
                              / body.inertia_body_kg_m2[0, 0], rel=1e-12)
    t = run1.t_s[run1.t_s <= 4.0]
    ref = solve_ivp(lambda _t, s: [s[1], Q * eq5(s[0], s[1] * kd, TRUTH)],
                    (0, t[-1]), [math.radians(case.RUNS["run1"]["phi0_deg"]), 0.0],
                    t_eval=t, rtol=1e-11, atol=1e-12, method="DOP853")
    np.testing.assert_allclose(run1.phi_rad[:t.size], ref.y[0], atol=2e-5)
    np.testing.assert_allclose(run1.p_rad_s[:t.size], ref.y[1], atol=2e-4)
    # the run breaks out positive and ends in the steady spin p = +0.0280
    assert run1.p_rad_s[-1] * kd == pytest.approx(0.0280, abs=0.0005)
    # on this mount the aerodynamic roll angle (gamma) is the observed aircraft roll (phi)
    y0 = Launch(speed_m_s=0.0, theta_rad=case.ALPHA, roll_rad=1.0).state(body)
    states = propagate_states(y0, 0.0, t[::10], body.phys(), MODEL.compile(), MODEL.values(),
                              dt_max=5e-4)
    d = air_angles(states, body)["phi_rad"] - observe(states, body.ref_from_cg_body_m())["phi_rad"]
    assert np.max(np.abs((d + np.pi) % (2 * np.pi) - np.pi)) < 1e-12


def true_peaks(run):
    s = np.sign(run.p_rad_s)
    i = np.flatnonzero(s[1:] * s[:-1] < 0)
    return np.where(np.abs(run.p_rad_s[i + 1]) < np.abs(run.p_rad_s[i]), i + 1, i)


def test_segments_start_at_the_zero_rate_peaks(run1):
    rec = case.measured_record(run1, np.random.default_rng(11))
    peaks, found = true_peaks(run1), zero_rate_points(rec)
    assert found.size == peaks.size >= 16
    assert np.max(np.abs(found - peaks)) <= 1
    segs = choose_segments(rec)
    # the segments tile the record
    assert segs[0].start == 0 and segs[-1].stop == len(rec.t_s)
    assert all(a.stop == b.start for a, b in zip(segs[:-1], segs[1:], strict=True))
    osc = [s for s in segs if s.kind == "oscillation"]
    # one cycle each: from a peak to the next-but-one (the first from the release)
    for s in osc[1:]:
        k = int(np.argmin(np.abs(peaks - s.start)))
        assert abs(peaks[k] - s.start) <= 1 and abs(peaks[k + 2] - s.stop) <= 1
    # after the last peak: 180 deg of roll in speed-up, 360 deg in steady spin
    turn = {"speed-up": np.pi, "steady": 2 * np.pi}
    for s in segs:
        if s.kind in turn and s.stop < len(rec.t_s):
            swept = abs(run1.phi_rad[s.stop] - run1.phi_rad[s.start])
            assert swept == pytest.approx(turn[s.kind], abs=np.radians(25))
    steady = [s for s in segs if s.kind == "steady"]
    assert len(steady) >= 10 and all(s.start > peaks[-1] for s in steady)
    # steady: the exact mean rate changes by less than ~3 % from one revolution to the next
    # (the default steady_tol, judged on the noisy record); the speed-up before them by more
    def mean_rate(a, b):
        return abs(run1.phi_rad[b] - run1.phi_rad[a]) / (run1.t_s[b] - run1.t_s[a])

    inner = [s for s in steady if s.stop + 40 < len(rec.t_s)]
    for a, b in zip(inner[:-1], inner[1:], strict=True):
        assert abs(mean_rate(b.start, b.stop) / mean_rate(a.start, a.stop) - 1) < 0.04
    first_rot = [s for s in segs if s.kind == "speed-up"][:6]
    growth = [mean_rate(b.start, b.stop) / mean_rate(a.start, a.stop) - 1
              for a, b in zip(first_rot[:-2], first_rot[2:], strict=True)]
    assert min(growth) > 0.03


def test_runs_of_sign_by_hand_and_on_noise():
    r = runs_of_sign([1.0, 2.0, -1.0, -0.5, 3.0, -2.0, -1.0, -1.0, 0.0])
    # n+ = 3, n- = 5, n = 8: E = 1 + 2*15/8 = 4.75, Var = 30*22/(64*7)
    assert (r.n, r.runs, r.longest) == (8, 4, 3)
    assert r.expected == pytest.approx(4.75)
    assert r.z == pytest.approx((4 - 4.75) / math.sqrt(660 / 448))
    rng = np.random.default_rng(5)
    white = [runs_of_sign(rng.standard_normal(60)).z for _ in range(400)]
    assert abs(np.mean(white)) < 0.15 and 0.85 < np.std(white) < 1.15
    e = rng.standard_normal(60)
    ar = np.array([e[: k + 1] @ 0.9 ** np.arange(k, -1, -1) for k in range(60)])
    assert runs_of_sign(ar).z < -3
    # all of one sign: the extreme, as the gap's sequence tests read it
    one = runs_of_sign([1.0, 2.0, 0.5, 3.0])
    assert (one.runs, one.longest, one.z, one.p) == (1, 4, -math.inf, 0.0)


def test_paper_correlation_table_is_symmetric_and_signed():
    R = paper_correlation()
    assert list(R.index) == list(TABLE_ORDER) and np.allclose(R, R.T)
    assert R.loc["C10", "C11"] == 0.840 and R.loc["C30", "C10"] == -0.696
    assert np.all(np.diag(R) == 1.0)


def small_fit(body, run1, rng, start, steps):
    """Run 1 up to 5 s (oscillation, saddles, break-out, early speed-up)."""
    keep = run1.t_s <= 5.0
    short = case.TrueRun("run1", run1.t_s[keep], run1.phi_rad[keep], run1.p_rad_s[keep])
    rec = case.measured_record(short, rng)
    return segmented_fit([rec], MODEL, body, case.ALPHA, steps=steps, start=start)


def test_global_fit_recovers_the_start_set_within_its_sigmas(body, run1, tmp_path):
    """The paper's start set free (the other seven held at the truth), started by equation
    error with the start set at 0: the local fit, then the global one through fit_shots."""
    start = MODEL.with_values({n: 0.0 for n in STEPS[0]})
    from cadra.studies.segmented_roll import equation_error_start

    keep = run1.t_s <= 5.0
    rec_for_start = case.measured_record(case.TrueRun("run1", run1.t_s[keep],
                                                      run1.phi_rad[keep], run1.p_rad_s[keep]),
                                         np.random.default_rng(21))
    start = equation_error_start([rec_for_start], start, body, list(STEPS[0]),
                                 alpha_rad=case.ALPHA)
    assert abs(start.parameter("S01").value - TRUTH["S01"]) < 0.5 * TRUTH["S01"]
    sf = small_fit(body, run1, np.random.default_rng(21), start, STEPS[:1])
    res = sf.result
    assert res.converged and sf.local.converged
    assert len(sf.segments) >= 15 and len(res.shots) == len(sf.segments)
    assert res.reduced_chi2 == pytest.approx(1.0, abs=0.15)
    tab = coefficient_table(res)
    assert list(tab.index) == [n for n in TABLE_ORDER if n in STEPS[0]]
    pulls = (tab["value"] - pd.Series(TRUTH)[tab.index]) / tab["sigma"]
    assert np.all(np.abs(pulls) < 4), pulls.to_dict()
    assert np.allclose(tab["signal_noise"], np.abs(tab["value"]) / tab["sigma"])
    # each segment's fitted roll angle at its epoch against the exact run (4 sigma)
    for sf_shot, seg in zip(res.shots, sf.segments, strict=True):
        e = seg.start + seg.n // 2
        roll = air_angles(sf_shot.state[None, :], body)["phi_rad"][0]
        d = (roll - run1.phi_rad[e] + np.pi) % (2 * np.pi) - np.pi
        assert abs(d) < 4 * sf_shot.local_sigma[6]
    C = correlation_table(res)
    assert np.allclose(C, C.T) and np.allclose(np.diag(C), 1.0)
    seg = segment_table(sf)
    assert set(seg["kind"]) <= {"oscillation", "saddle", "speed-up", "steady"}
    assert seg["rms_deg"].mean() == pytest.approx(case.SIGMA_DEG, rel=0.15)
    assert abs(seg["runs_z"].mean()) < 1.0
    out = write_roll(sf, {"table2": tab, "segments": seg}, [run1], case.ALPHA,
                     tmp_path / "roll")
    assert sorted(p.name for p in out.iterdir()) == [
        ".cadra-output", "report.md", "roll_fit.png", "segments.csv", "segments.md",
        "table2.csv", "table2.md"]
    back = pd.read_csv(out / "table2.csv", index_col=0)
    np.testing.assert_allclose(back["value"], tab["value"], rtol=1e-12)
    assert (out / "table2.md").read_text().startswith("| coefficient | value |")
    with pytest.raises(FileExistsError):      # an existing output is never overwritten
        write_roll(sf, {"table2": tab}, [run1], case.ALPHA, out)


def test_noise_free_segments_give_table2_from_the_equation_error_start(body, run1):
    """All 14 free, in the paper's steps, from the equation-error start (S01 0.70 for
    0.885, C12 12 for 40): the noise-free record's solution is the truth, to the solver's
    convergence tolerance (0.01 sigma)."""
    keep = run1.t_s <= 5.0
    rec = RollRecord("run1", run1.t_s[keep], np.mod(run1.phi_rad[keep], 2 * np.pi),
                     math.radians(case.SIGMA_DEG))
    sf = segmented_fit([rec], MODEL, body, case.ALPHA)
    res = sf.result
    assert res.converged and res.chi2 < 1e-4
    assert [r.converged for r in sf.steps] == [True] * len(STEPS)
    for n in TABLE_ORDER:
        assert abs(res.value(n) - TRUTH[n]) < 0.02 * res.sigma(n), n
