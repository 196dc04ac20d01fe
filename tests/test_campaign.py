"""Campaigns (cadra/campaign, docs/campaign.md): the manifest, the content keys, a real run on
a local Dask cluster and on a real ``dask scheduler`` / ``dask worker`` pair, resuming, a
failed shot, the database, status and export, and the report page in a real browser.

The campaign here is small and fast: three sphere shots of four stations flown and rendered
in memory (one with an impossible launch, so its stage one fails), fitted as one group with
the bundled sphere model, and one calibration sphere that cannot fly either (so the
calibration fails and the fits go on uncorrected, saying so); the truth is the sphere model's
own values.
"""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cadra.aero import load_bundled_model
from cadra.campaign import (
    ManifestError,
    campaign_status,
    load_manifest,
    query,
    read_tables,
    run_campaign,
)
from cadra.campaign.database import CampaignDB
from cadra.campaign.plan import file_sha256, plan
from cadra.cli.campaign import main as cadra

ROOT = Path(__file__).resolve().parents[1]

SPHERE = ('model = {{ kind = "sphere", d_cm = 2.0 }}, aero_model = "sphere", aim = "centre", '
          'seed = {seed}, n_stations = 4, mass = {{ mass_g = 32.882, x_cg_from_ref_cm = 0.0, '
          'inertia_g_cm2 = [13.153, 13.153, 13.153] }}, range = {{ pressure_torr = 760.0, '
          'temperature_k = 295.0 }}, launch = {{ x_m = -0.5, speed_m_s = {speed}, '
          'q_deg_s = 500.0 }}')


#: the group's bootstrap refits (its tasks run on the campaign's own workers)
BOOTSTRAP = 6


def manifest_text(speeds=(450.0, 700.0, -5.0), seeds=(11, 12, 13)) -> str:
    shots = "".join(f'[[shots]]\nid = "S-{k + 1}"\nspec = {{ {SPHERE.format(seed=s, speed=v)} }}\n'
                    for k, (v, s) in enumerate(zip(speeds, seeds, strict=True)))
    # a calibration sphere that cannot fly: the calibration fails, the fits go on uncorrected
    bad = SPHERE.format(seed=5, speed=-1)
    shots += f'[[shots]]\nid = "C-1"\nrole = "sphere"\nspec = {{ {bad} }}\n'

    return (f'name = "spheres"\n{shots}\n[[groups]]\nname = "all spheres"\nmodel = "sphere"\n'
            f'shots = ["S-1", "S-2", "S-3"]\nbootstrap = {BOOTSTRAP}\n')


def write_manifest(folder: Path, **kw) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "campaign.toml"
    path.write_text(manifest_text(**kw), encoding="utf-8")
    return path


# -- the manifest and the keys (no computing) ---------------------------------------------------


@pytest.mark.parametrize("text, key", [
    ('name = "x"\n', "shots"),
    ('[[shots]]\nid = "a"\n', "shots[0]"),
    ('[[shots]]\nspec = "nowhere.toml"\n', "shots[0].spec"),
    ('[[shots]]\nspec = "s.toml"\nshot = "s.toml"\n', "shots[0]"),
    ('[[shots]]\nspec = "s.toml"\nrole = "target"\n', "shots[0].role"),
    ('[[shots]]\nspec = "s.toml"\n[[shots]]\nspec = "s.toml"\n', "shots"),
    ('[[shots]]\nspec = "s.toml"\n[[groups]]\nname = "g"\nmodel = "sphere"\nshots = ["b"]\n',
     "groups[0].shots"),
    ('[[shots]]\nspec = "s.toml"\n[settings]\nformation = "film"\n', "settings.formation"),
    ('[[shots]]\nspec = "s.toml"\nid = "S"\n[[groups]]\nname = "g"\nmodel = "sphere"\n'
     'shots = ["S"]\nbootstrap = 1\n', "groups[0].bootstrap"),
    ('[[shots]]\nspec = "s.toml"\nid = "S"\n[[groups]]\nname = "g"\nmodel = "sphere"\n'
     'shots = ["S"]\nbootstrap = 10\nbootstrap_noise = "pink"\n', "groups[0].bootstrap_noise"),
    ('[[shots]]\nspec = "s.toml"\nrole = "sphere"\n[[groups]]\nname = "g"\nmodel = "sphere"\n'
     'shots = ["S"]\n', "groups"),
])
def test_a_bad_manifest_is_refused_naming_the_key(tmp_path, text, key):
    (tmp_path / "s.toml").write_text('shot_id = "S"\n', encoding="utf-8")
    path = tmp_path / "m.toml"
    path.write_text(text, encoding="utf-8")
    pattern = key.replace("[", ".").replace("]", ".")
    with pytest.raises(ManifestError, match=rf"{path}: .*{pattern}"):
        load_manifest(path)


