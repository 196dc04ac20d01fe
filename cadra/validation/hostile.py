"""Hostile inputs against the command lines (the figures of ``tools/hostile.py``).

Every case is a real ``cadra1``/``cadra2`` process run under a timeout, in a work folder of
inputs built first (:func:`make_work`: a two-station shot with images, stage-one folders of an
M2 and a sphere shot made from their truth, a station history recorded by a calibration, a
model file of the user's). Every input tree is hashed before and after each case, and so are
the repository's facility files, bundled models and default station history (a history may
grow by an append, its old bytes first; nothing may be lost or changed); of numba's cache the
file list is kept (numba may add to it, never lose from it). The cases
(:func:`cases`):

- **image headers**: a PNG claiming 100000 x 100000 px, one claiming 4000 x 3000, an empty
  file, a truncated one, a link to itself, a folder where an image belongs, a 16-bit and a
  colour image where 8-bit grey is declared, a text file; ``cadra1`` on the shot and
  ``cadra1 --check``: the station fails (status 1), no traceback, no hang;
- **option values**: every numeric option of every command with a negative, zero, NaN,
  infinite, absurd or non-numeric value: a usage error (status 2) naming the option;
- **output paths**: every input kind (the station history's file, its folder, ``stations/``,
  the stations root; numba's cache folder and its base; an image, the images folder, the shot
  folder and file; a trajectory file and its stage-one folder; a model file of the user's,
  the bundled models' folder; the facilities folder; the working folder) as the output of
  ``fit``, ``calibrate``, ``simulate`` and ``cadra1``, with ``--overwrite``, the history's
  root from the option, the environment and the default: refused (status 1 or 2), nothing
  written.

A case fails if it raised (a Python traceback on stderr), hung (the timeout), changed an
input, or ended otherwise than expected. :func:`run` returns the figures: ``cases``,
``uncaught``, ``hangs``, ``input_changes``, ``unexpected`` and the failed cases' names.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import struct
import subprocess
import sys
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cadra.facility.reference import REPO_ROOT

#: seconds a case may take before it counts as a hang
TIMEOUT_S = 300.0
SPEC = REPO_ROOT / "sample_shots" / "specs" / "m2_2429.toml"


@dataclass(frozen=True)
class Case:
    """One hostile run: its name, the program (``cadra1``/``cadra2``) and arguments, the
    environment's changes, and the exit statuses that are right for it."""

    name: str
    prog: str
    argv: tuple[str, ...]
    expect: tuple[int, ...]
    env: dict = field(default_factory=dict)


