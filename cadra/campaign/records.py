"""What the client makes of a task's outcome: the database's rows and the task's folder.

Each finished task's rows replace that task's earlier rows (the same ``kind:name``); each
task's folder (drawn on its worker, :mod:`cadra.campaign.folders`) is written under a name
made of its key (``shots/<shot>/stage1-<key>``, ``groups/<group>/multifit-<key>``, ...), so
a rerun never overwrites an earlier result. The shot's and group's reports are the
library's own (:mod:`cadra.report`).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pandas as pd

from cadra.campaign.database import CampaignDB
from cadra.campaign.folders import ensure
from cadra.campaign.manifest import Manifest
from cadra.campaign.tasks import Outcome
from cadra.campaign.tasks import first_line as _first_line

#: how much of a key names a task's folder
KEY_CHARS = 10


def slug(name: str) -> str:
    """A folder name for a shot or group id (letters, digits, ``.-_`` kept)."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_") or "unnamed"


def task_folder(out: Path, kind: str, name: str, key: str) -> Path:
    top = "shots" if kind in ("stage1", "single") else (
        "calibration" if kind == "calibrate" else "groups")
    return out / top / slug(name) / f"{kind}-{key[:KEY_CHARS]}"


def _rel(path: Path | None, out: Path) -> str:
    return "" if path is None else path.relative_to(out).as_posix()


def record(db: CampaignDB, manifest: Manifest, out: Path, o: Outcome) -> None:
    """Write ``o``'s folder (when it has one) and its database rows."""
    {"stage1": _stage1, "calibrate": _calibrate, "single": _single, "multifit": _multifit,
     "holdone": _holdone, "diagnose": _diagnose, "bootstrap": _bootstrap}[o.kind](
        db, manifest, out, o)


def _stage1(db, manifest, out, o):
    entry = manifest.shot(o.name)
    row = {"shot_id": o.name, "role": entry.role, "group_name": manifest.group_of(o.name),
           "status": "done" if o.ok else "failed", "error": _first_line(o.error),
           "body": _body((entry.spec or {}).get("model"))}
    if o.ok:
        v = o.value
        folder = task_folder(out, "stage1", o.name, o.key)
        ensure(folder, o.kind, o.name, v, o.folder)
        row.update(mach=v["mach"], velocity_m_s=v["velocity_m_s"],
                   n_stations=v["n_stations"], stage1_report=_rel(folder / "report.md", out),
                   body=row["body"] or _body(v["stage1"].shot.model))
    db.replace("shots", {"shot_id": o.name}, [row], o.key)


def _body(model) -> str:
    """A body's short name: its preset (``M2``) or its kind (``sphere``)."""
    model = model if isinstance(model, dict) else {}
    return str(model.get("preset") or model.get("kind") or "")


def _calibrate(db, manifest, out, o):
    if not o.ok:
        db.replace("station_biases", {}, [], o.key)
        return
    est = o.value
    rows = []
    names = ("x_m", "y_m", "z_m", "time_s")
    for k, st in enumerate(est.stations):
        r = {"facility": est.facility, "station": int(st), "applied": 1}
        for j, n in enumerate(names):
            r[n] = float(est.bias[k, j])
            r[f"sigma_{n}"] = float(est.sigma[k, j])
        rows.append(r)
    db.replace("station_biases", {}, rows, o.key)
    folder = task_folder(out, "calibrate", o.name, o.key)
    if not folder.exists():
        from cadra.atomic import atomic_output_dir

        with atomic_output_dir(folder) as tmp:
            pd.DataFrame(rows).to_csv(tmp / "station_biases.csv", index=False)


def _single(db, manifest, out, o):
    where = {"scope": "single", "name": o.name}
    if not o.ok:
        db.replace("fits", where, [{**where, "status": "failed", "converged": 0,
                                    "note": _first_line(o.error)}], o.key)
        db.replace("coefficients", where, [], o.key)
        return
    row, model = o.value["row"], o.value["model"]
    fit = {**where, "model": model, "status": row["status"], "converged": row["converged"],
           "chi2nu": row["reduced_chi2"], "dof": row["dof"], "n_shots": 1, "shots": o.name,
           "note": o.value.get("note", "")}
    db.replace("fits", where, [fit], o.key)
    params = [k for k in row if f"{k}_sigma_scaled" in row]   # studies.single's columns
    coefs = [{**where, "model": model, "parameter": p, "value": row[p],
              "sigma": row[f"{p}_sigma"], "vary": 1, "mach": o.value["mach"],
              "alpha_rms_deg": row.get("alpha_rms_deg"),
              "sigma_rms_deg": row.get("sigma_rms_deg")} for p in params]
    db.replace("coefficients", where, coefs, o.key)


