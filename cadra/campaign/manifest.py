"""A campaign's manifest: the shots, the groups and what each group runs (docs/campaign.md).

A manifest is a TOML file::

    name = "seed004"

    [settings]                    # all optional
    max_iterations = 60           # stage two's iteration limit
    formation = "view"            # stage one's wire formation: once per "view" or per "image"
    bias_significance = 3.0       # apply a station bias only where |b| > 3 sigma

    [[shots]]
    spec = "../sample_shots/specs/m2_2429.toml"    # a shot specification: simulated, rendered
    [[shots]]
    id = "SPH-1"
    role = "sphere"                                # a calibration shot
    spec = { model = { kind = "sphere", d_cm = 2.0 }, ... }   # or a specification inline
    [[shots]]
    shot = "range/2431/shot.toml"                  # a real shot: its shot file and images

    [[groups]]
    name = "M2 M0.70"
    model = "m2_m070"                              # bundled name or a path
    shots = ["M2-2425", "M2-2426"]
    hold = ["Cmq_A2=3.65"]                         # optional, as cadra2 fit --hold takes them
    hold_study = { parameter = "Cmq_A2", values = [2.0, 3.0, 4.0] }   # optional (Fig. 15)
    diagnose = true                                # the gap diagnosis (default true)
    bootstrap = 200                                # optional: parametric bootstrap refits
    bootstrap_noise = "white"                      # or "residuals" (docs/fitting.md)

Paths are relative to the manifest's folder. A shot's id is its ``id``, else its
specification's ``shot_id``, else its shot file's. Every test shot (``role = "test"``, the
default) gets a single fit; sphere shots calibrate the stations, and the bias table they give
corrects every test shot before its fits. Errors are :class:`ManifestError` naming the key.
"""

from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from cadra.fields import Fields

#: what a shot is for
ROLES = ("test", "sphere")
#: the manifest's top-level keys, a shot's and a group's
_TOP = ("name", "settings", "shots", "groups", "facility")
_SHOT = ("id", "spec", "shot", "role")
_GROUP = ("name", "model", "shots", "hold", "free", "hold_study", "diagnose", "bootstrap",
          "bootstrap_noise")
_SETTINGS = ("max_iterations", "formation", "bias_significance", "single_model")


class ManifestError(ValueError):
    """A manifest that cannot be run; the message names the key."""


_F = Fields(ManifestError)


@dataclass(frozen=True)
class Settings:
    """Campaign-wide settings that change results (they enter every task's key)."""

    max_iterations: int = 60
    formation: str = "view"
    bias_significance: float = 3.0
    single_model: str | None = None      # None: the linear template for the body


@dataclass(frozen=True)
class ShotEntry:
    """One shot: a specification to simulate (``spec``, parsed) or a shot file (``shot``)."""

    shot_id: str
    role: str
    spec: dict | None = None
    spec_path: str | None = None         # the file the specification is in (its paths' base)
    shot: str | None = None              # absolute path of a shot file


@dataclass(frozen=True)
class HoldStudy:
    parameter: str
    values: tuple[float, ...]            # in the model file's unit (as cadra2 holdone takes)


@dataclass(frozen=True)
class Group:
    """Shots fitted together with one model, and what else runs on them."""

    name: str
    model: str                           # bundled name or absolute path
    shots: tuple[str, ...]
    hold: tuple[str, ...] = ()
    free: tuple[str, ...] = ()
    hold_study: HoldStudy | None = None
    diagnose: bool = True
    bootstrap: int = 0                   # parametric bootstrap refits (0: none)
    bootstrap_noise: str = "white"


@dataclass(frozen=True)
class Manifest:
    name: str
    path: str
    shots: tuple[ShotEntry, ...]
    groups: tuple[Group, ...]
    settings: Settings = field(default_factory=Settings)

    def shot(self, shot_id: str) -> ShotEntry:
        for s in self.shots:
            if s.shot_id == shot_id:
                return s
        raise KeyError(shot_id)

    @property
    def test_shots(self) -> tuple[ShotEntry, ...]:
        return tuple(s for s in self.shots if s.role == "test")

    @property
    def spheres(self) -> tuple[ShotEntry, ...]:
        return tuple(s for s in self.shots if s.role == "sphere")

    def group_of(self, shot_id: str) -> str:
        """The first group holding ``shot_id`` ("" if none)."""
        return next((g.name for g in self.groups if shot_id in g.shots), "")


