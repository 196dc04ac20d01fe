"""A campaign's task graph, each task keyed by the content of what it depends on.

A task's key is the SHA-256 of a canonical JSON text holding its kind, the task code's
version (its kind's in :data:`TASK_VERSIONS`, with the package's), the settings that change
its result and its inputs by content: a specification's parsed values and the files it
names (aero model, facility), a shot file's bytes and its images' bytes, a group's model
file, and the keys of the tasks it takes results from. So the same work is never done
twice, and a changed input reruns exactly the tasks downstream of it (docs/campaign.md,
"Resuming").

Tasks (their ids ``kind:name``): ``stage1:<shot>`` for every shot; ``calibrate:spheres``
from the sphere shots' stage one; ``single:<shot>`` for every test shot (after the
calibration, when there is one); per group ``multifit:<group>``, and from it
``holdone:<group>`` (when the group asks for a hold study), ``diagnose:<group>`` and
``bootstrap:<group>`` (when the group asks for one).
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from cadra.campaign.manifest import Manifest, ShotEntry

#: per kind, bumped when that kind's code changes what it returns for the same inputs (a
#: change to one kind reruns it and what takes its results, not the campaign's stage one)
TASK_VERSIONS = {"stage1": "2", "calibrate": "2", "single": "2", "multifit": "3",
                 "holdone": "3", "diagnose": "2", "bootstrap": "3"}


@dataclass(frozen=True)
class Task:
    kind: str
    name: str
    key: str
    payload: dict = field(repr=False)
    #: ids (kind:name) of the tasks whose outcomes it takes, in run_task's order (None: an
    #: optional input, the calibration, that the campaign does not have)
    inputs: tuple[str | None, ...] = ()

    @property
    def id(self) -> str:
        return f"{self.kind}:{self.name}"

    @property
    def upstream(self) -> tuple[str, ...]:
        return tuple(u for u in self.inputs if u)


def file_sha256(path: str | os.PathLike) -> str:
    """The SHA-256 of a file's bytes (read in 1 MiB blocks)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _key(obj) -> str:
    from cadra import __version__

    text = json.dumps({"code": [__version__, TASK_VERSIONS[obj["kind"]]], **obj},
                      sort_keys=True,
                      separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _model_hash(name_or_path: str, base_dir, hasher) -> str:
    from cadra.aero.model import resolve_model_path

    return hasher(resolve_model_path(name_or_path, base_dir))


def _facility_hash(name_or_path: str, base_dir, hasher) -> str:
    from cadra.io.facility_file import resolve_facility_path

    p = Path(name_or_path)
    if base_dir is not None and not p.is_absolute() and (Path(base_dir) / p).is_file():
        return hasher(Path(base_dir) / p)
    return hasher(resolve_facility_path(str(name_or_path)))


def shot_content(entry: ShotEntry, hasher: Callable[[Path], str] = file_sha256) -> dict:
    """What a shot's stage one depends on, by content."""
    if entry.spec is not None:
        base = Path(entry.spec_path).parent if entry.spec_path else None
        spec = dict(entry.spec)
        return {"spec": spec,
                "aero_model": _model_hash(str(spec.get("aero_model", "")), base, hasher),
                "facility": _facility_hash(str(spec.get("facility", "hffaf")), base, hasher)}
    from cadra.io.shotfile import load_shot_file

    sf = load_shot_file(entry.shot)
    images = sorted((str(st.station), view, hasher(Path(p)))
                    for st in sf.stations for view, p in st.images.items() if p)
    base = Path(entry.shot).parent
    return {"shot_file": hasher(Path(entry.shot)), "images": images,
            "facility": _facility_hash(sf.facility, base, hasher)}


def plan(manifest: Manifest, hasher: Callable[[Path], str] = file_sha256) -> list[Task]:
    """The campaign's tasks in an order where every task follows its inputs."""
    s = manifest.settings
    tasks: dict[str, Task] = {}

    def add(kind, name, payload, upstream, content):
        ups = tuple(upstream)
        key = _key({"kind": kind, "content": content,
                    "upstream": [tasks[u].key if u else None for u in ups]})
        t = Task(kind, name, key, payload, ups)
        tasks[t.id] = t
        return t

    for e in manifest.shots:
        add("stage1", e.shot_id, {"entry": e, "formation": s.formation}, (),
            {"shot": shot_content(e, hasher), "formation": s.formation})
    calib = None
    if manifest.spheres:
        calib = add("calibrate", "spheres", {}, [f"stage1:{e.shot_id}"
                                                 for e in manifest.spheres], {}).id
    fit_settings = {"max_iterations": s.max_iterations,
                    "bias_significance": s.bias_significance}
    single_model = (_model_hash(s.single_model, Path(manifest.path).parent, hasher)
                    if s.single_model else None)
    for e in manifest.test_shots:
        add("single", e.shot_id, {"shot_id": e.shot_id, "model": s.single_model,
                                  **fit_settings},
            [f"stage1:{e.shot_id}", calib], {"model": single_model, **fit_settings})
    for g in manifest.groups:
        content = {"model": _model_hash(g.model, Path(manifest.path).parent, hasher),
                   "hold": list(g.hold), "free": list(g.free), **fit_settings}
        fit = add("multifit", g.name, {"group": g, **fit_settings},
                  [calib, *(f"stage1:{sid}" for sid in g.shots)], content)
        if g.hold_study is not None:
            add("holdone", g.name, {"group": g, **fit_settings}, [fit.id],
                {"parameter": g.hold_study.parameter, "values": list(g.hold_study.values),
                 **fit_settings})
        if g.diagnose:
            add("diagnose", g.name, {"group": g}, [fit.id], {})
        if g.bootstrap:
            add("bootstrap", g.name, {"n": g.bootstrap, "noise": g.bootstrap_noise},
                [fit.id], {"n": g.bootstrap, "noise": g.bootstrap_noise})
    return list(tasks.values())


__all__ = ["TASK_VERSIONS", "Task", "file_sha256", "plan", "shot_content"]
