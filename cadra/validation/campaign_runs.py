"""Campaigns checked against the truth they were flown with (tools/validate_campaign.py) and
timed (tools/bench_campaign.py).

:func:`group_recovery` compares every group's multi-fit with the aerodynamic model its shots
were flown with (each specification's ``aero_model`` with its ``aero_values``): per free
parameter the fitted value, its sigma, the truth and the pull. :func:`synthetic_manifest`
writes a campaign of N synthetic shots of mixed bodies (capsules in groups of five, sphere
calibration shots, bullets) for the benchmark.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pandas as pd

from cadra.campaign import load_manifest, read_tables

ROOT = Path(__file__).resolve().parents[2]
SPECS = ROOT / "sample_shots" / "specs"


def flown_model(entry):
    """The aerodynamic model a specification's shot was flown with (SI values)."""
    from cadra.aero import resolve_model
    from cadra.io.spec_file import spec_from_dict

    spec = spec_from_dict(dict(entry.spec),
                          source_path=Path(entry.spec_path) if entry.spec_path else None)
    model = resolve_model(spec.aero_model,
                          Path(spec.source_path).parent if spec.source_path else None)
    return model.with_values(spec.aero_values) if spec.aero_values else model


def group_recovery(folder: str | os.PathLike, manifest) -> pd.DataFrame:
    """Per group and free parameter: ``group``, ``parameter``, ``value``, ``sigma``,
    ``truth``, ``pull`` ((value - truth) / sigma), ``within_2sigma``; groups whose shots were
    flown with different models are skipped (no one truth)."""
    m = load_manifest(manifest) if not hasattr(manifest, "groups") else manifest
    coef = read_tables(folder)["coefficients"]
    rows = []
    for g in m.groups:
        truths = [flown_model(m.shot(s)) for s in g.shots]
        values = [t.values() for t in truths]
        if any(len(v) != len(values[0]) or not np.array_equal(v, values[0]) for v in values):
            continue
        truth = truths[0]
        fit = coef[(coef["scope"] == "group") & (coef["name"] == g.name) & (coef["vary"] == 1)]
        for r in fit.itertuples():
            t = truth.parameter(r.parameter).value
            pull = (r.value - t) / r.sigma if r.sigma and r.sigma > 0 else math.nan
            rows.append({"group": g.name, "parameter": r.parameter, "value": r.value,
                         "sigma": r.sigma, "truth": t, "pull": pull,
                         "within_2sigma": bool(abs(pull) <= 2.0)})
    return pd.DataFrame(rows)


# -- the benchmark's campaign ----------------------------------------------------------------

#: the bodies of the benchmark's campaign, in the order they are dealt, and their specs
MIX = (("capsule", "m2_2429"), ("capsule", "m2_2425"), ("sphere", "sphere_1"),
       ("capsule", "m2_2427"), ("capsule", "m2_2428"), ("sphere", "sphere_2"),
       ("capsule", "m2_2426"), ("bullet", "m80_1"), ("capsule", "m2_2431"),
       ("sphere", "sphere_3"))
#: capsules per group
GROUP_SIZE = 5


def synthetic_manifest(folder: str | os.PathLike, n_shots: int, *, tag: int = 0) -> Path:
    """A campaign of ``n_shots`` synthetic shots dealt from :data:`MIX` (each a sample
    specification with its own seed, so every shot is new), the capsules in groups of
    :data:`GROUP_SIZE` with the M2 M0.70 model, the spheres as calibration shots, the bullets
    fitted alone. ``tag`` changes every seed (a different campaign of the same size)."""
    import tomllib

    import tomli_w

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    shots, capsules = [], []
    for k in range(n_shots):
        body, name = MIX[k % len(MIX)]
        spec = tomllib.loads((SPECS / f"{name}.toml").read_text(encoding="utf-8"))
        sid = f"{body}-{k + 1:04d}"
        spec.update(shot_id=sid, seed=100_000 * (tag + 1) + k)
        entry = {"id": sid, "spec": spec}
        if body == "sphere":
            entry["role"] = "sphere"
        if body == "capsule":
            capsules.append(sid)
        shots.append(entry)
    groups = [{"name": f"capsules {j // GROUP_SIZE + 1}", "model": "m2_m070",
               "shots": capsules[j:j + GROUP_SIZE]}
              for j in range(0, len(capsules), GROUP_SIZE) if capsules[j:j + GROUP_SIZE]]
    path = folder / "campaign.toml"
    path.write_bytes(tomli_w.dumps({"name": f"bench-{n_shots}", "shots": shots,
                                    "groups": groups}).encode("utf-8"))
    return path


# -- the benchmark ---------------------------------------------------------------------------


def _task_costs(folder) -> dict:
    """Worker seconds per task kind over the current tasks that finished: count and total."""
    t = read_tables(folder)["tasks"]
    t = t[(t["current"] == 1) & t["status"].isin(["done", "failed"])]
    return {k: {"tasks": int(len(d)), "seconds": float(d["seconds"].sum())}
            for k, d in t.groupby("kind")}


def _done_keys(folder) -> set[str]:
    t = read_tables(folder)["tasks"]
    return set(t.loc[(t["current"] == 1) & (t["status"] == "done"), "key"])