def _resolve(base: Path, value, key: str) -> Path:
    text = _F.string(value, key, empty=False, what="a path")
    p = Path(text).expanduser()
    return (p if p.is_absolute() else base / p).resolve()


def _shot_entry(raw, k: int, manifest_path: Path) -> ShotEntry:
    base = manifest_path.parent
    where = f"shots[{k}]"
    raw = dict(_F.as_table(raw, where))
    _F.check_unknown(raw, _SHOT, f"{where}.")
    role = raw.get("role", "test")
    if role not in ROLES:
        raise _F.fail(f"{where}.role", f"{role!r} is not one of {list(ROLES)}")
    if ("spec" in raw) == ("shot" in raw):
        raise _F.fail(where, "give either spec (a specification to simulate) or shot (a shot "
                             "file with its images)")
    if "spec" in raw:
        spec_path = str(manifest_path)   # an inline specification's paths start here
        if isinstance(raw["spec"], dict):
            spec = dict(raw["spec"])
        else:
            path = _resolve(base, raw["spec"], f"{where}.spec")
            if not path.is_file():
                raise _F.fail(f"{where}.spec", f"no such file: {path}")
            with open(path, "rb") as fh:
                try:
                    spec = tomllib.load(fh)
                except tomllib.TOMLDecodeError as exc:
                    raise _F.fail(f"{where}.spec", f"{path}: {exc}") from None
            spec_path = str(path)
        sid = raw.get("id") or spec.get("shot_id") or (
            f"shot-{spec['seed004_shot']}" if "seed004_shot" in spec else "")
        if not sid:
            raise _F.fail(f"{where}.id", "missing (the specification has no shot_id)")
        spec.setdefault("shot_id", sid)
        return ShotEntry(shot_id=_F.string(sid, f"{where}.id", empty=False), role=role,
                         spec=spec, spec_path=spec_path)
    path = _resolve(base, raw["shot"], f"{where}.shot")
    if not path.is_file():
        raise _F.fail(f"{where}.shot", f"no such file: {path}")
    sid = raw.get("id")
    if not sid:
        from cadra.io.shotfile import load_shot_file

        sid = load_shot_file(path).shot_id
    return ShotEntry(shot_id=_F.string(sid, f"{where}.id", empty=False), role=role,
                     shot=str(path))


def _group(raw, k: int, base: Path, ids: set[str]) -> Group:
    where = f"groups[{k}]"
    raw = dict(_F.as_table(raw, where))
    _F.check_unknown(raw, _GROUP, f"{where}.")
    name = _F.string(_F.require(raw, "name", f"{where}."), f"{where}.name", empty=False)
    model = _F.string(_F.require(raw, "model", f"{where}."), f"{where}.model", empty=False)
    if model.endswith(".toml") or os.sep in model:
        model = str(_resolve(base, model, f"{where}.model"))
    shots = raw.get("shots")
    if not isinstance(shots, list) or not shots:
        raise _F.fail(f"{where}.shots", "expected a non-empty list of shot ids")
    for s in shots:
        if s not in ids:
            raise _F.fail(f"{where}.shots", f"no shot {s!r} in [[shots]]")
    if len(set(shots)) != len(shots):
        raise _F.fail(f"{where}.shots", "a shot is listed twice")
    study = None
    if "hold_study" in raw:
        hs = dict(_F.as_table(raw["hold_study"], f"{where}.hold_study"))
        _F.check_unknown(hs, ("parameter", "values"), f"{where}.hold_study.")
        values = hs.get("values")
        if not isinstance(values, list) or len(values) < 2:
            raise _F.fail(f"{where}.hold_study.values", "expected at least two values")
        study = HoldStudy(
            parameter=_F.string(_F.require(hs, "parameter", f"{where}.hold_study."),
                                f"{where}.hold_study.parameter", empty=False),
            values=tuple(_F.number(v, f"{where}.hold_study.values") for v in values))
    lists = {}
    for key in ("hold", "free"):
        value = raw.get(key, [])
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise _F.fail(f"{where}.{key}", "expected a list of strings")
        lists[key] = tuple(value)
    diagnose = raw.get("diagnose", True)
    if not isinstance(diagnose, bool):
        raise _F.fail(f"{where}.diagnose", "expected true or false")
    boot = raw.get("bootstrap", 0)
    if isinstance(boot, bool) or not isinstance(boot, int) or not (boot == 0 or boot >= 2):
        raise _F.fail(f"{where}.bootstrap", "expected a number of refits, 2 or more (0: none)")
    noise = raw.get("bootstrap_noise", "white")
    if noise not in ("white", "residuals"):
        raise _F.fail(f"{where}.bootstrap_noise", "expected \"white\" or \"residuals\"")
    return Group(name=name, model=model, shots=tuple(shots), hold_study=study,
                 diagnose=diagnose, bootstrap=boot, bootstrap_noise=noise, **lists)


