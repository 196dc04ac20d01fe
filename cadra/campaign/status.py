"""What a campaign folder holds against what its manifest asks for, and its tables exported.

:func:`campaign_status` plans the manifest again (its files hashed as they are now) and
says, for every task, whether it is ``done`` (its current key has a stored result),
``failed`` (its current key failed when last run), ``submitted`` (queued or running in a run
that holds the folder now), ``interrupted`` (submitted by a run that was killed), ``stale`` (done
under an earlier key: an input changed since) or ``to do`` (never run).
"""

from __future__ import annotations

import os
from pathlib import Path

import pandas as pd

from cadra.campaign.database import FILENAME, PUBLIC_TABLES, CampaignDB, read_tables
from cadra.campaign.manifest import load_manifest
from cadra.campaign.plan import file_sha256, plan
from cadra.campaign.tasks import first_line

#: the states, in the order the summary lists them
STATES = ("done", "failed", "submitted", "interrupted", "stale", "to do")


def _held(out: Path) -> bool:
    from filelock import FileLock, Timeout

    from cadra.campaign.run import LOCK

    lock = FileLock(str(out / LOCK))
    try:
        lock.acquire(timeout=0)
    except Timeout:
        return True
    lock.release()
    return False


def group_fit(folder: str | os.PathLike, group: str, manifest=None):
    """The multi-fit (:class:`~cadra.fitting.result.FitResult`) of ``group`` that the
    campaign in ``folder`` stored for the manifest as it is now (default: the one the folder
    last ran); ``ValueError`` naming the groups or the task's state when there is none."""
    from cadra.campaign.run import _load

    out = Path(folder)
    if not (out / FILENAME).is_file():
        raise FileNotFoundError(f"{out}: no campaign here (no {FILENAME})")
    db = CampaignDB(out)
    try:
        m = load_manifest(manifest or db.get("manifest"))
        tasks = {t.id: t for t in plan(m, hasher=db.hasher(file_sha256))}
        t = tasks.get(f"multifit:{group}")
        if t is None:
            names = [g.name for g in m.groups]
            raise ValueError(f"no group {group!r} in the campaign (groups: "
                             f"{', '.join(names) or 'none'})")
        if not db.done(t.key):
            raise ValueError(f"group {group!r}: its multi-fit is not done for the manifest as "
                             "it is now (cadra campaign status says why; run it first)")
    finally:
        db.close()
    o = _load(out, f"results/{t.key}.pkl")
    if o is None or not o.ok:
        raise ValueError(f"group {group!r}: no stored multi-fit result in {out}/results")
    return o.value["result"]


def campaign_status(folder: str | os.PathLike, manifest=None) -> pd.DataFrame:
    """One row per task of the manifest (default: the one the folder last ran): ``task``
    (kind:name), ``kind``, ``name``, ``state`` (:data:`STATES`), ``seconds``, ``worker``,
    ``error`` (first line)."""
    out = Path(folder)
    if not (out / FILENAME).is_file():
        raise FileNotFoundError(f"{out}: no campaign here (no {FILENAME})")
    running_now = _held(out)
    db = CampaignDB(out)
    try:
        path = manifest or db.get("manifest")
        m = load_manifest(path)
        tasks = plan(m, hasher=db.hasher(file_sha256))
        rows = []
        for t in tasks:
            last = db.conn.execute(
                "SELECT status, seconds, worker, error FROM tasks WHERE key = ? "
                "ORDER BY rowid DESC LIMIT 1", (t.key,)).fetchone()
            earlier = db.conn.execute(
                "SELECT 1 FROM tasks WHERE kind = ? AND name = ? AND key != ? AND "
                "status = 'done' LIMIT 1", (t.kind, t.name, t.key)).fetchone()
            if db.done(t.key):
                state = "done"
            elif last and last[0] == "failed":
                state = "failed"
            elif last and last[0] in ("submitted", "interrupted"):
                state = ("submitted" if running_now and last[0] == "submitted"
                         else "interrupted")
            elif earlier:
                state = "stale"
            else:
                state = "to do"
            err = first_line(last[3]) if last else ""
            rows.append({"task": t.id, "kind": t.kind, "name": t.name, "state": state,
                         "seconds": last[1] if last else None,
                         "worker": last[2] if last else None, "error": err})
        return pd.DataFrame(rows)
    finally:
        db.close()


def status_lines(table: pd.DataFrame, verbose: bool = False) -> list[str]:
    """The summary ``cadra campaign status`` prints: counts by state, then every task that is
    not done (every task with ``verbose``)."""
    counts = table["state"].value_counts()
    lines = ["tasks: " + ", ".join(f"{int(counts[s])} {s}" for s in STATES if s in counts)]
    show = table if verbose else table[table["state"] != "done"]
    for r in show.itertuples():
        extra = f": {r.error}" if r.error else ""
        lines.append(f"  {r.state:<11} {r.task}{extra}")
    return lines


def export_tables(folder: str | os.PathLike, out_dir: str | os.PathLike, *,
                  overwrite: bool = False, parquet: bool = True) -> Path:
    """Write the database's public tables as ``<table>.csv`` (and ``<table>.parquet``) into
    ``out_dir``, atomically (units in the column names; docs/campaign.md)."""
    from cadra.atomic import atomic_output_dir

    tables = read_tables(folder, PUBLIC_TABLES)
    with atomic_output_dir(out_dir, overwrite=overwrite, kind="campaign export") as tmp:
        for name, df in tables.items():
            df.to_csv(tmp / f"{name}.csv", index=False)
            if parquet:
                df.to_parquet(tmp / f"{name}.parquet", index=False)
    return Path(out_dir)


__all__ = ["STATES", "campaign_status", "export_tables", "status_lines"]
