"""The station history under concurrency and failure (docs/calibration.md, "Station history":
locking, order, failed appends).

Truth is counted, not computed by the code under test: N processes released together append N
estimates; the file must then hold N verified entries, in time order, and entry k must have
been compared with exactly the k - 1 entries before it. A full disk is simulated by a write
that stores half its bytes and raises ENOSPC; the history must be byte-for-byte unchanged.
"""

from __future__ import annotations

import errno
import multiprocessing as mp
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cadra.calibration import history as hist
from cadra.calibration.history import (
    BiasTable,
    append_compared,
    history_path,
    load_history,
)

FAC = "hffaf"
N = 16
N_PROC = 8
SPECS = Path(__file__).resolve().parents[1] / "sample_shots" / "specs"


def make_table(seed: int, created: str = "2026-11-22T21:30:00Z") -> BiasTable:
    rng = np.random.default_rng(seed)
    sigma = np.tile([2e-4, 1e-4, 1e-4, 5e-8], (N, 1)) * rng.uniform(0.8, 1.2, (N, 4))
    bias = rng.normal(0.0, 1.0, (N, 4)) * sigma
    return BiasTable(facility=FAC, created_utc=created, stations=np.arange(1, N + 1),
                     bias=bias, sigma=sigma, shots=(f"sphere_{seed}",), method="test")


def _worker(root: str, seed: int, barrier, results) -> None:
    """One concurrent append: wait for all, then append-with-compare; report what it saw."""
    table = make_table(seed)
    barrier.wait(timeout=60)
    rec = append_compared(table, root)
    results.put((seed, len(rec.history), rec.table.created_utc,
                 rec.comparison.attrs["previous_created_utc"], rec.entry))


def test_concurrent_appends_each_compare_with_the_history_they_locked(tmp_path):
    ctx = mp.get_context("spawn")
    barrier = ctx.Barrier(N_PROC)
    results = ctx.Queue()
    procs = [ctx.Process(target=_worker, args=(str(tmp_path), k, barrier, results))
             for k in range(N_PROC)]
    for p in procs:
        p.start()
    got = [results.get(timeout=120) for _ in range(N_PROC)]
    for p in procs:
        p.join(timeout=60)
        assert p.exitcode == 0
    entries, warnings = load_history(tmp_path, FAC)
    assert warnings == []
    assert len(entries) == N_PROC
    # every process's estimate is there once, in file order = time order
    assert sorted(e.shots[0] for e in entries) == sorted(f"sphere_{k}" for k in range(N_PROC))
    times = [e.created_utc for e in entries]
    assert times == sorted(times) and len(set(times)) == N_PROC
    # entry k (1-based) saw exactly the k - 1 entries before it, and compared with entry k - 1
    assert {n for _, n, _, _, _ in got} == set(range(N_PROC))
    for seed, n_seen, created, previous, entry in got:
        assert entry == n_seen + 1
        assert entries[n_seen].created_utc == created
        assert entries[n_seen].shots == (f"sphere_{seed}",)
        assert previous == (entries[n_seen - 1].created_utc if n_seen else None)


def test_timestamp_is_taken_under_the_lock_and_never_older(tmp_path):
    """A table made before the latest entry (a slow run, a clock stepped back) is stamped
    after it, never refused as older."""
    future = "2099-01-01T00:00:00.000000Z"
    hist.append_entry(make_table(1, created=future), tmp_path)
    rec = append_compared(make_table(2, created="2026-01-01T00:00:00Z"), tmp_path)
    assert rec.table.created_utc == "2099-01-01T00:00:00.000001Z"
    assert len(rec.history) == 1 and rec.entry == 2
    entries, _ = load_history(tmp_path, FAC)
    assert [e.created_utc for e in entries] == [future, rec.table.created_utc]


