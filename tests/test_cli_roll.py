"""``cadra2 roll``: seed 003's segmented fit of a pure-roll record given as files.

Truth: the coefficients (seed 003 Table 2, the bundled ``seed003_romof``) that flew the
record on CADRA's roll bearing; the steady spin the paper derives from them (+0.0280).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cadra.aero import resolve_model
from cadra.cli.cadra2 import main
from cadra.dynamics.modes import TestMode
from cadra.dynamics.observe import observe
from cadra.dynamics.setup import propagate_states
from cadra.dynamics.trajectory import Launch
from cadra.flight.data import rigid_body_from_shot
from cadra.io.shotfile import MassProperties, ShotFile, StationRecord, save_shot
from cadra.io.trajectory import COLUMNS, write_trajectory
from cadra.validation import seed003_runs as case

R_AIR, T_K = 287.05, 288.15


def _files(tmp_path: Path, *, axis: bool = True, duration_s: float = 11.0):
    """Run 1 of the seed 003 case as a shot file (roll bearing, frames as stations) and a
    trajectory file measuring phi (0.25 deg) and, with ``axis``, theta and psi."""
    from cadra.body.finner import finner_mass_properties, finner_preset

    fb = finner_preset("basic_finner", d_m=case.D_M)
    mp = finner_mass_properties(fb, case.ALUMINIUM)
    rho = 2.0 * case.Q_INF / case.V_STREAM**2
    t = np.arange(int(round(duration_s * case.FPS)) + 1) / case.FPS
    shot = ShotFile(
        shot_id="ROLL-1", model={"kind": "finner", "preset": "basic_finner",
                                 "d_cm": case.D_M * 100},
        mass=MassProperties(mp.mass_kg, np.array([mp.cg_s_m, 0.0, 0.0]), mp.inertia_kg_m2),
        pressure_pa=rho * R_AIR * T_K, temperature_k=T_K, facility="hffaf",
        stations=tuple(StationRecord(i + 1, float(tk)) for i, tk in enumerate(t)),
        test_mode=TestMode(kind="roll_bearing", stream_m_s=case.V_STREAM))
    save_shot(shot, tmp_path / "shot.toml")
    body = rigid_body_from_shot(shot)
    model = resolve_model("seed003_romof")
    y0 = Launch(speed_m_s=0.0, theta_rad=case.ALPHA, roll_rad=math.radians(41.16)).state(body)
    states = propagate_states(y0, 0.0, t, body.phys(), model.compile(), model.values(),
                              dt_max=5e-4)
    obs = observe(states, body.ref_from_cg_body_m())
    rng = np.random.default_rng(5)
    n, s = t.size, case.SIGMA_DEG
    table = pd.DataFrame({
        "station": np.arange(1, n + 1), "t_s": t, "status": "ok",
        "x_m": np.nan, "y_m": np.nan, "z_m": np.nan,
        "theta_deg": np.degrees(obs["theta_rad"]) + rng.normal(0, 0.05, n) if axis else np.nan,
        "psi_deg": np.degrees(obs["psi_rad"]) + rng.normal(0, 0.05, n) if axis else np.nan,
        "phi_deg": np.mod(np.degrees(obs["phi_rad"]) + rng.normal(0, s, n), 360.0),
        "sigma_x_m": np.nan, "sigma_y_m": np.nan, "sigma_z_m": np.nan,
        "sigma_theta_deg": 0.05 if axis else np.nan, "sigma_psi_deg": 0.05 if axis else np.nan,
        "sigma_phi_deg": s, "x_top_minus_side_m": np.nan, "x_consistency": np.nan,
        "reason": "", "warnings": ""})
    traj = tmp_path / "trajectory.csv"
    write_trajectory(traj, table.loc[:, [*COLUMNS, "phi_deg", "sigma_phi_deg"]],
                     {"shot_id": "ROLL-1", "shot_file": str(tmp_path / "shot.toml")})
    return traj, model


def test_cadra2_roll_fits_a_roll_record_from_files(tmp_path, capsys):
    traj, model = _files(tmp_path)
    out = tmp_path / "roll"
    assert main(["roll", str(traj), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "roll: 1 record(s)" in text and "converged" in text
    for name in ("report.md", "roll_fit.png", "table2.csv", "table3.csv", "segments.csv",
                 "steady_spins.csv", "paper_table3.md"):
        assert (out / name).is_file(), name
    tab = pd.read_csv(out / "table2.csv", index_col=0)
    assert len(tab) == 14
    truth = pd.Series({n: model.parameter(n).value for n in tab.index})
    pulls = (tab["value"] - truth) / tab["sigma"]
    assert np.all(np.abs(pulls) < 4), pulls.round(2).to_dict()
    spins = pd.read_csv(out / "steady_spins.csv", index_col=0)
    stable = spins[spins["stable"]]
    near = stable.iloc[np.argmin(np.abs(stable["p_hat"] - 0.0280))]
    assert near["p_hat"] == pytest.approx(0.0280, abs=max(3 * near["sigma"], 0.001))
    assert "57.0" in (out / "report.md").read_text()[:400]     # the bearing's angle of attack


def test_cadra2_roll_refusals(tmp_path, capsys):
    traj, _ = _files(tmp_path, axis=False, duration_s=2.0)
    assert main(["roll", str(traj), "-o", str(tmp_path / "a")]) == 1
    assert "give --alpha-deg" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:       # a usage error, before anything is read
        main(["roll", str(traj), "-o", str(tmp_path / "b"), "--alpha-deg", "95"])
    assert exc.value.code == 2
    assert "argument --alpha-deg: must be a finite number >= -90 and <= 90" in \
        capsys.readouterr().err
    assert main(["roll", str(traj), "-o", str(tmp_path / "c"), "--window", "4"]) == 1
    assert "--window" in capsys.readouterr().err
    assert not any((tmp_path / d).exists() for d in "abc")


def test_a_constant_roll_angle_holds_nothing_to_fit(tmp_path, capsys):
    """The roll held at one angle (noise alone): refused in one line, where it printed
    "converged" with a steady spin of -5e16 and infinite sigmas."""
    traj, _ = _files(tmp_path, duration_s=2.0)
    text = traj.read_text().splitlines()
    head = [line for line in text if line.startswith("#")]
    table = pd.read_csv(traj, comment="#")
    rng = np.random.default_rng(9)
    table["phi_deg"] = 41.16 + rng.normal(0, case.SIGMA_DEG, len(table))
    traj.write_text("\n".join(head) + "\n" + table.to_csv(index=False))
    assert main(["roll", str(traj), "-o", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "no roll motion above the noise" in err, err
    assert not (tmp_path / "out").exists()


def test_each_frame_keeps_its_own_roll_sigma(tmp_path):
    """A record whose frames carry different sigmas (a blurred stretch): each frame is
    weighted by its own, where the record's median replaced them all without a word."""
    from cadra import channels
    from cadra.flight.load import load_shots
    from cadra.studies.segmented_roll import choose_segments, records_of, segment_shots

    traj, _ = _files(tmp_path, duration_s=2.0)
    head = [line for line in traj.read_text().splitlines() if line.startswith("#")]
    table = pd.read_csv(traj, comment="#")
    sig = np.where(np.arange(len(table)) < len(table) // 2, 0.25, 1.0)
    table["sigma_phi_deg"] = sig
    traj.write_text("\n".join(head) + "\n" + table.to_csv(index=False))
    shots, _ = load_shots([traj])
    (record,) = records_of(shots)
    np.testing.assert_allclose(np.degrees(record.sigmas), sig)
    seg = choose_segments(record)[0]
    (data,) = segment_shots(record, [seg], shots[0].rigid)
    k = channels.NAMES.index("phi")
    np.testing.assert_allclose(np.degrees(data.sigma[:, k]), sig[seg.start:seg.stop])


def test_a_roll_fit_far_above_the_noise_is_warned_about(tmp_path, capsys):
    """Sigmas written 5x too small: chi^2/nu ~25, p(chi^2) ~ 0: a poor minimum as cadra2 fit
    says it (its worst channel and station), exit status 1."""
    traj, _ = _files(tmp_path, duration_s=1.5)
    head = [line for line in traj.read_text().splitlines() if line.startswith("#")]
    table = pd.read_csv(traj, comment="#")
    table["sigma_phi_deg"] = table["sigma_phi_deg"] / 5.0
    traj.write_text("\n".join(head) + "\n" + table.to_csv(index=False))
    assert main(["roll", str(traj), "-o", str(tmp_path / "out"), "-q"]) == 1
    err = capsys.readouterr().err
    assert "CONVERGED TO A POOR MINIMUM" in err and "channel phi carries" in err, err


def test_a_relative_shot_file_is_found_beside_the_trajectory(tmp_path, monkeypatch):
    """``# shot_file: shot.toml`` in a trajectory file carried with its shot file: read from
    the trajectory's folder, whatever the working folder."""
    from cadra.flight.load import trajectory_and_shot

    traj, _ = _files(tmp_path, duration_s=1.0)
    text = traj.read_text().replace(f"# shot_file: {tmp_path / 'shot.toml'}",
                                    "# shot_file: shot.toml")
    traj.write_text(text)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    assert trajectory_and_shot(traj)[1] == tmp_path / "shot.toml"


def test_lost_frames_split_the_record_and_say_so(tmp_path):
    """16 frames lost mid-spin (the roll across them unknown, more than pi at this rate):
    the record is split at the gap into two pieces, each unwrapped alone, and the note says
    where, instead of an unwrap across the gap that broke the fit."""
    from cadra.flight.load import load_shots
    from cadra.studies.segmented_roll import records_of

    traj, _ = _files(tmp_path, duration_s=4.0)
    head = [line for line in traj.read_text().splitlines() if line.startswith("#")]
    table = pd.read_csv(traj, comment="#")
    n = len(table)
    lost = table.index[(table.index >= n // 2) & (table.index < n // 2 + 16)]
    table.loc[lost, ["phi_deg", "sigma_phi_deg"]] = np.nan
    traj.write_text("\n".join(head) + "\n" + table.to_csv(index=False))
    shots, _ = load_shots([traj])
    records = records_of(shots)
    assert [r.name for r in records] == ["ROLL-1.1", "ROLL-1.2"]
    assert "16 frame(s) lost at t = " in records[0].note and "split there" in records[0].note
    assert sum(len(r.t_s) for r in records) == n - 16
    for r in records:     # each piece continuous: consecutive frames turn by less than pi
        assert np.all(np.abs(np.diff(r.phi_rad)) < np.pi)


def test_a_free_flight_shot_is_not_a_roll_bearing(tmp_path, capsys):
    """A shot file without [test_mode]: refused as not a roll bearing, not with a message
    about measured positions."""
    traj, _ = _files(tmp_path, duration_s=1.0)
    shot = tmp_path / "shot.toml"
    text = shot.read_text()
    start = text.index("[test_mode]")
    end = text.find("\n[", start + 1)
    shot.write_text(text[:start] + (text[end + 1:] if end > 0 else ""))
    assert main(["roll", str(traj), "-o", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip()
    assert "a free flight, not a roll bearing" in err and "position" not in err, err


def test_a_shot_file_found_nowhere_is_named_once_with_where_it_was_looked_for(tmp_path,
                                                                            capsys):
    traj, _ = _files(tmp_path, duration_s=1.0)
    traj.write_text(traj.read_text().replace(f"# shot_file: {tmp_path / 'shot.toml'}",
                                             "# shot_file: gone.toml"))
    assert main(["roll", str(traj), "-o", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("gone.toml") == 2 and str(tmp_path / "gone.toml") in err, err
    assert "pass it with --shot" in err