def _settings(raw) -> Settings:
    raw = dict(_F.as_table(raw, "settings"))
    _F.check_unknown(raw, _SETTINGS, "settings.")
    s = Settings()
    formation = raw.get("formation", s.formation)
    if formation not in ("view", "image"):
        raise _F.fail("settings.formation", f"{formation!r} is not \"view\" or \"image\"")
    single = raw.get("single_model")
    return Settings(
        max_iterations=_F.integer(raw.get("max_iterations", s.max_iterations),
                                  "settings.max_iterations", 1),
        formation=formation,
        bias_significance=_F.positive(raw.get("bias_significance", s.bias_significance),
                                      "settings.bias_significance"),
        single_model=None if single is None else _F.string(single, "settings.single_model",
                                                           empty=False))


def manifest_from_dict(data: dict, path: str | os.PathLike) -> Manifest:
    """A :class:`Manifest` from parsed TOML; ``path`` is the manifest's file (its folder is
    where relative paths start)."""
    path = Path(path).resolve()
    base = path.parent
    data = dict(_F.as_table(data, "manifest"))
    _F.check_unknown(data, _TOP)
    name = _F.string(data.get("name", path.stem), "name", empty=False)
    raw_shots = data.get("shots")
    if not isinstance(raw_shots, list) or not raw_shots:
        raise _F.fail("shots", "expected at least one [[shots]] entry")
    shots = tuple(_shot_entry(s, k, path) for k, s in enumerate(raw_shots))
    ids = [s.shot_id for s in shots]
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        raise _F.fail("shots", f"shot id(s) given twice: {dup}")
    raw_groups = data.get("groups", [])
    if not isinstance(raw_groups, list):
        raise _F.fail("groups", "expected [[groups]] entries")
    groups = tuple(_group(g, k, base, set(ids)) for k, g in enumerate(raw_groups))
    names = [g.name for g in groups]
    if len(set(names)) != len(names):
        raise _F.fail("groups", "a group name is given twice")
    for g in groups:
        spheres = [s for s in g.shots if next(e for e in shots if e.shot_id == s).role
                   == "sphere"]
        if spheres:
            raise _F.fail("groups", f"{g.name}: sphere shot(s) {spheres} cannot join a "
                                    "multi-fit (they calibrate the stations)")
    return Manifest(name=name, path=str(path), shots=shots, groups=groups,
                    settings=_settings(data.get("settings", {})))


def load_manifest(path: str | os.PathLike) -> Manifest:
    """Read and check a campaign manifest; errors name the file and the key."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise ManifestError(f"{path}: no such manifest") from None
    except tomllib.TOMLDecodeError as exc:
        raise ManifestError(f"{path}: not TOML: {exc}") from None
    try:
        return manifest_from_dict(data, path)
    except ManifestError as exc:
        raise ManifestError(f"{path}: {exc}") from None


__all__ = ["Group", "HoldStudy", "Manifest", "ManifestError", "Settings", "ShotEntry",
           "load_manifest", "manifest_from_dict"]