def _keys(path: Path) -> dict[str, str]:
    return {t.id: t.key for t in plan(load_manifest(path))}


def test_a_changed_shot_changes_the_keys_of_exactly_what_depends_on_it(tmp_path):
    base = _keys(write_manifest(tmp_path / "a"))
    changed = _keys(write_manifest(tmp_path / "b", seeds=(11, 99, 13)))
    assert set(base) == set(changed) == {
        "stage1:S-1", "stage1:S-2", "stage1:S-3", "stage1:C-1", "calibrate:spheres",
        "single:S-1", "single:S-2", "single:S-3", "multifit:all spheres",
        "diagnose:all spheres", "bootstrap:all spheres"}
    assert {k for k in base if base[k] != changed[k]} == {
        "stage1:S-2", "single:S-2", "multifit:all spheres", "diagnose:all spheres",
        "bootstrap:all spheres"}
    # the manifest's folder or file name is not content: a copy elsewhere has the same keys
    assert _keys(write_manifest(tmp_path / "c" / "d")) == base


def test_a_fit_setting_changes_the_fits_keys_not_stage_ones(tmp_path):
    base = _keys(write_manifest(tmp_path / "a"))
    path = write_manifest(tmp_path / "b")
    path.write_text(path.read_text() + "[settings]\nmax_iterations = 20\n", encoding="utf-8")
    changed = _keys(path)
    assert {k for k in base if base[k] != changed[k]} == {
        k for k in base if not k.startswith(("stage1", "calibrate"))}


def test_file_hashes_are_cached_until_the_file_changes(tmp_path):
    db = CampaignDB(tmp_path)
    calls = []
    hasher = db.hasher(lambda p: calls.append(p) or file_sha256(p))
    f = tmp_path / "image.bin"
    f.write_bytes(b"a" * 1000)
    first = hasher(f)
    assert hasher(f) == first and len(calls) == 1
    f.write_bytes(b"b" * 1001)
    assert hasher(f) != first and len(calls) == 2
    db.close()


def test_a_query_spans_campaigns(tmp_path):
    for name, value in (("c1", 0.97), ("c2", 0.95)):
        (tmp_path / name).mkdir()
        db = CampaignDB(tmp_path / name)
        db.replace("coefficients", {"scope": "group"},
                   [{"scope": "group", "name": "g", "parameter": "CD_A1", "value": value,
                     "sigma": 0.01, "vary": 1, "mach": 0.7}], "k")
        db.close()
    got = query("SELECT campaign, value FROM coefficients WHERE parameter = 'CD_A1' "
                "ORDER BY campaign", [tmp_path / "c1", tmp_path / "c2"])
    assert got.to_dict("records") == [{"campaign": "c1", "value": 0.97},
                                      {"campaign": "c2", "value": 0.95}]


# -- a real run -------------------------------------------------------------------------------


@pytest.fixture(scope="session")
def campaign(tmp_path_factory):
    """The small campaign run once on a local cluster of two worker processes, shared by
    pytest-xdist's workers (the first to come runs it under a file lock, the others read its
    folder: pytest-xdist's documented recipe). Tests that change it work on a copy."""
    import pickle

    from filelock import FileLock

    root = tmp_path_factory.getbasetemp().parent / "campaign"
    root.mkdir(exist_ok=True)
    manifest, out, done = root / "manifest" / "campaign.toml", root / "out", root / "summary"
    with FileLock(str(root / "run.lock")):
        if not done.exists():
            write_manifest(manifest.parent)
            summary = run_campaign(manifest, out, workers=2, progress=False)
            done.write_bytes(pickle.dumps(summary))
    return manifest, out, pickle.loads(done.read_bytes())