def killed_and_resumed(manifest: Path, out: Path, fraction: float = 0.5,
                       workers: int = 2) -> dict:
    """Run the campaign with ``cadra campaign run`` in a process, stop it with SIGTERM once
    ``fraction`` of its tasks are done, then resume it here: the tasks the resumed run ran
    and those it should have (every task without a stored result when the first was stopped).
    """
    import signal
    import subprocess
    import sys
    import time

    from cadra.campaign import run_campaign
    from cadra.campaign.plan import plan

    n = len(plan(load_manifest(manifest)))
    proc = subprocess.Popen([sys.executable, "-m", "cadra.cli.campaign", "campaign", "run",
                             str(manifest), "-o", str(out), "--workers", str(workers), "-q"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    while proc.poll() is None:
        time.sleep(2.0)
        try:
            if len(_done_keys(out)) >= fraction * n:
                break
        except (FileNotFoundError, Exception):  # noqa: BLE001 - the database is not made yet
            continue
    proc.send_signal(signal.SIGTERM)
    proc.wait(timeout=600)
    done = _done_keys(out)
    summary = run_campaign(manifest, out, workers=workers, progress=False)
    return {"resume_tasks": n, "resume_done_before_kill": len(done),
            "resume_rerun_tasks": summary.ran, "resume_expected_tasks": n - len(done),
            "resume_exit_status": proc.returncode}


def changed_one(manifest: Path, out: Path, workers: int = 2) -> dict:
    """Change one capsule's specification (its seed) and rerun: the tasks that ran and those
    that should have (that shot's stage one and single fit, its group's tasks, and any task
    that had failed)."""
    import tomllib

    import tomli_w

    from cadra.campaign import run_campaign
    from cadra.campaign.plan import plan

    data = tomllib.loads(manifest.read_text(encoding="utf-8"))
    shot = next(s for s in data["shots"] if s["id"].startswith("capsule"))
    shot["spec"]["seed"] += 7
    changed = manifest.with_name("changed.toml")
    changed.write_bytes(tomli_w.dumps(data).encode("utf-8"))
    before = {t.id: t.key for t in plan(load_manifest(manifest))}
    after = {t.id: t.key for t in plan(load_manifest(changed))}
    t = read_tables(out)["tasks"]
    failed = set(t.loc[(t["current"] == 1) & (t["status"] == "failed"), "kind"] + ":"
                 + t.loc[(t["current"] == 1) & (t["status"] == "failed"), "name"])
    expected = {i for i in after if after[i] != before.get(i)} | failed
    summary = run_campaign(changed, out, workers=workers, progress=False)
    return {"change_one_rerun_tasks": summary.ran,
            "change_one_expected_tasks": len(expected),
            "change_one_ran_as_expected": set(summary.ran_ids) <= expected,
            "change_one_report_written": summary.report_written}


#: the warm-up campaign's size (every task kind: capsules in a group, spheres, a bullet) and
#: seed tag (its shots are none of the timed campaigns')
WARM_SHOTS, WARM_TAG = 10, 999


def bench(n_shots: int, work: Path, *, memory_sizes=()) -> dict:
    """The campaign benchmark (tools/bench_campaign.py): ``n_shots`` synthetic shots on one
    and on two local workers, per-stage costs, peak memory per worker (also for each of
    ``memory_sizes``), a stopped-and-resumed run and a one-shot change."""
    from cadra.campaign import run_campaign

    work = Path(work)
    # numba compiles each kernel once per machine and caches it on disk: a warm-up campaign
    # of every task kind first, so that neither timed run (the one-worker run goes first)
    # pays that one-time cost (it was 40 s of the one-worker run's 800 s)
    run_campaign(synthetic_manifest(work / "warm_manifest", WARM_SHOTS, tag=WARM_TAG),
                 work / "warm", workers=1, progress=False)
    manifest = synthetic_manifest(work / "manifest", n_shots)
    one = run_campaign(manifest, work / "one_worker", workers=1, progress=True)
    two = run_campaign(manifest, work / "two_workers", workers=2, progress=True)
    costs = _task_costs(work / "one_worker")
    worker_s = sum(c["seconds"] for c in costs.values())
    speedup = one.seconds / two.seconds
    per_shot = worker_s / n_shots
    efficiency = speedup / 2.0
    out = {"shots": n_shots, "workers": 2, "tasks": two.tasks,
           "wall_s": round(two.seconds, 1), "wall_s_1_worker": round(one.seconds, 1),
           "seconds_per_shot": round(two.seconds / n_shots, 2),
           "worker_seconds_per_shot": round(per_shot, 2),
           "stage_seconds_per_task": {k: round(c["seconds"] / max(c["tasks"], 1), 2)
                                      for k, c in costs.items()},
           "stage_tasks": {k: c["tasks"] for k, c in costs.items()},
           "speedup_2_workers": round(speedup, 3),
           "peak_rss_mb_per_worker": round(max(two.peak_rss_mb.values(), default=math.nan), 1),
           "failed_tasks": sorted(set(one.failed) | set(two.failed)),
           "projected_1000_shots_s": round(1000 * per_shot / (2 * efficiency), 0),
           "projected_formula": "T(1000 shots, W workers) = 1000 * c / (W * e); c = worker "
                                "seconds per shot, e = speedup_2_workers / 2"}
    out[f"peak_rss_mb_per_worker_{n_shots}_shots"] = out["peak_rss_mb_per_worker"]
    for n in memory_sizes:
        if n == n_shots:
            continue
        m = synthetic_manifest(work / f"manifest_{n}", n, tag=n)
        r = run_campaign(m, work / f"memory_{n}", workers=2, progress=True)
        out[f"peak_rss_mb_per_worker_{n}_shots"] = round(max(r.peak_rss_mb.values()), 1)
    out |= killed_and_resumed(manifest, work / "resumed")
    out |= changed_one(manifest, work / "resumed")
    return out


__all__ = ["GROUP_SIZE", "MIX", "bench", "changed_one", "flown_model", "group_recovery",
           "killed_and_resumed", "synthetic_manifest"]
