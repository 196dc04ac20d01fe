"""``cadra2 motion`` on a trajectory made from the simulated sample shot
CONE-1 (sample_shots/cone_1: a 10-degree cone rolling at 62.5 rad/s, Mach 2.3, bundled
``cone_linear`` aerodynamics as truth), with Gaussian noise of the stated sigmas.

Truths, independent of cadra.motion: the model file's coefficients (C_m = Cm_a sin sigma,
C_mq = Cmq_0, C_L = CL_a sin sigma); the roots of the linear angular equation with lift,
    r^2 - (iP + D - a) r - (M + iPa) = 0   (docs/motion.md; no Magnus term in the model),
solved here with numpy from those coefficients and the truth history's speed and spin; the
truth history's own angle of attack (axis inclinations minus those of the cg's velocity).
Tolerance: 3 sigma (one noise draw: |pull| < 3 fails 0.3 % of the time for an honest sigma).
"""

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cadra.aero import resolve_model
from cadra.cli.cadra2 import main as cadra2_main
from cadra.flight.classic import analyse_shot
from cadra.flight.load import load_shots
from cadra.io.trajectory import COLUMNS, write_trajectory
from cadra.report.motion import write_outputs

SAMPLE = Path(__file__).resolve().parents[1] / "sample_shots" / "cone_1"
SIGMA_POS, SIGMA_DEG = 1e-4, 0.1


def _trajectory(path: Path, rng, rows=None) -> Path:
    t = pd.read_csv(SAMPLE / "truth.csv")
    if rows is not None:
        t = t.iloc[rows]
    n = len(t)
    table = pd.DataFrame({
        "station": t["station"].to_numpy(), "t_s": t["t_s"].to_numpy(), "status": "ok",
        **{f"{c}_m": t[f"{c}_m"] + rng.normal(0, SIGMA_POS, n) for c in "xyz"},
        **{f"{c}_deg": t[f"{c}_deg"] + rng.normal(0, SIGMA_DEG, n) for c in ("theta", "psi")},
        **{f"sigma_{c}_m": SIGMA_POS for c in "xyz"},
        **{f"sigma_{c}_deg": SIGMA_DEG for c in ("theta", "psi")},
        "x_top_minus_side_m": 0.0, "x_consistency": 0.0, "reason": "", "warnings": ""})
    write_trajectory(path, table.loc[:, list(COLUMNS)],
                     {"shot_id": "CONE-1", "shot_file": str(SAMPLE / "shot.toml")})
    return path


@pytest.fixture(scope="module")
def traj(tmp_path_factory):
    base = tmp_path_factory.mktemp("motion")
    return base, _trajectory(base / "trajectory.csv", np.random.default_rng(2026))


def _truth_roots(shot):
    """Time-domain roots of the linear angular equation from the model file and the truth."""
    truth = pd.read_csv(SAMPLE / "truth.csv")
    par = {p.name: p.value for p in resolve_model("cone_linear").parameters}
    r = shot.rigid
    V, p = truth["airspeed_m_s"].mean(), truth["p_rad_s"].mean()
    S, d, m = r.area_m2, r.d_m, r.mass_kg
    Ix, I = r.inertia_body_kg_m2[0, 0], r.inertia_body_kg_m2[1, 1]
    q = 0.5 * r.density_kg_m3 * V * V
    M = par["Cm_a"] * q * S * d / I
    D = par["Cmq_0"] * q * S * d * d / (2 * V * I)
    a = r.density_kg_m3 * S * V * par["CL_a"] / (2 * m)
    P = p * Ix / I
    roots = np.roots([1.0, -(1j * P + D - a), -(M + 1j * P * a)])
    return sorted(roots, key=lambda z: -z.imag), V, p, par


def _pull(value, sigma, truth):
    return (value - truth) / sigma