def _multifit(db, manifest, out, o):
    where = {"scope": "group", "name": o.name}
    group = next(g for g in manifest.groups if g.name == o.name)
    if not o.ok:
        db.replace("fits", where, [{**where, "model": group.model, "status": "failed",
                                    "converged": 0, "note": _first_line(o.error)}], o.key)
        db.replace("coefficients", where, [], o.key)
        db.replace("curves", {"group_name": o.name}, [], o.key)
        return
    result, shots, missing = o.value["result"], o.value["shots"], o.value["missing"]
    folder = task_folder(out, "multifit", o.name, o.key)
    ensure(folder, o.kind, o.name, o.value, o.folder)
    notes = [f"ran on {len(shots)} of {len(group.shots)} shots: "
             + "; ".join(f"{k} failed ({_first_line(v)})" for k, v in missing.items())
             ] if missing else []
    note = "; ".join(notes + ([o.value["note"]] if o.value.get("note") else []))
    mach = float(np.mean([r for r in _machs(db, [s.shot_id for s in shots]) if r is not None]
                         or [math.nan]))
    db.replace("fits", where, [{
        **where, "model": result.model.name, "status": result.status,
        "converged": bool(result), "chi2nu": result.reduced_chi2, "dof": result.dof,
        "n_shots": len(shots), "shots": ",".join(s.shot_id for s in shots), "note": note,
        "report": _rel(folder / "report.md", out)}], o.key)
    with db.conn:   # each shot's row links to the group fit it is in
        db.conn.executemany("UPDATE shots SET fit_report = ? WHERE shot_id = ?",
                            [(_rel(folder / "report.md", out), s.shot_id) for s in shots])
    ca = result.consider     # held values with an uncertainty: their consider sigma
    cons = {} if ca is None else dict(zip(ca.names, ca.sigma, strict=True))
    rows = []
    for p in result.params.values():
        if p.kind != "aero":
            continue
        rows.append({**where, "model": result.model.name, "parameter": p.name,
                     "value": p.value, "sigma": p.stderr, "vary": p.vary, "mach": mach,
                     "sigma_consider": cons.get(p.name) if p.vary else None})
    db.replace("coefficients", where, rows, o.key)
    curves = o.value.get("curves")
    crow = [] if curves is None else [{"group_name": o.name, **r}
                                      for r in curves.to_dict("records")]
    db.replace("curves", {"group_name": o.name}, crow, o.key)


def _machs(db, ids):
    q = f"SELECT mach FROM shots WHERE shot_id IN ({', '.join('?' for _ in ids)})"
    return [r[0] for r in db.conn.execute(q, ids).fetchall()]


def _holdone(db, manifest, out, o):
    group = next(g for g in manifest.groups if g.name == o.name)
    where = {"group_name": o.name}
    if not o.ok:
        db.replace("hold_study", where, [], o.key)
        return
    table = o.value
    folder = task_folder(out, "holdone", o.name, o.key)
    ensure(folder, o.kind, o.name, table, o.folder)
    rows = [{"group_name": o.name, "parameter": group.hold_study.parameter,
             "held_value": r["value"], "status": r["status"], "converged": r["converged"],
             "reduced_chi2": r["reduced_chi2"], "theta_rms_deg": r.get("theta_rms_deg"),
             "psi_rms_deg": r.get("psi_rms_deg")} for r in table.to_dict("records")]
    db.replace("hold_study", where, rows, o.key)


def _diagnose(db, manifest, out, o):
    where = {"group_name": o.name}
    if not o.ok:
        db.replace("gap_verdicts", where, [{**where, "verdict": "not diagnosed",
                                            "summary": _first_line(o.error)}], o.key)
        return
    dg = o.value
    folder = task_folder(out, "diagnose", o.name, o.key)
    ensure(folder, o.kind, o.name, dg, o.folder)
    best = dg.ranking.iloc[0] if len(dg.ranking) else None
    db.replace("gap_verdicts", where, [{
        **where, "verdict": _first_line(dg.verdict),
        "best_effect": "" if best is None else str(best["candidate"]),
        "best_p": None if best is None else best.get("p_value"),
        "chi2nu_before": dg.reduced_chi2_before, "chi2nu_after": dg.reduced_chi2_after,
        "summary": dg.verdict}], o.key)


def _bootstrap(db, manifest, out, o):
    where = {"group_name": o.name}
    if not o.ok:
        db.replace("bootstrap", where, [], o.key)
        return
    boot = o.value
    ensure(task_folder(out, "bootstrap", o.name, o.key), o.kind, o.name, boot, o.folder)
    rows = [{"group_name": o.name, "noise": boot.noise,
             **{k: r[k] for k in ("parameter", "value", "sigma_cov", "sigma_boot", "ratio",
                                  "bias_sigma", "lower", "upper", "n")},
             "non_gaussian": None if r["non_gaussian"] is None else int(r["non_gaussian"])}
            for r in boot.table.to_dict("records")]
    db.replace("bootstrap", where, rows, o.key)


__all__ = ["KEY_CHARS", "record", "slug", "task_folder"]
