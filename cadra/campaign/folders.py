"""A task's report folder: drawn on the worker, written by the client.

The library's report writers (a shot's stage-one report and plots, a group fit's report, plots
and 3-D view, a hold study, a gap diagnosis) cost seconds of plotting each: 0.3 s a shot and
4 s a group fit. Drawn by the client, they made it a third process on two cores: a campaign
on two workers spent 18 % more worker time than on one (docs/campaign.md, "Speed and scale").
So the worker draws the folder into a scratch folder of its own and returns its files as
bytes (:class:`Folder`), and the client writes them, atomically, under the task's key-named
folder (:func:`write`). A folder whose outcome carries no files (an outcome stored before, a
folder removed since) is drawn by the client (:func:`render`). Nothing is written on the
worker beyond its scratch folder, which it removes.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

from cadra.atomic import OUTPUT_MARKER, atomic_output_dir


@dataclass(frozen=True)
class Folder:
    """A report folder's files (relative path -> bytes) and its output kind (the kind its
    :data:`cadra.atomic.OUTPUT_MARKER` names)."""

    kind: str
    files: dict[str, bytes]


def _draw(kind: str, name: str, value, out: Path) -> bool:
    """Write ``kind``'s folder for ``value`` at ``out`` with the library's writer; False for
    a kind without a drawn folder."""
    if kind == "stage1":
        from cadra.report.stage1 import write_stage1

        write_stage1(value["stage1"], out, truth=value["truth"])
    elif kind == "multifit":
        from cadra.campaign.tasks import first_line
        from cadra.report.fit import write_fit_outputs

        result = value["result"]
        write_fit_outputs(result, value["shots"], out, title=f"{name}: {result.model.name}",
                          notes=[f"not in this fit: {k} ({first_line(v)})"
                                 for k, v in value["missing"].items()])
    elif kind == "holdone":
        from cadra.report.studies import write_hold_one

        write_hold_one(value, str(value["held"].iloc[0]) if len(value) else "held", out)
    elif kind == "bootstrap":
        from cadra.report.studies import write_bootstrap

        write_bootstrap(value, name, out)
    elif kind == "diagnose":
        from cadra.report.gap import write_diagnosis

        write_diagnosis(value, value.fit_given, out, where_tables=value.where_tables)
    else:
        return False
    return True


def render(kind: str, name: str, value) -> Folder | None:
    """The task's folder drawn in a scratch folder and read back as bytes; None for a kind
    without one (a calibration's one small table is written by the client)."""
    with tempfile.TemporaryDirectory(prefix="cadra_folder_") as tmp:
        out = Path(tmp) / "folder"
        if not _draw(kind, name, value, out):
            return None
        marker = (out / OUTPUT_MARKER).read_text(encoding="utf-8")
        out_kind = marker.split("\n", 1)[0].removeprefix("kind:").strip() or "output"
        files = {p.relative_to(out).as_posix(): p.read_bytes()
                 for p in sorted(out.rglob("*")) if p.is_file() and p.name != OUTPUT_MARKER}
    return Folder(out_kind, files)


def write(path: Path, folder: Folder) -> Path:
    """Write ``folder`` at ``path`` (which must not exist), atomically."""
    with atomic_output_dir(path, kind=folder.kind) as tmp:
        for rel, data in folder.files.items():
            target = tmp / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(data)
    return path


def ensure(path: Path, kind: str, name: str, value, drawn: Folder | None) -> None:
    """The task's folder at ``path`` unless it exists: ``drawn`` (the worker's) if given,
    else drawn here."""
    if path.exists():
        return
    folder = drawn if drawn is not None else render(kind, name, value)
    if folder is not None:
        write(path, folder)


def run_drawn(kind: str, name: str, key: str, payload: dict, *upstream):
    """:func:`cadra.campaign.tasks.run_task`, then its folder drawn here, on the worker (what
    the campaign submits to Dask); the drawing's time counts in the task's. A folder that
    cannot be drawn is left to the client, which draws it again and reports what fails."""
    import time
    from dataclasses import replace

    from cadra import cores
    from cadra.campaign.tasks import run_task

    o = run_task(kind, name, key, payload, *upstream)
    if not o.ok:
        return o
    t0 = time.perf_counter()
    try:
        with cores.limit(1):
            folder = render(kind, name, o.value)
    except Exception:  # noqa: BLE001 - the client draws it again and reports what fails
        folder = None
    return replace(o, folder=folder, seconds=o.seconds + time.perf_counter() - t0)


__all__ = ["Folder", "ensure", "render", "run_drawn", "write"]
