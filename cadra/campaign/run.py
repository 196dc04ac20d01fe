"""Running a campaign on Dask: the client plans, submits, records; the workers compute.

:func:`run_campaign` plans the manifest's tasks (:mod:`cadra.campaign.plan`), reuses every
task whose key already has a stored result, and submits the rest to a Dask cluster with
``client.submit`` (each task's inputs passed as futures, so the scheduler sees the graph).
As each task finishes, the client, and only the client, stores its outcome
(``results/<key>.pkl``, never overwritten), writes its folder and database rows
(:mod:`cadra.campaign.records`), and last the report page. A task that fails is recorded
with its reason and does not stop the others; killing the run loses only the tasks then
running: the next run finds the rest stored.

The cluster is a :class:`distributed.LocalCluster` of processes with one thread each (one
worker per core by default), or an existing scheduler's address. Each worker is one process
that keeps its caches between tasks (numba's compiled code, the facility file, the aero
models); stage one runs in the worker's own process (its own pool gives way to Dask's).
"""

from __future__ import annotations

import hashlib
import os
import pickle
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from cadra.atomic import OUTPUT_MARKER, atomic_write_bytes, output_kind
from cadra.campaign.cluster import local_client
from cadra.campaign.database import CampaignDB, read_tables
from cadra.campaign.folders import run_drawn
from cadra.campaign.manifest import Manifest, load_manifest
from cadra.campaign.plan import Task, file_sha256, plan
from cadra.campaign.records import record
from cadra.campaign.tasks import Outcome, first_line

#: the campaign folder's kind (its :data:`cadra.atomic.OUTPUT_MARKER`)
KIND = "campaign"
#: the report page, a view of the database rewritten by every run that changed something
REPORT = "report.html"
LOCK = ".campaign.lock"


class CampaignError(RuntimeError):
    """A campaign that cannot run here (a folder in use or not a campaign's)."""


@dataclass
class RunSummary:
    """What one run did (counts of tasks by what happened to them)."""

    folder: Path
    tasks: int = 0
    reused: int = 0
    ran: int = 0
    failed: list[str] = field(default_factory=list)
    report_written: bool = False
    seconds: float = 0.0
    workers: int = 0
    ran_ids: list[str] = field(default_factory=list)
    #: worker address -> its process's peak resident memory, MB (when tasks ran)
    peak_rss_mb: dict = field(default_factory=dict)

    def __str__(self) -> str:
        fail = f", {len(self.failed)} failed ({', '.join(self.failed[:5])})" if self.failed \
            else ""
        return (f"campaign: {self.tasks} tasks, {self.reused} reused, {self.ran} run{fail}; "
                f"report {'written' if self.report_written else 'unchanged'}; "
                f"{self.seconds:.0f} s on {self.workers} worker(s)")


def _utc() -> str:
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def prepare_folder(out: Path) -> Path:
    """Create the campaign folder, or check an existing one is a campaign's."""
    out = Path(out)
    if out.exists():
        if not out.is_dir():
            raise CampaignError(f"{out} is a file, not a campaign folder")
        kind = output_kind(out)
        if kind is None and any(out.iterdir()):
            raise CampaignError(f"{out} is a folder CADRA did not write; choose a new folder")
        if kind not in (None, KIND):
            raise CampaignError(f"{out} is CADRA's {kind or 'other'} output, not a campaign")
    out.mkdir(parents=True, exist_ok=True)
    marker = out / OUTPUT_MARKER
    if not marker.exists():
        marker.write_text(f"kind: {KIND}\nwritten by CADRA: a campaign folder; reruns add to "
                          "it and never overwrite a result\n", encoding="utf-8")
    return out


def _lock(out: Path):
    from filelock import FileLock, Timeout

    lock = FileLock(str(out / LOCK))
    try:
        lock.acquire(timeout=0)
    except Timeout:
        raise CampaignError(f"{out}: another run is using this campaign folder") from None
    return lock


def _load(out: Path, rel: str) -> Outcome | None:
    try:
        with open(out / rel, "rb") as fh:
            return pickle.load(fh)
    except (OSError, pickle.UnpicklingError, EOFError, AttributeError):
        return None