def _full_disk(monkeypatch):
    """Every history write stores half its bytes, then fails as a full disk does."""
    def write_half_then_enospc(fd, data):
        os.write(fd, data[: len(data) // 2])
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(hist, "_write_all", write_half_then_enospc)


def test_full_disk_leaves_the_history_as_it_was(tmp_path, monkeypatch):
    append_compared(make_table(1), tmp_path)
    path = history_path(tmp_path, FAC)
    before = path.read_bytes()
    _full_disk(monkeypatch)
    with pytest.raises(OSError) as info:
        append_compared(make_table(2), tmp_path)
    assert info.value.errno == errno.ENOSPC
    assert path.read_bytes() == before
    monkeypatch.undo()
    rec = append_compared(make_table(3), tmp_path)   # and the next append is clean
    assert rec.entry == 2 and load_history(tmp_path, FAC)[1] == []


def test_failed_first_append_leaves_no_file_and_a_held_lock_times_out(tmp_path, monkeypatch):
    from filelock import FileLock

    path = history_path(tmp_path, FAC)
    _full_disk(monkeypatch)
    with pytest.raises(OSError):
        append_compared(make_table(1), tmp_path)
    assert not path.exists()
    monkeypatch.undo()
    append_compared(make_table(2), tmp_path)
    before = path.read_bytes()
    with FileLock(f"{path}.lock"), pytest.raises(TimeoutError, match="lock"):
        append_compared(make_table(3), tmp_path, timeout_s=0.2)
    assert path.read_bytes() == before


# --------------------------------------------------------------------------- cadra2 calibrate


def _sphere_trajectories(base: Path) -> list[str]:
    """Three sphere shots' trajectory files (simulator truth + seeded noise, one biased
    station), as tests/test_cadra2_cli.py makes them."""
    from cadra.io.trajectory import COLUMNS, write_trajectory
    from cadra.synthetic.simulate import load_shot_spec, simulate_shot, write_shot

    rng = np.random.default_rng(9)
    sp = 2.5e-7
    out = []
    for k in (1, 2, 3):
        sim = simulate_shot(load_shot_spec(SPECS / f"sphere_{k}.toml"))
        d = write_shot(sim, base / f"sphere_{k}", images=False, progress=False)
        t = sim.truth
        n = len(t)
        y_bias = np.where(t["station"].to_numpy() == 5, 6e-4, 0.0)
        table = pd.DataFrame({
            "station": t["station"].to_numpy(), "t_s": t["t_s"].to_numpy(), "status": "ok",
            "x_m": t["x_m"] + rng.normal(0, sp, n),
            "y_m": t["y_m"] + y_bias + rng.normal(0, sp, n),
            "z_m": t["z_m"] + rng.normal(0, sp, n), "theta_deg": np.nan, "psi_deg": np.nan,
            "sigma_x_m": sp, "sigma_y_m": sp, "sigma_z_m": sp, "sigma_theta_deg": np.nan,
            "sigma_psi_deg": np.nan, "x_top_minus_side_m": 0.0, "x_consistency": 0.0,
            "reason": "", "warnings": ""})
        path = base / f"sphere_{k}.csv"
        write_trajectory(path, table.loc[:, list(COLUMNS)],
                         {"shot_id": sim.spec.shot_id, "shot_file": str(d / "shot.toml")})
        out.append(str(path))
    return out


@pytest.fixture(scope="module")
def sphere_trajs(tmp_path_factory):
    return _sphere_trajectories(tmp_path_factory.mktemp("spheres"))


@pytest.mark.slow
def test_concurrent_cadra2_calibrate(sphere_trajs, tmp_path):
    """8 real ``cadra2 calibrate`` processes started at once on one history: 8 entries, every
    run exits 0, and run k's report compares with the k - 1 entries it locked. Slow: ~50 s on
    two busy cores (8 interpreters, 8 joint sphere fits); before the change 2 of the 8 runs
    crashed ("older than the latest entry"), 6 entries were kept, all 8 reports compared with
    "0 earlier entries" and said "appended"."""
    root = tmp_path / "root"
    env = {**os.environ, "PYTHONWARNINGS": "error"}
    procs = [subprocess.Popen([sys.executable, "-m", "cadra.cli.cadra2", "calibrate",
                               *sphere_trajs, "-o", str(tmp_path / f"cal{k}"),
                               "--stations-root", str(root)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              env=env)
             for k in range(N_PROC)]
    outs = [p.communicate(timeout=300) for p in procs]
    for p, (_, err) in zip(procs, outs, strict=True):
        assert p.returncode == 0, err
        assert "Traceback" not in err
    entries, warnings = load_history(root, FAC)
    assert warnings == [] and len(entries) == N_PROC
    seen = set()
    for k in range(N_PROC):
        report = (tmp_path / f"cal{k}" / "report.md").read_text()
        n_seen = int(report.split("Comparison with the station history (")[1].split(" ")[0])
        seen.add(n_seen)
        head = (tmp_path / f"cal{k}" / "bias_table.csv").read_text().splitlines()[2]
        assert head.startswith("# created_utc: ")
        assert entries[n_seen].created_utc == head.split(": ", 1)[1]
        assert f"Station history: recorded in {history_path(root, FAC)} as entry {n_seen + 1}" \
            in report
    assert seen == set(range(N_PROC))


def test_cadra2_calibrate_full_disk_says_so(sphere_trajs, tmp_path, monkeypatch, capsys):
    """A full disk during the append: exit 3, one line on stderr (no traceback), the history
    byte-for-byte as it was, and a report that says plainly the estimate was not recorded."""
    from cadra.cli.cadra2 import main

    root = tmp_path / "root"
    assert main(["calibrate", *sphere_trajs, "-o", str(tmp_path / "ok"), "--stations-root",
                 str(root)]) == 0
    path = history_path(root, FAC)
    before = path.read_bytes()
    capsys.readouterr()
    _full_disk(monkeypatch)
    out = tmp_path / "full"
    assert main(["calibrate", *sphere_trajs, "-o", str(out), "--stations-root",
                 str(root)]) == 3
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "NOT recorded in the station history" in err and "No space left on device" in err
    assert path.read_bytes() == before
    report = (out / "report.md").read_text()
    assert "**Station history: NOT recorded.**" in report
    assert "No space left on device" in report and "recorded in" not in report.replace(
        "NOT recorded", "")
    assert "Comparison with the station history (1 earlier" in report


def test_history_location_never_the_working_folder_by_default(sphere_trajs, tmp_path,
                                                              monkeypatch):
    from cadra.calibration.history import STATIONS_ROOT_ENV, stations_root
    from cadra.cli.cadra2 import main
    from cadra.facility.reference import REPO_ROOT

    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    monkeypatch.delenv(STATIONS_ROOT_ENV, raising=False)
    assert stations_root() == REPO_ROOT and (REPO_ROOT / "facilities").is_dir()
    assert stations_root(".") == Path(".")          # the working folder only when asked
    env_root = tmp_path / "env_root"
    monkeypatch.setenv(STATIONS_ROOT_ENV, str(env_root))
    assert stations_root() == env_root
    assert main(["calibrate", *sphere_trajs, "-o", str(tmp_path / "cal")]) == 0
    assert len(load_history(env_root, FAC)[0]) == 1
    assert not (work / "stations").exists()
    # an installed package (no facilities/ beside it) and no setting: refused, naming both ways
    monkeypatch.delenv(STATIONS_ROOT_ENV)
    monkeypatch.setattr(hist, "REPO_ROOT", tmp_path / "site-packages")
    with pytest.raises(hist.StationHistoryError, match="--stations-root or CADRA_STATIONS"):
        stations_root()