def test_every_task_runs_and_the_failed_shot_is_isolated(campaign):
    _, out, summary = campaign
    assert summary.tasks == 11 and summary.ran == 11 and summary.reused == 0
    assert sorted(summary.failed) == ["calibrate:spheres", "single:S-3", "stage1:C-1",
                                      "stage1:S-3"]
    t = read_tables(out)
    shots = t["shots"].set_index("shot_id")
    assert list(shots.loc[["S-1", "S-2"], "status"]) == ["done", "done"]
    assert shots.loc["S-3", "status"] == "failed"
    assert "speed_m_s" in shots.loc["S-3", "error"]           # the reason, from the spec check
    link = shots.loc["S-1", "fit_report"]                      # the group fit it is in
    assert link.startswith("groups/all_spheres/multifit-") and (out / link).is_file()
    fit = t["fits"].set_index(["scope", "name"]).loc[("group", "all spheres")]
    assert fit["converged"] == 1 and fit["n_shots"] == 2 and fit["shots"] == "S-1,S-2"
    assert fit["note"].startswith("ran on 2 of 3 shots: S-3 failed")
    uncorrected = "not corrected for station biases: the sphere calibration failed (no sphere"
    assert uncorrected in fit["note"]
    singles = t["fits"][t["fits"]["scope"] == "single"].set_index("name")
    assert singles.loc["S-1", "note"].startswith(uncorrected)
    tasks = t["tasks"].set_index("name")
    assert set(t["tasks"]["status"]) == {"done", "failed"}
    assert tasks.loc["all spheres"]["worker"].str.startswith("tcp://").all()


def test_the_groups_bootstrap_ran_on_the_workers_and_agrees_with_its_covariance(campaign):
    _, out, _ = campaign
    t = read_tables(out)
    boot = t["bootstrap"].set_index("parameter")
    coef = t["coefficients"]
    group = coef[(coef["scope"] == "group") & (coef["vary"] == 1)].set_index("parameter")
    assert set(boot.index) == set(group.index)
    assert (boot["n"] == BOOTSTRAP).all() and (boot["noise"] == "white").all()
    np.testing.assert_array_equal(boot.loc[group.index, "sigma_cov"], group["sigma"])
    # six refits: a std scatters by ~30 %; far outside that would be a wrong replicate
    assert boot["ratio"].between(0.3, 2.0).all(), boot["ratio"]
    assert boot["non_gaussian"].isna().all()           # too few refits to judge
    folder = next((out / "groups" / "all_spheres").glob("bootstrap-*"))
    assert {"report.md", "bootstrap.csv", "bootstrap_samples.csv", "bootstrap.png"} <= {
        p.name for p in folder.iterdir()}


def test_the_group_recovers_the_truth_it_was_flown_with(campaign):
    _, out, _ = campaign
    truth = load_bundled_model("sphere")
    coef = read_tables(out)["coefficients"]
    group = coef[(coef["scope"] == "group") & (coef["vary"] == 1)]
    assert set(group["parameter"]) == set(truth.free_names())
    for r in group.itertuples():
        assert abs(r.value - truth.parameter(r.parameter).value) < 3 * r.sigma, r
    single = coef[coef["scope"] == "single"]
    assert set(single["name"]) == {"S-1", "S-2"}
    for r in group.itertuples():                              # two shots know more than one
        assert r.sigma < single.loc[single["parameter"] == r.parameter, "sigma"].min()