def _store(out: Path, o: Outcome) -> str:
    """Store ``o`` (without its drawn folder: the folder is written beside it)."""
    from dataclasses import replace

    rel = f"results/{o.key}.pkl"
    if not (out / rel).exists():
        atomic_write_bytes(out / rel, pickle.dumps(replace(o, folder=None),
                                                   protocol=pickle.HIGHEST_PROTOCOL))
    return rel


def _peak_rss_mb() -> float:
    """This process's peak resident memory, MB (Linux reports KiB)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _report_key(tasks: list[Task], db: CampaignDB) -> str:
    rows = [(t.id, t.key, db.done(t.key)) for t in tasks]
    return hashlib.sha256(repr(rows).encode()).hexdigest()


def run_campaign(manifest: Manifest | str | os.PathLike, out_dir: str | os.PathLike, *,
                 scheduler: str | None = None, workers: int | None = None,
                 progress: bool = True) -> RunSummary:
    """Run (or resume) a campaign into ``out_dir``: every task whose result is not yet stored
    runs on Dask, and the database and report follow. ``scheduler``: an existing Dask
    scheduler's address (default: a local cluster of ``workers`` processes, one per core).
    ``progress``: one bar over the tasks that run, with a line for each that fails.
    Returns a :class:`RunSummary`."""
    import time

    t0 = time.perf_counter()
    if not isinstance(manifest, Manifest):
        manifest = load_manifest(manifest)
    out = prepare_folder(Path(out_dir))
    lock = _lock(out)
    db = CampaignDB(out)
    try:
        db.interrupted()
        tasks = plan(manifest, hasher=db.hasher(file_sha256))
        db.mark_current(t.key for t in tasks)
        db.set(name=manifest.name, manifest=manifest.path,
               manifest_sha256=file_sha256(manifest.path), last_run_utc=_utc())
        if db.get("created_utc") is None:
            db.set(created_utc=_utc())
        from cadra import __version__

        db.set(cadra_version=__version__)
        summary = RunSummary(out, tasks=len(tasks))
        stored = {t.id: o for t in tasks
                  if (rel := db.done(t.key)) and (o := _load(out, rel)) is not None}
        _Scheduler(tasks, stored, db, manifest, out, summary).run(scheduler, workers, progress)
        _drop_superseded(db, tasks)
        key = _report_key(tasks, db)
        if key != db.get("report_key") or not (out / REPORT).exists():
            write_report(out, manifest.name)
            db.set(report_key=key)
            summary.report_written = True
        summary.seconds = time.perf_counter() - t0
        return summary
    finally:
        db.close()
        lock.release()


class _Scheduler:
    """Decides, task by task, whether a stored outcome stands or the task runs, and submits
    what runs to Dask as soon as its inputs are decided (inputs that run are passed as
    futures, so the scheduler sees the graph).

    A task without a stored outcome for its key runs. A task with one is reused when none of
    its inputs ran in this run, or when the inputs that ran failed again exactly as they had
    when the stored outcome was made (:attr:`Outcome.failed_inputs`): a group fit that went
    on without a failed shot stands while that shot keeps failing, and runs again once the
    shot comes through. Such a task waits for its rerun inputs to finish before it is
    decided."""

    def __init__(self, tasks, stored, db, manifest, out, summary):
        self.tasks, self.stored, self.db = tasks, stored, db
        self.manifest, self.out, self.summary = manifest, out, summary
        self.outcomes: dict[str, Outcome] = {}     # decided: reused or finished this run
        self.futures: dict[str, object] = {}       # submitted this run
        self.ran: set[str] = set()
        self.client = None
        self.scattered: dict[str, object] = {}

    def _reuse(self, t: Task) -> None:
        o = self.stored[t.id]
        self.outcomes[t.id] = o
        record(self.db, self.manifest, self.out, o)
        self.summary.reused += 1

    def _decide(self, t: Task) -> bool:
        """Reuse or submit ``t`` if its inputs allow it now; False: it must wait."""
        if any(u not in self.outcomes and u not in self.futures for u in t.upstream):
            return False
        if t.id in self.stored:
            rerun = [u for u in t.upstream if u in self.ran]
            if not rerun:
                self._reuse(t)
                return True
            if any(u not in self.outcomes for u in rerun):
                return False                        # wait for the rerun inputs to finish
            failed = tuple(sorted(u for u in t.upstream if not self.outcomes[u].ok))
            if all(u in failed for u in rerun) and failed == self.stored[t.id].failed_inputs:
                self._reuse(t)
                return True
        self._submit(t)
        return True

    def _arg(self, u):
        if u is None:
            return None
        if u in self.futures and u not in self.outcomes:
            return self.futures[u]
        if u not in self.scattered:   # decided already: send its outcome once
            self.scattered[u] = self.client.scatter(self.outcomes[u], hash=False)
        return self.scattered[u]

    def _submit(self, t: Task) -> None:
        if self.client is None:
            self.client, self.cluster = local_client(self.scheduler, self.workers)
            self.summary.workers = len(self.client.scheduler_info(n_workers=-1)["workers"])
            from distributed import as_completed

            self.done = as_completed()
        f = self.client.submit(run_drawn, t.kind, t.name, t.key, t.payload,
                               *(self._arg(u) for u in t.inputs),
                               key=f"{t.kind}-{t.key[:16]}-{os.getpid()}", pure=False)
        self.futures[t.id] = f
        self.by_key[f.key] = t
        self.ran.add(t.id)
        self.db.started(t.key, t.kind, t.name, _utc())
        self.done.add(f)
        if self.bar is not None:
            self.bar.total = len(self.ran)
            self.bar.refresh()

    def run(self, scheduler, workers, progress) -> None:
        from tqdm import tqdm

        self.scheduler, self.workers, self.by_key, self.cluster = scheduler, workers, {}, None
        self.bar = None
        waiting = list(self.tasks)
        try:
            waiting = [t for t in waiting if not self._decide(t)]
            if self.client is None:
                return
            self.bar = tqdm(total=len(self.ran), desc=f"campaign {self.manifest.name}",
                            unit="task", disable=not progress)
            for f in self.done:
                self._finish(f)
                waiting = [t for t in waiting if not self._decide(t)]
            self.bar.close()
        finally:
            if self.client is not None:
                try:
                    self.summary.peak_rss_mb = self.client.run(_peak_rss_mb)
                except Exception:  # noqa: BLE001 - a figure, not a result
                    pass
                self.client.close()
            if self.cluster is not None:
                self.cluster.close()
        if waiting:   # cannot happen: every input is decided once the runs are finished
            raise RuntimeError(f"tasks left undecided: {[t.id for t in waiting]}")

    def _finish(self, f) -> None:
        t = self.by_key[f.key]
        try:
            o = f.result()
        except Exception as exc:  # noqa: BLE001 - a lost worker fails its task only
            o = Outcome(t.kind, t.name, t.key, False, error=f"{type(exc).__name__}: {exc}")
        rel = _store(self.out, o) if o.ok else None
        try:
            record(self.db, self.manifest, self.out, o)
        except Exception as exc:  # noqa: BLE001 - a report that cannot be written
            o = Outcome(t.kind, t.name, t.key, False, error=f"recording failed: "
                        f"{type(exc).__name__}: {exc}", seconds=o.seconds, worker=o.worker,
                        started_utc=o.started_utc, failed_inputs=o.failed_inputs)
            rel = None
        self.db.finished(o, _utc(), rel)
        self.outcomes[t.id] = o
        self.summary.ran += 1
        self.summary.ran_ids.append(t.id)
        if not o.ok:
            self.summary.failed.append(t.id)
            if not self.bar.disable:
                self.bar.write(f"{t.id}: failed: {first_line(o.error)}")
        self.bar.update(1)
        f.release()


def _drop_superseded(db: CampaignDB, tasks: list[Task]) -> None:
    """Remove result rows of tasks the manifest no longer asks for (a removed shot or
    group): the tables hold the campaign as it now stands."""
    from cadra.campaign.database import RESULT_TABLES

    keys = [t.key for t in tasks]
    marks = ", ".join("?" for _ in keys)
    with db.conn:
        for table in RESULT_TABLES:
            db.conn.execute(f"DELETE FROM {table} WHERE task_key NOT IN ({marks})", keys)


def write_report(out: Path, name: str) -> Path:
    """The report page from the campaign's database (``report.html``)."""
    from cadra.report.campaign_page import write_campaign_page

    tables = read_tables(out)
    tables["tasks"] = tables["tasks"][tables["tasks"]["current"] == 1]
    return write_campaign_page(tables, out / REPORT, title=f"Campaign {name}",
                               overwrite=True)


__all__ = ["CampaignError", "RunSummary", "prepare_folder", "run_campaign", "write_report"]