def _png_claiming(width: int, height: int) -> bytes:
    """A few rows of a grey PNG whose header claims ``width`` x ``height`` px."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8,
                                                              0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"\x00" * (4 * (width + 1)))) + chunk(b"IEND", b""))


def make_work(base: Path) -> dict[str, Path]:
    """The inputs the cases aim at, under ``base`` (created): returns name -> path."""
    from cadra.synthetic.simulate import load_shot_spec, simulate_shot, write_shot
    from cadra.validation.truth_files import write_trajectory_file

    base.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(17)
    spec = dataclasses.replace(load_shot_spec(SPEC), n_stations=2)
    write_shot(simulate_shot(spec), base / "shot", images=True, progress=False)
    for name, spec_file in (("m2", SPEC), ("sphere", SPEC.with_name("sphere_1.toml"))):
        sim = simulate_shot(load_shot_spec(spec_file))
        write_shot(sim, base / name, images=False, progress=False)
        (base / f"{name}_stage1").mkdir()
        write_trajectory_file(sim, base / name / "shot.toml",
                              base / f"{name}_stage1" / "trajectory.csv", rng)
    root = base / "root"
    done = subprocess.run([sys.executable, "-m", "cadra.cli.cadra2", "calibrate",
                           str(base / "sphere_stage1"), "-o", str(base / "calibration"),
                           "--stations-root", str(root), "-q"], capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"the work folder's calibration failed: {done.stderr.strip()}")
    (base / "models").mkdir()
    shutil.copy(REPO_ROOT / "cadra" / "aero" / "models" / "m2_m070.toml",
                base / "models" / "mine.toml")
    return {"base": base, "shot": base / "shot", "m2_stage1": base / "m2_stage1",
            "sphere_stage1": base / "sphere_stage1", "root": root,
            "model": base / "models" / "mine.toml"}


def _image_cases(work: dict) -> list[Case]:
    """Each bad image in a copy of the shot; ``cadra1`` and ``cadra1 --check``."""
    import cv2

    base, shot = work["base"], work["shot"]
    grey = cv2.imread(str(shot / "images" / "st01_top.png"), cv2.IMREAD_UNCHANGED)
    bad = {"header_100000px": _png_claiming(100_000, 100_000),
           "header_4000x3000": _png_claiming(4000, 3000), "empty": b"",
           "truncated": (shot / "images" / "st01_top.png").read_bytes()[:5000],
           "text": b"not an image\n",
           "16_bit": cv2.imencode(".png", grey.astype(np.uint16) * 257)[1].tobytes(),
           "colour": cv2.imencode(".png", np.dstack([grey] * 3))[1].tobytes()}
    out = []
    for kind in (*bad, "link_loop", "folder"):
        copy = base / "images" / kind
        shutil.copytree(shot, copy)
        img = copy / "images" / "st01_top.png"
        img.unlink()
        if kind == "link_loop":
            img.symlink_to(img.name)
        elif kind == "folder":
            img.mkdir()
        else:
            img.write_bytes(bad[kind])
        out.append(Case(f"image {kind}: cadra1", "cadra1",
                        (str(copy / "shot.toml"), "-o", str(base / "image_out" / kind), "-q",
                         "--workers", "2", "--no-overlays"), (1,)))
        out.append(Case(f"image {kind}: cadra1 --check", "cadra1",
                        ("--check", str(copy / "shot.toml")), (1,)))
    return out


#: per command: its data arguments and its numeric options' bad values
_OPTIONS = {
    ("cadra2", "fit"): ("--model", "m2_m070", {
        "--max-iterations": ("-5", "0", "nan", "abc"),
        "--sigma-time-s": ("-1", "nan", "inf", "1e300"),
        "--min-sigma-position-m": ("-1", "nan", "1e300"),
        "--min-sigma-angle-deg": ("-1", "nan", "1e300")}),
    ("cadra2", "diagnose"): ("--model", "m2_m070", {"--alpha": ("0", "2", "nan")}),
    ("cadra2", "calibrate"): (None, None, {"--threshold-sigma": ("0", "-1", "nan")}),
    ("cadra2", "motion"): (None, None, {"--window": ("1", "-3"), "--step": ("0",),
                                        "--path-degree": ("-1", "99"),
                                        "--spin": ("nan", "inf")}),
    ("cadra2", "roll"): (None, None, {"--alpha-deg": ("95", "nan"), "--window": ("2",)}),
}


def _option_cases(work: dict) -> list[Case]:
    out = []
    for (prog, command), (flag, value, options) in _OPTIONS.items():
        data = str(work["sphere_stage1" if command == "calibrate" else "m2_stage1"])
        extra = (flag, value) if flag else ()
        for option, values in options.items():
            for v in values:
                out.append(Case(f"{command} {option} {v}", prog,
                                (command, data, *extra, "-o", str(work["base"] / "never"),
                                 f"{option}={v}"), (2,)))
    for v in ("0", "-2", "abc"):
        out.append(Case(f"cadra1 --workers {v}", "cadra1",
                        (str(work["shot"] / "shot.toml"), "-o", str(work["base"] / "never"),
                         f"--workers={v}"), (2,)))
    return out


def _output_cases(work: dict) -> list[Case]:
    """Every input kind as the output, from every root source of the station history."""
    from cadra.calibration.history import history_path

    base, root = work["base"], work["root"]
    cache = Path(os.environ.get("NUMBA_CACHE_DIR", base / "no-cache"))
    kinds = {"images": work["shot"] / "images", "image": work["shot"] / "images" /
             "st01_top.png", "shot folder": work["shot"], "shot file": work["shot"] /
             "shot.toml", "trajectory": work["m2_stage1"] / "trajectory.csv",
             "stage-one folder": work["m2_stage1"], "model file": work["model"],
             "model folder": work["model"].parent, "bundled models": REPO_ROOT / "cadra" /
             "aero" / "models", "facilities": REPO_ROOT / "facilities",
             "numba cache": cache, "numba cache base": cache.parent, "working folder": base}
    out = []
    fit = ("fit", str(work["m2_stage1"]), "--model", str(work["model"]))
    for kind, path in kinds.items():
        for prog, argv in (("cadra2", fit), ("cadra2", ("calibrate",
                                                         str(work["sphere_stage1"]),
                                                         "--stations-root", str(root))),
                           ("cadra2", ("simulate", str(work["shot"] / "spec.toml")
                                       if (work["shot"] / "spec.toml").is_file()
                                       else str(SPEC))),
                           ("cadra1", (str(work["shot"] / "shot.toml"),))):
            out.append(Case(f"{kind} as the output of {prog} {argv[0]}", prog,
                            (*argv, "-o", str(path), "--overwrite"), (1, 2)))
    for source, roots in (("option", root), ("environment", root), ("default", None)):
        r = root if roots is not None else REPO_ROOT
        hist = history_path(r, "hffaf")
        env = {"CADRA_STATIONS_ROOT": str(root)} if source == "environment" else {}
        given = ("--stations-root", str(root)) if source == "option" else ()
        for kind, path in (("history file", hist), ("history folder", hist.parent),
                           ("stations folder", hist.parent.parent), ("stations root", r)):
            for argv in (("fit", str(work["m2_stage1"]), "--model", "m2_m070",
                          "--bias-table", "current", *given),
                         ("calibrate", str(work["sphere_stage1"]), *given, "--no-history")):
                out.append(Case(f"{kind} ({source} root) as the output of {argv[0]}",
                                "cadra2", (*argv, "-o", str(path), "--overwrite"), (1, 2),
                                env))
    return out


def cases(work: dict) -> list[Case]:
    return _image_cases(work) + _option_cases(work) + _output_cases(work)


def _snapshot(root: Path) -> dict[str, bytes]:
    """Every path under ``root`` (or the file itself) -> its bytes (a link: its target)."""
    if root.is_file():
        return {"": root.read_bytes()}
    out = {}
    for p in sorted(root.rglob("*")) if root.exists() else []:
        key = str(p.relative_to(root))
        out[key] = (os.readlink(p).encode() if p.is_symlink() else
                    p.read_bytes() if p.is_file() else b"<dir>")
    return out


def _changed(before: dict, after: dict, append_only: bool) -> bool:
    """Whether a tree lost or changed anything (``append_only``: a file that grew with its
    old bytes first, as a station history grows, is not a change; new files are not)."""
    for k, v in before.items():
        new = after.get(k)
        if new is None or (new != v and not (append_only and new.startswith(v))):
            return True
    return not append_only and set(after) != set(before)


def _inputs(work: dict) -> dict[str, dict]:
    """Snapshots of every input tree: the work folder's inputs and the repository's."""
    trees = {k: work[k] for k in ("shot", "m2_stage1", "sphere_stage1", "root", "model")}
    trees.update({"facilities": REPO_ROOT / "facilities",
                  "bundled models": REPO_ROOT / "cadra" / "aero" / "models",
                  "default stations": REPO_ROOT / "stations",
                  "images": work["base"] / "images"})
    return {k: _snapshot(p) for k, p in trees.items()}


def _cache_files() -> set[str]:
    folder = os.environ.get("NUMBA_CACHE_DIR")
    return ({str(p) for p in Path(folder).rglob("*")} if folder and Path(folder).exists()
            else set())


def run_case(case: Case, cwd: Path) -> dict:
    """Run one case: its exit status, whether it raised or hung."""
    module = "cadra.cli.cadra1" if case.prog == "cadra1" else "cadra.cli.cadra2"
    env = {**os.environ, **case.env}
    if "CADRA_STATIONS_ROOT" not in case.env:
        env.pop("CADRA_STATIONS_ROOT", None)
    try:
        p = subprocess.run([sys.executable, "-m", module, *case.argv], cwd=cwd, env=env,
                           capture_output=True, text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        return {"name": case.name, "hang": True, "uncaught": False, "code": None}
    return {"name": case.name, "hang": False, "code": p.returncode,
            "uncaught": "Traceback (most recent call last)" in p.stderr,
            "stderr": p.stderr.strip().splitlines()[-1:] if p.stderr.strip() else []}


def run(base: Path, progress: bool = True) -> dict:
    """Build the inputs under ``base``, run every case, return the figures."""
    from tqdm import tqdm

    work = make_work(base)
    all_cases = cases(work)
    before, cache_before = _inputs(work), _cache_files()
    rows = []
    for case in tqdm(all_cases, desc="hostile", disable=not progress):
        row = run_case(case, work["base"])
        after = _inputs(work)
        changed = sorted(k for k in before if _changed(before[k], after[k],
                                                       append_only=k in ("root",
                                                                         "default stations")))
        lost = cache_before - _cache_files()
        row["changed"] = changed + (["numba cache"] if lost else [])
        row["unexpected"] = (not row["hang"] and row["code"] not in case.expect)
        rows.append(row)
        before = after
    bad = [r for r in rows if r["hang"] or r["uncaught"] or r["changed"] or r["unexpected"]]
    return {"cases": len(rows), "uncaught": sum(r["uncaught"] for r in rows),
            "hangs": sum(r["hang"] for r in rows),
            "input_changes": sum(bool(r["changed"]) for r in rows),
            "unexpected": sum(r["unexpected"] for r in rows),
            "image_cases": sum(r["name"].startswith("image ") for r in rows),
            "option_cases": sum(" as the output of " not in r["name"]
                                and not r["name"].startswith("image ") for r in rows),
            "output_cases": sum(" as the output of " in r["name"] for r in rows),
            "failed": [{k: r[k] for k in ("name", "code", "hang", "uncaught", "changed")}
                       | {"stderr": r.get("stderr", [])} for r in bad]}


__all__ = ["Case", "TIMEOUT_S", "cases", "make_work", "run", "run_case"]