def test_a_rerun_does_nothing_and_a_changed_shot_reruns_only_its_tasks(campaign, tmp_path):
    manifest, out, _ = campaign
    copy = tmp_path / "out"
    shutil.copytree(out, copy)
    again = run_campaign(manifest, copy, workers=1, progress=False)
    # what failed is tried again; what went on without it stands while it fails again
    failed = ["calibrate:spheres", "single:S-3", "stage1:C-1", "stage1:S-3"]
    assert sorted(again.ran_ids) == failed and again.reused == 7
    assert not again.report_written
    before = read_tables(copy)["coefficients"]
    changed = write_manifest(tmp_path / "m2", seeds=(11, 99, 13))
    status = campaign_status(copy, changed).set_index("task")["state"]
    assert status["stage1:S-2"] == "stale" and status["stage1:S-1"] == "done"
    assert status["stage1:S-3"] == "failed"
    rerun = run_campaign(changed, copy, workers=1, progress=False)
    assert sorted(rerun.ran_ids) == sorted(["bootstrap:all spheres", "diagnose:all spheres",
                                            "multifit:all spheres", "single:S-2", "stage1:S-2",
                                            *failed])
    assert rerun.report_written
    after = read_tables(copy)["coefficients"]
    s1 = [d[(d["name"] == "S-1")].drop(columns="task_key").reset_index(drop=True)
          for d in (before, after)]
    pd.testing.assert_frame_equal(*s1)                        # untouched shot: same rows
    kept = sorted(p.name for p in (copy / "shots" / "S-2").iterdir())
    assert len(kept) == 2 and all(k.startswith("stage1-") for k in kept)   # both runs' folders:
    # nothing overwritten


def test_status_and_export_from_the_command_line(campaign, tmp_path, capsys):
    _, out, _ = campaign
    assert cadra(["campaign", "status", str(out)]) == 0
    text = capsys.readouterr().out
    assert text.splitlines()[0] == "tasks: 7 done, 4 failed"
    assert "failed      stage1:S-3: SpecError" in text
    dest = tmp_path / "export"
    assert cadra(["campaign", "export", str(out), "-o", str(dest), "-q"]) == 0
    db = read_tables(out)
    for name in ("shots", "coefficients", "fits", "curves", "gap_verdicts", "bootstrap"):
        from_csv = pd.read_csv(dest / f"{name}.csv")
        from_parquet = pd.read_parquet(dest / f"{name}.parquet")
        assert len(from_csv) == len(from_parquet) == len(db[name]) > 0
        pd.testing.assert_frame_equal(from_parquet, db[name])
    assert cadra(["campaign", "export", str(out), "-o", str(dest), "-q"]) == 1   # no overwrite


def test_a_groups_next_shot_is_planned_from_its_stored_fit(campaign, tmp_path, capsys):
    """cadra campaign plan: the group's stored multi-fit (the very result the database's
    coefficients come from), candidates at other speeds, each adding information."""
    from cadra.campaign import group_fit

    _, out, _ = campaign
    result = group_fit(out, "all spheres")
    coef = read_tables(out)["coefficients"]
    assert set(result.aero_names) <= set(coef[coef["name"] == "all spheres"]["parameter"])
    dest = tmp_path / "plan"
    argv = ["campaign", "plan", str(out), "--group", "all spheres", "-o", str(dest),
            "--mach", "1.2:3.5", "--candidates", "8", "--refine", "1", "-q"]
    assert cadra(argv) == 0
    best = pd.read_csv(dest / "best.csv")
    assert (best["objective"] < 1.0).all()          # any further shot adds information
    assert best["mach"].between(1.2, 3.5).all()
    sig = pd.read_csv(dest / "sigmas.csv").set_index("parameter")
    for n, s in zip(result.aero_names, result.aero_sigma, strict=True):
        assert sig.loc[n, "sigma_now"] == pytest.approx(s, rel=1e-6)
    capsys.readouterr()
    assert cadra([*argv[:3], "--group", "nope", "-o", str(tmp_path / "x"), "-q"]) == 1
    err = capsys.readouterr().err
    assert "no group 'nope'" in err and "all spheres" in err
    assert cadra([*argv[:5], "-o", str(out), "-q"]) == 1      # never over the campaign