def test_motion_recovers_the_simulators_truth(traj, capsys):
    base, path = traj
    out = base / "out"
    assert cadra2_main(["motion", str(path), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "C_mα (per rad): -0.49" in text and f"wrote {out}/" in text
    for f in ("report.md", "angles.csv", "arms.csv", "coefficients.csv", "yaw_card.png",
              "arms.png", "config.toml"):
        assert (out / f).is_file() and (out / f).stat().st_size > 0, f
    assert not (out / "sectional.png").exists()      # 16 stations: too few cycles
    report = (out / "report.md").read_text()
    assert "sectional fits and the Kryloff-Bogoliuboff reduction: not computed" in report
    assert "C_mpα (Magnus): not computed" in report

    shot = load_shots([str(path)])[0][0]
    (r1, r2), V, p, par = _truth_roots(shot)
    arms = pd.read_csv(out / "arms.csv", dtype={"arm": str}).set_index("arm")
    # fitted in distance: the rates per metre are the time roots over the speed
    for arm, root in (("1", r1), ("2", r2)):
        row = arms.loc[arm]
        assert abs(_pull(row["omega_rad_per_m"], row["omega_sigma_rad_per_m"],
                         root.imag / V)) < 3, arm
    assert arms.loc["1", "omega_rad_per_m"] > 0 > arms.loc["2", "omega_rad_per_m"]

    c = pd.read_csv(out / "coefficients.csv").iloc[0]
    # C_m = Cm_a sin(sigma): the slope at the record's amplitudes (< 5 deg) is Cm_a to 0.1 %
    assert abs(_pull(c["Cm_alpha_per_rad"], c["Cm_alpha_sigma_per_rad"], par["Cm_a"])) < 3
    assert c["Cm_alpha_sigma_per_rad"] < 0.01 * abs(par["Cm_a"])
    assert abs(_pull(c["Cmq_sum_per_rad"], c["Cmq_sum_sigma_per_rad"], par["Cmq_0"])) < 3
    assert abs(_pull(c["C_L_alpha_per_rad"], c["C_L_alpha_sigma_per_rad"], par["CL_a"])) < 3
    # the gyroscopic sign: the arms' frequencies sum to +p Ix/I for the 6-DOF run's p > 0
    assert abs(_pull(c["spin_from_fit_rad_s"], c["spin_from_fit_sigma_rad_s"], p)) < 3
    assert c["spin_from_fit_rad_s"] > 3 * c["spin_from_fit_sigma_rad_s"]

    # the angle history against the truth's (axis inclinations minus the cg velocity's)
    truth = pd.read_csv(SAMPLE / "truth.csv").set_index("station")
    ang = pd.read_csv(out / "angles.csv").set_index("station")
    v = truth[["vx_m_s", "vy_m_s", "vz_m_s"]].to_numpy()
    speed = np.linalg.norm(v, axis=1)
    alpha_t = truth["theta_deg"] - np.degrees(np.arcsin(v[:, 2] / speed))
    beta_t = truth["psi_deg"] - np.degrees(np.arcsin(v[:, 1] / speed))
    meas = np.concatenate([ang[f"{c}_deg"] - tr.loc[ang.index]
                           for c, tr in (("alpha", alpha_t), ("beta", beta_t))])
    fitted = np.concatenate([ang[f"{c}_fit_deg"] - tr.loc[ang.index]
                             for c, tr in (("alpha", alpha_t), ("beta", beta_t))])
    # the measurements: the noise (rms 0.1 deg +- 12 % over 32 values) and the path's
    # approximation (the swerve's +-0.03 deg, noise-free), no more
    assert math.sqrt(np.mean(meas**2)) < 1.5 * SIGMA_DEG
    # the fitted epicycle averages the noise: expected rms sigma sqrt(8/32) = sigma/2
    assert math.sqrt(np.mean(fitted**2)) < SIGMA_DEG


def test_tricyclic_with_the_spin_gives_magnus_and_quiet_prints_one_line(traj, capsys):
    base, path = traj
    out = base / "spin"
    truth = pd.read_csv(SAMPLE / "truth.csv")
    p = float(truth["p_rad_s"].mean())
    assert cadra2_main(["motion", str(path), "-o", str(out), "--spin", f"{p:.4f}",
                        "--variable", "time", "-q"]) == 0
    cap = capsys.readouterr()
    assert cap.out.count("\n") == 1 and cap.out.startswith("motion: 1 shot(s)")
    assert "warning" not in cap.err      # the given spin agrees with the arms
    arms = pd.read_csv(out / "arms.csv", dtype={"arm": str})
    assert list(arms["arm"]) == ["1", "2", "trim"]
    # a symmetric cone has no trim: the trim arm is zero within its sigma
    trim = arms.set_index("arm").loc["trim"]
    assert trim["K_deg"] < 3 * trim["K_sigma_deg"]
    c = pd.read_csv(out / "coefficients.csv").iloc[0]
    assert c["spin_given_rad_s"] == pytest.approx(p, abs=1e-4)
    # cone_linear has no Magnus moment
    assert abs(_pull(c["Cm_p_alpha_per_rad"], c["Cm_p_alpha_sigma_per_rad"], 0.0)) < 3
    assert abs(_pull(c["Cm_alpha_per_rad"], c["Cm_alpha_sigma_per_rad"], -0.49)) < 3


def test_an_existing_output_is_refused_and_left_alone(traj, capsys):
    base, path = traj
    out = base / "existing"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    assert cadra2_main(["motion", str(path), "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert "cadra2 motion:" in err and "a folder CADRA did not write" in err
    assert cadra2_main(["motion", str(path), "-o", str(out), "--overwrite"]) == 1
    assert "a folder CADRA did not write" in capsys.readouterr().err   # not even when told
    assert [f.name for f in out.iterdir()] == ["keep.txt"]
    assert (out / "keep.txt").read_text() == "mine"
    # an output over an input is refused even with --overwrite
    assert cadra2_main(["motion", str(path), "-o", str(base), "--overwrite"]) == 1
    assert "cadra2 motion:" in capsys.readouterr().err


def test_too_few_stations_is_one_clear_message(tmp_path, capsys):
    path = _trajectory(tmp_path / "short.csv", np.random.default_rng(1), rows=range(5))
    out = tmp_path / "out"
    assert cadra2_main(["motion", str(path), "-o", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err
    assert err.startswith("cadra2 motion: ") and "5 station(s)" in err
    assert "the epicyclic fit needs at least 6" in err
    assert not out.exists()


def test_bad_spin_count_is_refused(traj, capsys):
    base, path = traj
    assert cadra2_main(["motion", str(path), str(path), "-o", str(base / "x"), "--spin", "1",
                        "--spin", "2", "--spin", "3"]) == 1
    assert "--spin: give one value for every shot" in capsys.readouterr().err
    assert not (base / "x").exists()


def test_help_shows_every_default_and_verbosity_on_both_sides(capsys, tmp_path):
    """``cadra2 motion --help`` shows every option's default, and -q is taken before the
    subcommand as after it (the trajectory here does not exist: refused, status 1, not a
    usage error)."""
    with pytest.raises(SystemExit) as exc:
        cadra2_main(["motion", "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    assert "``" not in text and "Kryloff-Bogoliuboff" in text
    options = text.split("options:", 1)[1]
    for opt in ("--variable", "--spin", "--offset", "--nonrolling", "--path-degree",
                "--window", "--step", "--overwrite"):
        entry = options.split(f"\n  {opt}", 1)[1].split("\n  -", 1)[0]
        assert "(default" in " ".join(entry.split()), opt
    missing = str(tmp_path / "t.csv")
    for argv in (["-q", "motion", missing, "-o", str(tmp_path / "o")],
                 ["motion", missing, "-o", str(tmp_path / "o"), "-q"]):
        assert cadra2_main(argv) == 1



def test_a_long_record_gets_sectional_fits_and_the_kb_reduction(traj, tmp_path):
    """A dense record (300 points, ~17 cycles) of a linear epicycle with the cone's
    coefficients and no lift (the cg on a ballistic parabola): the K-B reduction's constant
    terms are the coefficients, its quadratic terms zero, within 3 sigma."""
    shot = load_shots([str(traj[1])])[0][0]
    r = shot.rigid
    V, Cma, Cmq = 800.0, -0.49, -4.0
    q, S, d, I = 0.5 * r.density_kg_m3 * V**2, r.area_m2, r.d_m, r.inertia_body_kg_m2[1, 1]
    M, D = Cma * q * S * d / I, Cmq * q * S * d * d / (2 * V * I)
    roots = np.roots([1.0, -D, -M])
    n = 300
    t = np.linspace(0.0, 0.24, n)
    xi = 0.05 * np.exp(roots[0] * t) + 0.03j * np.exp(roots[1] * t)
    rng = np.random.default_rng(5)
    sig = math.radians(0.01)
    g = r.gravity_m_s2
    cg = np.column_stack([V * t, np.zeros(n), -0.5 * g * t * t])
    theta = xi.imag + np.arctan(-g * t / V) + rng.normal(0, sig, n)   # + the path's dip
    psi = xi.real + rng.normal(0, sig, n)
    axis = np.column_stack([np.sqrt(1 - np.sin(theta)**2 - np.sin(psi)**2), np.sin(psi),
                            np.sin(theta)])
    ref = cg - r.cg_from_ref_body_m[0] * axis + rng.normal(0, 1e-5, (n, 3))
    meas = np.column_stack([ref, theta, psi])
    sigma = np.column_stack([np.full((n, 3), 1e-5), np.full((n, 2), sig)])
    dense = replace(shot, stations=np.arange(1, n + 1), t_s=t, meas=meas, sigma=sigma)
    res = analyse_shot(dense, variable="time")
    assert res.sections is not None and res.kb is not None and res.kb_lift_corrected
    kb = res.kb
    assert abs(_pull(kb.Cm_alpha0, kb.Cm_alpha0_sigma, Cma)) < 3
    assert abs(_pull(kb.Cm_alpha2, kb.Cm_alpha2_sigma, 0.0)) < 3
    assert abs(_pull(kb.Cmq_sum0, kb.Cmq_sum0_sigma, Cmq)) < 3
    assert abs(_pull(kb.Cmq_sum2, kb.Cmq_sum2_sigma, 0.0)) < 3
    assert res.fit.chi2_dof < 2 and abs(_pull(res.coefficients.C_L_alpha,
                                              res.coefficients.C_L_alpha_sigma, 0.0)) < 3
    files = write_outputs([res], tmp_path / "out")
    assert "sectional.png" in files and (tmp_path / "out" / "sectional.png").is_file()
    table = pd.read_csv(tmp_path / "out" / "coefficients.csv")
    assert list(table["method"]) == ["linear theory (time)", "Kryloff-Bogoliuboff (time)"]


def test_constant_angles_hold_no_motion_to_reduce(tmp_path, capsys):
    """The angles held at their mean (noise alone): refused in one line, where coefficients
    with tiny sigmas came out of the noise."""
    t = pd.read_csv(SAMPLE / "truth.csv")
    rng = np.random.default_rng(3)
    n = len(t)
    table = pd.DataFrame({
        "station": t["station"].to_numpy(), "t_s": t["t_s"].to_numpy(), "status": "ok",
        **{f"{c}_m": t[f"{c}_m"] + rng.normal(0, SIGMA_POS, n) for c in "xyz"},
        **{f"{c}_deg": t[f"{c}_deg"].mean() + rng.normal(0, SIGMA_DEG, n)
           for c in ("theta", "psi")},
        **{f"sigma_{c}_m": SIGMA_POS for c in "xyz"},
        **{f"sigma_{c}_deg": SIGMA_DEG for c in ("theta", "psi")},
        "x_top_minus_side_m": 0.0, "x_consistency": 0.0, "reason": "", "warnings": ""})
    path = tmp_path / "flat.csv"
    write_trajectory(path, table.loc[:, list(COLUMNS)],
                     {"shot_id": "CONE-1", "shot_file": str(SAMPLE / "shot.toml")})
    out = tmp_path / "out"
    assert cadra2_main(["motion", str(path), "-o", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "no angular motion above the noise" in err, err
    assert not out.exists()