def test_the_report_holds_the_campaigns_numbers_in_a_browser(campaign, browser, open_page):
    _, out, _ = campaign
    page, errors = open_page(browser, (out / "report.html").as_uri())
    page.wait_for_function("() => [...document.querySelectorAll('.plotly-graph-div')]"
                           ".every(d => d._fullLayout)")
    curves = read_tables(out)["curves"]
    cd = curves[curves["coefficient"] == "CD"]
    angle = cd["angle"].iloc[0]
    traces = page.evaluate(
        "(id) => document.getElementById(id).data.map(t => ({meta: t.meta ?? null, "
        "x: Array.from(t.x), y: Array.from(t.y)}))", f"curve-CD-{angle}")
    curve = next(t for t in traces if t["meta"] and t["meta"].get("role") == "curve")
    np.testing.assert_array_equal(curve["x"], cd["angle_deg"])
    np.testing.assert_array_equal(curve["y"], cd["value"])
    rows = page.evaluate("() => [...document.querySelectorAll('#shots tbody tr')]"
                         ".map(r => r.innerText)")
    assert sum(any(s in r for r in rows) for s in ("S-1", "S-2", "S-3")) == 3
    page.click("#shots a[href*='S-1']")
    page.wait_for_load_state()
    assert page.url.endswith("report.md") and "S-1" in page.url
    assert errors == []
    page.close()


# -- a real dask scheduler and two workers ---------------------------------------------------


def _dask(*args) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "distributed.cli." + args[0], *args[1:]],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def test_a_real_scheduler_and_workers_give_the_same_database(campaign, tmp_path):
    manifest, out, _ = campaign
    file = tmp_path / "scheduler.json"
    procs = [_dask("dask_scheduler", "--host", "127.0.0.1", "--port", "0",
                   "--scheduler-file", str(file), "--dashboard-address", ":0")]
    try:
        deadline = time.monotonic() + 120
        while not file.exists():
            assert time.monotonic() < deadline and procs[0].poll() is None
            time.sleep(0.2)
        import json

        address = json.loads(file.read_text())["address"]
        procs += [_dask("dask_worker", address, "--nthreads", "1", "--no-dashboard",
                        "--name", f"w{k}") for k in range(2)]
        from distributed import Client

        with Client(address) as client:
            client.wait_for_workers(2, timeout=120)
        there = tmp_path / "out"
        summary = run_campaign(manifest, there, scheduler=address, progress=False)
        assert summary.workers == 2 and summary.ran == 11
        local, remote = read_tables(out), read_tables(there)
        for name in ("shots", "coefficients", "fits", "curves", "gap_verdicts", "bootstrap"):
            pd.testing.assert_frame_equal(local[name], remote[name], check_exact=True)
        used = set(remote["tasks"]["worker"].dropna())
        assert len(used) == 2        # both workers took tasks
    finally:
        for p in procs:
            p.send_signal(signal.SIGTERM)
        for p in procs:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()


def test_the_local_workers_keep_the_allocators_adaptive_threshold(monkeypatch):
    """Dask's nanny would start each worker with MALLOC_TRIM_THRESHOLD_ set, which turns off
    glibc's adaptive mmap threshold (stage one 27 % slower); the campaign's local cluster
    leaves it unset, and a value the user exports is still what the workers get."""
    import os

    from cadra.campaign.cluster import local_client

    def trim():
        return os.environ.get("MALLOC_TRIM_THRESHOLD_")

    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)
    client, cluster = local_client(None, 1)
    try:
        assert list(client.run(trim).values()) == [None]
    finally:
        client.close()
        cluster.close()
    assert trim() is None      # nor did the nanny set it in this process
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "131072")
    client, cluster = local_client(None, 1)
    try:
        assert list(client.run(trim).values()) == ["131072"]
    finally:
        client.close()
        cluster.close()


def test_a_database_an_older_cadra_wrote_gains_the_new_columns(tmp_path):
    import sqlite3

    from cadra.campaign.database import FILENAME, SCHEMA

    old = sqlite3.connect(tmp_path / FILENAME)
    cols = {c: t for c, t in SCHEMA["coefficients"].items() if c != "sigma_consider"}
    old.execute("CREATE TABLE coefficients (" + ", ".join(f"{c} {t}" for c, t in cols.items())
                + ", task_key TEXT)")
    old.execute("INSERT INTO coefficients (scope, name, parameter, value, sigma) "
                "VALUES ('group', 'G', 'CD_A1', 1.25, 0.01)")
    old.commit()
    old.close()
    db = CampaignDB(tmp_path)
    try:
        rows = db.conn.execute("SELECT value, sigma, sigma_consider FROM coefficients").fetchall()
    finally:
        db.close()
    assert rows == [(1.25, 0.01, None)]
