"""Shot file: one shot's model, mass properties, range air, spark times and images.

A TOML file (schema in ``docs/shot_file.md``) in file units -- g, cm, g cm^2, torr, K, s --
read into a frozen :class:`ShotFile` in SI. Mass properties are in **model axes** M (x along the
symmetry axis toward the nose / heat shield, y port, z up with the model upright; seed 004
Table 2; docs/conventions.md): the cg is given from the body's reference point
(``cadra.body``; docs/bodies.md) and the inertia tensor about the cg.

Every error is a :class:`ShotFileError` naming the offending key (``mass.inertia_g_cm2: ...``).
:func:`save_shot` validates the complete file before writing anything and writes atomically
(temporary file + :func:`os.replace`); it refuses to overwrite unless asked.
"""

from __future__ import annotations

import json
import math
import os
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cadra import units
from cadra.atmosphere import Atmosphere
from cadra.atomic import atomic_write_text
from cadra.conventions import model_to_body_vector
from cadra.dynamics.modes import TestMode
from cadra.facility.reference import VIEW_AXES
from cadra.fields import frozen_array
from cadra.io.plain import plain
from cadra.io.toml_file import Fields, prefixed_by, read_toml

#: Current shot-file schema version.
SCHEMA_VERSION = 1
#: Model kinds ``cadra.body.body_from_spec`` builds.
MODEL_KINDS = ("sphere", "capsule", "cone", "bullet", "finner")

# Plausibility bounds: a value outside them is a unit error, not a range condition.
PRESSURE_TORR_RANGE = (0.01, 7600.0)      # 1.3 Pa .. 10 atm
TEMPERATURE_K_RANGE = (150.0, 400.0)
MASS_G_RANGE = (0.0, 1e5)                 # exclusive lower bound; 100 kg upper bound
CG_CM_MAX = 100.0                         # |cg offset| < 1 m
MODEL_LENGTH_CM_MAX = 100.0               # model dimensions < 1 m
VELOCITY_M_S_RANGE = (0.0, 2.0e4)
#: largest |inertia component| of a model, g cm^2: the heaviest model (MASS_G_RANGE, 100 kg)
#: at the largest size (1 m) has m L^2 = 1e9 g cm^2. Larger is a unit slip, and far larger
#: (1e308) would overflow the eigen-check
INERTIA_MAX_G_CM2 = 1e9
#: plausible mean density of a model, g/cm^3 (mass over the body's volume): hollow or foam
#: models ~0.1, plastics ~1, steel ~8, tungsten ~19 (osmium, the densest metal, 22.6). A mass
#: in kg written as grams, or a diameter 10x too large, lands below 0.1 (docs/shot_file.md)
DENSITY_G_CM3_RANGE = (0.1, 25.0)
#: plausible radius of gyration sqrt(I / m) of a model about a principal axis, as a fraction
#: of its largest dimension: a solid body's lies at ~0.05-0.6 of it (a cylinder about its
#: axis 0.35 d, a sphere 0.32 d, a long rod about a transverse axis 0.29 L); no mass lies
#: beyond the body, and a value 1e-3 of it is an inertia in kg m^2 written under the g cm^2
#: key (1 kg m^2 = 1e7 g cm^2)
GYRATION_FRACTION_RANGE = (0.01, 1.0)
#: Model-spec keys that are a size (must be > 0); other length keys need only |x| < 1 m.
MODEL_SIZE_KEYS = ("d", "diameter", "h", "length", "l")

_TOP_KEYS = ("schema_version", "shot_id", "facility", "notes", "nominal_velocity_m_s",
             "model", "mass", "range", "test_mode", "gun", "stations")
#: keys of the optional ``[gun]`` table: the launcher's rifling twist (one of the two units;
#: negative for a left-hand twist) and the muzzle velocity, or the muzzle spin itself
GUN_KEYS = ("twist_in_per_turn", "twist_m_per_turn", "muzzle_velocity_m_s",
            "muzzle_spin_rad_s")
#: accepted twists, m per turn (a 7-inch small-arms barrel to 30 calibres of a large gun)
TWIST_M_RANGE = (0.02, 20.0)
#: accepted muzzle spins, rad/s
SPIN_RAD_S_MAX = 2.0e5
#: keys of the optional ``[test_mode]`` table (file units; the pivot in model axes)
TEST_MODE_KEYS = ("kind", "stream_m_s", "pivot_from_cg_cm")
_INERTIA_COMPONENT_KEYS = {
    "Ixx_g_cm2": (0, 0), "Iyy_g_cm2": (1, 1), "Izz_g_cm2": (2, 2),
    "Ixy_g_cm2": (0, 1), "Ixz_g_cm2": (0, 2), "Iyz_g_cm2": (1, 2),
}


class ShotFileError(ValueError):
    """A shot file (or ShotFile object) that cannot be right; the message names the key."""


@dataclass(frozen=True, eq=False)
class MassProperties:
    """Measured mass properties, SI, model axes M (docs/conventions.md).

    Attributes
    ----------
    mass_kg : mass, kg.
    cg_model_m : (3,) nominal cg minus the body's reference point, model axes, m.
    inertia_model_kg_m2 : (3, 3) inertia tensor about the cg, model axes, kg m^2
        (``I_ij = integral (r^2 delta_ij - x_i x_j) dm``; off-diagonals are minus the products
        of inertia). ``I_B = D I_M D`` with ``D = diag(1, -1, -1)`` gives body axes.
    """

    mass_kg: float
    cg_model_m: np.ndarray
    inertia_model_kg_m2: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "mass_kg", float(self.mass_kg))
        object.__setattr__(self, "cg_model_m", frozen_array(self.cg_model_m, 3))
        object.__setattr__(self, "inertia_model_kg_m2",
                           frozen_array(self.inertia_model_kg_m2, (3, 3)))

    def __eq__(self, other):
        if not isinstance(other, MassProperties):
            return NotImplemented
        return (self.mass_kg == other.mass_kg
                and np.array_equal(self.cg_model_m, other.cg_model_m)
                and np.array_equal(self.inertia_model_kg_m2, other.inertia_model_kg_m2))

    __hash__ = None  # mutable-looking numpy contents: not hashable


@dataclass(frozen=True)
class Gun:
    """How the shot was launched, as far as its spin goes (SI; docs/shot_file.md).

    ``twist_m_per_turn``: the rifling's travel per turn (negative: left-hand), with
    ``muzzle_velocity_m_s`` the spin at the muzzle p = 2 pi V / twist; or
    ``muzzle_spin_rad_s`` given directly. The fit's start takes the spin from it
    (docs/spark_range.md): a spark range's stations cannot show a bullet's spin.
    """

    twist_m_per_turn: float | None = None
    muzzle_velocity_m_s: float | None = None
    muzzle_spin_rad_s: float | None = None

    def spin_rad_s(self, speed_m_s: float | None = None) -> float:
        """The muzzle spin, rad/s: given, or 2 pi V / twist with the muzzle velocity (or,
        without one, ``speed_m_s``, e.g. the speed measured in the range); NaN if unknown."""
        if self.muzzle_spin_rad_s is not None:
            return float(self.muzzle_spin_rad_s)
        v = self.muzzle_velocity_m_s if self.muzzle_velocity_m_s is not None else speed_m_s
        if self.twist_m_per_turn is None or v is None:
            return math.nan
        return 2.0 * math.pi * float(v) / float(self.twist_m_per_turn)


@dataclass(frozen=True)
class StationRecord:
    """One station of a shot: spark time (s, from the shot's reference epoch) and images.

    ``images`` maps view name (``"top"``, ``"side"``) to the image path as written in the
    file (relative to the shot file unless absolute).
    """

    station: int
    time_s: float
    images: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class ShotFile:
    """A loaded shot file, SI units (see module doc and docs/shot_file.md).

    Attributes
    ----------
    shot_id : e.g. ``"M2-2429"``.
    model : the body spec as ``cadra.body.body_from_spec`` takes it (file units, e.g.
        ``{"kind": "capsule", "preset": "M2", "d_cm": 3.556}``).
    mass : :class:`MassProperties` (SI, model axes).
    pressure_pa, temperature_k : range air.
    facility : facility reference-file name or path (:func:`cadra.io.facility_file.load_facility`).
    stations : per-station records, in increasing station id.
    notes : free text.
    source_path : the file this was read from (None if built in memory).
    nominal_velocity_m_s : optional nominal speed, m/s.
    test_mode : how the model was tested (:class:`cadra.dynamics.modes.TestMode`; default free
        flight in the range). A wind-tunnel record's "stations" are its camera frames.
    gun : the launcher's twist and muzzle velocity, or the muzzle spin (:class:`Gun`), or None.
    """

    shot_id: str
    model: dict
    mass: MassProperties
    pressure_pa: float
    temperature_k: float
    facility: str
    stations: tuple[StationRecord, ...]
    notes: str = ""
    source_path: str | None = None
    nominal_velocity_m_s: float | None = None
    test_mode: TestMode = field(default_factory=TestMode)
    gun: Gun | None = None

    def __post_init__(self):
        object.__setattr__(self, "stations", tuple(self.stations))

    def atmosphere(self, **kwargs) -> Atmosphere:
        """Range air (``Atmosphere.from_pt``; keyword options are passed on)."""
        return Atmosphere.from_pt(self.pressure_pa, self.temperature_k, **kwargs)

    def station(self, station: int) -> StationRecord:
        """The record of station id ``station`` (KeyError if the shot has none)."""
        for rec in self.stations:
            if rec.station == station:
                return rec
        raise KeyError(f"shot {self.shot_id}: no station {station}")

    @property
    def station_ids(self) -> tuple[int, ...]:
        return tuple(rec.station for rec in self.stations)

    @property
    def times_s(self) -> np.ndarray:
        """Spark times of :attr:`stations`, s."""
        return np.array([rec.time_s for rec in self.stations], dtype=float)

    def image_path(self, station: int, view: str) -> Path:
        """Path of the ``view`` image of ``station``, resolved relative to the shot file."""
        rec = self.station(station)
        if view not in rec.images:
            raise KeyError(f"shot {self.shot_id}: station {station} has no {view!r} image "
                           f"(has {sorted(rec.images)})")
        p = Path(rec.images[view])
        if not p.is_absolute() and self.source_path is not None:
            p = Path(self.source_path).parent / p
        return p


# --------------------------------------------------------------------------- validation


_F = Fields(ShotFileError)
_number, _in_range, _require, _check_unknown = _F.number, _F.in_range, _F.require, \
    _F.check_unknown
_table = _F.table


def _vector3(value, key: str) -> np.ndarray:
    return _F.vector(value, 3, key, " [x, y, z]")


def validate_model_spec(model, key: str = "model") -> dict:
    """Check a body spec: ``kind`` known, dimensions positive and plausible (cm scale).

    Keys ending in a length unit of :data:`cadra.units.UNITS` (``_cm``, ``_mm``, ``_m``)
    are lengths (finite, |x| < 1 m); the size keys ``d_*``, ``diameter_*``, ``h_*``,
    ``length_*``, ``l_*`` must be > 0. Angle keys (``_deg``, ``_rad``) must be finite numbers.
    Everything else is passed through for ``cadra.body``.
    """
    if not isinstance(model, Mapping):
        raise ShotFileError(f"{key}: expected a table, got {type(model).__name__}")
    model = dict(model)
    kind = _require(model, "kind", f"{key}.")
    if kind not in MODEL_KINDS:
        raise ShotFileError(f"{key}.kind: {kind!r} is not one of {list(MODEL_KINDS)}")
    for k, v in model.items():
        if k == "kind":
            continue
        length = units.split_unit_key(k, "length")
        if length is not None:
            x = _number(v, f"{key}.{k}")
            if length[0] in MODEL_SIZE_KEYS and not x > 0:
                raise ShotFileError(f"{key}.{k}: a model dimension must be > 0, got {v!r}")
            if abs(units.m_to_cm(units.to_si(x, length[1]))) >= MODEL_LENGTH_CM_MAX:
                raise ShotFileError(f"{key}.{k}: {v!r} is not a model dimension "
                                    f"(|x| < {MODEL_LENGTH_CM_MAX:g} cm; check the unit)")
        elif units.split_unit_key(k, "angle") is not None:
            _number(v, f"{key}.{k}")
    return model


def validate_inertia(inertia: np.ndarray, key: str) -> np.ndarray:
    """Symmetric, positive definite, principal moments satisfying the triangle inequalities;
    every component in g cm^2 with magnitude at most :data:`INERTIA_MAX_G_CM2` (checked
    first, so the numerics below never overflow)."""
    inertia = np.asarray(inertia, dtype=float)
    if inertia.shape != (3, 3) or not np.all(np.isfinite(inertia)):
        raise ShotFileError(f"{key}: expected a finite 3x3 tensor")
    scale = float(np.max(np.abs(inertia)))
    if scale > INERTIA_MAX_G_CM2:
        i, j = np.unravel_index(int(np.argmax(np.abs(inertia))), (3, 3))
        raise ShotFileError(f"{key}: component [{i}][{j}] = {inertia[i, j]:g} g cm^2 is not a "
                            f"model's moment of inertia (|I| <= {INERTIA_MAX_G_CM2:g} g cm^2, "
                            f"100 kg at 1 m; check the unit)")
    if scale == 0.0:
        raise ShotFileError(f"{key}: tensor is zero")
    if not np.allclose(inertia, inertia.T, rtol=0.0, atol=1e-9 * scale):
        raise ShotFileError(f"{key}: tensor is not symmetric")
    eig = np.linalg.eigvalsh(0.5 * (inertia + inertia.T))
    if eig[0] <= 0.0:
        raise ShotFileError(f"{key}: tensor is not positive definite (principal moments "
                            f"{eig.tolist()})")
    if eig[0] + eig[1] < eig[2] * (1.0 - 1e-9):
        raise ShotFileError(f"{key}: principal moments {eig.tolist()} violate the triangle "
                            f"inequality I1 + I2 >= I3 (no rigid body has them)")
    return inertia


def _mass_from_dict(mass: Mapping) -> MassProperties:
    known = {"mass_g", "cg_from_reference_cm", "inertia_g_cm2", *_INERTIA_COMPONENT_KEYS}
    _check_unknown(mass, known, "mass.")
    m_g = _number(_require(mass, "mass_g", "mass."), "mass.mass_g")
    if not m_g > 0:
        raise ShotFileError(f"mass.mass_g: must be positive, got {m_g!r}")
    _in_range(m_g, "mass.mass_g", *MASS_G_RANGE, "a model mass in grams")
    cg_cm = _vector3(_require(mass, "cg_from_reference_cm", "mass."), "mass.cg_from_reference_cm")
    if np.any(np.abs(cg_cm) >= CG_CM_MAX):
        raise ShotFileError(f"mass.cg_from_reference_cm: {cg_cm.tolist()} is not a cg offset "
                            f"in cm (|each| < {CG_CM_MAX:g}; check the unit)")
    components = [k for k in _INERTIA_COMPONENT_KEYS if k in mass]
    if "inertia_g_cm2" in mass:
        key = "mass.inertia_g_cm2"
        if components:
            raise ShotFileError(f"mass.{components[0]}: give either inertia_g_cm2 (tensor) or "
                                f"the Ixx_g_cm2 ... components, not both")
        raw = mass["inertia_g_cm2"]
        if (not isinstance(raw, list | tuple | np.ndarray) or len(raw) != 3
                or not all(isinstance(r, list | tuple | np.ndarray) and len(r) == 3
                           for r in raw)):
            raise ShotFileError(f"{key}: expected a 3x3 tensor [[Ixx, Ixy, Ixz], "
                                f"[Ixy, Iyy, Iyz], [Ixz, Iyz, Izz]]")
        inertia = np.array([[_number(v, f"{key}[{i}][{j}]") for j, v in enumerate(r)]
                            for i, r in enumerate(raw)])
    else:
        key = "mass.inertia_g_cm2"
        if not components:
            raise ShotFileError(f"{key}: missing (a 3x3 tensor, or Ixx_g_cm2, Iyy_g_cm2, "
                                f"Izz_g_cm2 [+ Ixy_g_cm2, Ixz_g_cm2, Iyz_g_cm2])")
        inertia = np.zeros((3, 3))
        for k, (i, j) in _INERTIA_COMPONENT_KEYS.items():
            if i == j:
                v = _number(_require(mass, k, "mass."), f"mass.{k}")
            else:
                v = _number(mass.get(k, 0.0), f"mass.{k}")
            inertia[i, j] = inertia[j, i] = v
        key = "mass.Ixx_g_cm2/Iyy_g_cm2/Izz_g_cm2"
    validate_inertia(inertia, key)
    return MassProperties(mass_kg=units.g_to_kg(m_g), cg_model_m=units.cm_to_m(cg_cm),
                          inertia_model_kg_m2=units.g_cm2_to_kg_m2(inertia))


#: largest plausible |time_s|: a range's spark times (a unit slip beyond), a wind-tunnel
#: record's frames (a free-to-roll run lasts tens of seconds)
MAX_TIME_S = {"range": 10.0, "tunnel": 3600.0}


def _stations_from_list(stations, max_time_s: float = MAX_TIME_S["range"]
                        ) -> tuple[StationRecord, ...]:
    if not isinstance(stations, list | tuple) or not stations:
        raise ShotFileError("stations: expected a non-empty array of tables "
                            "([[stations]] station = 1, time_s = ..., images = {...})")
    out = []
    for n, rec in enumerate(stations):
        where = f"stations[{n}]."
        if not isinstance(rec, Mapping):
            raise ShotFileError(f"stations[{n}]: expected a table")
        _check_unknown(rec, {"station", "time_s", "images"}, where)
        sid = _require(rec, "station", where)
        if isinstance(sid, bool) or not isinstance(sid, int | np.integer) or sid < 1:
            raise ShotFileError(f"{where}station: expected a station id (integer >= 1), "
                                f"got {sid!r}")
        t = _number(_require(rec, "time_s", where), f"{where}time_s")
        if abs(t) > max_time_s:
            raise ShotFileError(f"{where}time_s: {t!r} s is not a "
                                + ("spark time" if max_time_s <= MAX_TIME_S["range"]
                                   else "tunnel record's frame time")
                                + f" (|t| <= {max_time_s:g} s; check the unit: seconds)")
        images = rec.get("images", {})
        if not isinstance(images, Mapping):
            raise ShotFileError(f"{where}images: expected a table view = \"path\"")
        for view, path in images.items():
            if view not in VIEW_AXES:
                raise ShotFileError(f"{where}images.{view}: unknown view (known: "
                                    f"{', '.join(sorted(VIEW_AXES))})")
            if not isinstance(path, str) or not path.strip():
                raise ShotFileError(f"{where}images.{view}: expected a non-empty path string")
        out.append(StationRecord(station=int(sid), time_s=t, images=dict(images)))
    ids = [r.station for r in out]
    if len(set(ids)) != len(ids):
        dup = next(i for i in ids if ids.count(i) > 1)
        raise ShotFileError(f"stations: station {dup} appears more than once")
    out.sort(key=lambda r: r.station)
    for a, b in zip(out, out[1:], strict=False):
        if not b.time_s > a.time_s:
            n = ids.index(b.station)
            raise ShotFileError(f"stations[{n}].time_s: station {b.station} fires at "
                                f"{b.time_s!r} s, not after station {a.station} "
                                f"({a.time_s!r} s)")
    return tuple(out)


def _solid_volume_m3(body) -> float:
    """The body's volume, m^3: a body of revolution's, or a finned body's with its fins
    (:func:`cadra.body.finner_mass_properties` at unit density)."""
    from cadra.body import FinnedBody, finner_mass_properties
    from cadra.body.mass import solid_properties

    if isinstance(body, FinnedBody):
        return finner_mass_properties(body, 1.0).mass_kg
    return solid_properties(body, n_meridian=401).volume_m3


def _check_density(model: dict, mass: MassProperties) -> None:
    """The body must be buildable from ``model`` and ``mass_g`` over its volume a plausible
    density (:data:`DENSITY_G_CM3_RANGE`): catches kg written as g and size-unit slips."""
    from cadra.body import body_from_spec

    try:
        body = body_from_spec(model)
    except ValueError as exc:
        raise ShotFileError(f"model.{exc}") from None
    with np.errstate(all="ignore"):
        vol = float(np.pi / 6 * body.diameter_m**2 * body.length_m * 1e6)  # order of magnitude
        volume_cm3 = (_solid_volume_m3(body) * 1e6 if 1e-9 < vol < 1e9 else vol)
    if not 1e-9 < volume_cm3 < 1e9:
        raise ShotFileError(f"model: the body's volume, {volume_cm3:.3g} cm^3, is not a "
                            "model's (a dimension in the wrong unit?)")
    m_g = units.from_si(mass.mass_kg, "g")
    rho = m_g / volume_cm3
    lo, hi = DENSITY_G_CM3_RANGE
    if not lo <= rho <= hi:
        raise ShotFileError(
            f"mass.mass_g: {m_g:g} g in the model's {volume_cm3:.4g} "
            f"cm^3 is a density of {rho:.3g} g/cm^3, outside [{lo:g}, {hi:g}] -- a mass in kg "
            f"written as grams, or a model dimension in the wrong unit (model.*_cm)?")
    _check_gyration(body, mass)


def _check_gyration(body, mass: MassProperties) -> None:
    """Each principal radius of gyration within :data:`GYRATION_FRACTION_RANGE` of the body's
    largest dimension: catches an inertia in kg m^2 (or in g mm^2) under the g cm^2 keys."""
    size_cm = 100.0 * max(body.diameter_m, body.length_m)
    eig_g_cm2 = units.from_si(np.linalg.eigvalsh(mass.inertia_model_kg_m2), "g_cm2")
    m_g = units.from_si(mass.mass_kg, "g")
    lo, hi = GYRATION_FRACTION_RANGE
    for moment in (eig_g_cm2[0], eig_g_cm2[-1]):
        k_cm = float(np.sqrt(max(moment, 0.0) / m_g))
        if not lo * size_cm <= k_cm <= hi * size_cm:
            raise ShotFileError(
                f"mass.inertia_g_cm2: a principal moment of {moment:.4g} g cm^2 is a radius "
                f"of gyration of {k_cm:.3g} cm for {m_g:g} g, outside [{lo:g}, {hi:g}] x the "
                f"model's {size_cm:.3g} cm -- an inertia in kg m^2 (x 1e7 g cm^2) or another "
                f"unit under the g cm^2 keys?")


def shot_from_dict(data: Mapping, source_path: str | os.PathLike | None = None) -> ShotFile:
    """Validate a parsed shot file (file units) and build the SI :class:`ShotFile`."""
    if not isinstance(data, Mapping):
        raise ShotFileError("shot file: expected a table at top level")
    _check_unknown(data, _TOP_KEYS, "")
    version = _require(data, "schema_version")
    if version != SCHEMA_VERSION:
        raise ShotFileError(f"schema_version: {version!r} not supported (this CADRA reads "
                            f"version {SCHEMA_VERSION})")
    shot_id = _require(data, "shot_id")
    if not isinstance(shot_id, str) or not shot_id.strip():
        raise ShotFileError(f"shot_id: expected a non-empty string, got {shot_id!r}")
    facility = _require(data, "facility")
    if not isinstance(facility, str) or not facility.strip():
        raise ShotFileError(f"facility: expected a facility name or path, got {facility!r}")
    notes = data.get("notes", "")
    if not isinstance(notes, str):
        raise ShotFileError("notes: expected a string")
    model = validate_model_spec(_require(data, "model"))
    mass = _mass_from_dict(_table(data, "mass"))
    rng = _table(data, "range")
    _check_unknown(rng, {"pressure_torr", "temperature_k"}, "range.")
    p_torr = _number(_require(rng, "pressure_torr", "range."), "range.pressure_torr")
    _in_range(p_torr, "range.pressure_torr", *PRESSURE_TORR_RANGE, "a range pressure in torr")
    t_k = _number(_require(rng, "temperature_k", "range."), "range.temperature_k")
    _in_range(t_k, "range.temperature_k", *TEMPERATURE_K_RANGE, "a range temperature in K")
    v_nom = data.get("nominal_velocity_m_s")
    if v_nom is not None:
        v_nom = _in_range(_number(v_nom, "nominal_velocity_m_s"), "nominal_velocity_m_s",
                          *VELOCITY_M_S_RANGE, "a model speed in m/s")
    test_mode = _test_mode_from_dict(data.get("test_mode"))
    gun = gun_from_dict(data.get("gun"))
    stations = _stations_from_list(_require(data, "stations"),
                                   MAX_TIME_S["range" if test_mode.kind == "range" else "tunnel"])
    _check_density(model, mass)
    return ShotFile(shot_id=shot_id, model=model, mass=mass,
                    pressure_pa=units.torr_to_pa(p_torr), temperature_k=t_k,
                    facility=facility, stations=stations, notes=notes,
                    source_path=str(source_path) if source_path is not None else None,
                    nominal_velocity_m_s=v_nom, test_mode=test_mode, gun=gun)


def gun_from_dict(table) -> Gun | None:
    """A shot file's (or spec's) ``[gun]`` table in file units (absent: None)."""
    if table is None:
        return None
    if not isinstance(table, Mapping):
        raise ShotFileError("gun: expected a table")
    _check_unknown(table, set(GUN_KEYS), "gun.")
    if "twist_in_per_turn" in table and "twist_m_per_turn" in table:
        raise ShotFileError("gun.twist_in_per_turn: give the twist once (in or m per turn)")
    twist = None
    for key, to_m in (("twist_in_per_turn", units.M_PER_IN), ("twist_m_per_turn", 1.0)):
        if key in table:
            twist = _number(table[key], f"gun.{key}") * to_m
            if not TWIST_M_RANGE[0] <= abs(twist) <= TWIST_M_RANGE[1]:
                raise ShotFileError(
                    f"gun.{key}: {table[key]!r} is not a rifling twist (|twist| from "
                    f"{TWIST_M_RANGE[0]} to {TWIST_M_RANGE[1]} m per turn)")
    v = table.get("muzzle_velocity_m_s")
    if v is not None:
        v = _in_range(_number(v, "gun.muzzle_velocity_m_s"), "gun.muzzle_velocity_m_s",
                      *VELOCITY_M_S_RANGE, "a muzzle velocity in m/s")
    spin = table.get("muzzle_spin_rad_s")
    if spin is not None:
        spin = _number(spin, "gun.muzzle_spin_rad_s")
        if not 0 < abs(spin) <= SPIN_RAD_S_MAX:
            raise ShotFileError(f"gun.muzzle_spin_rad_s: {spin!r} is not a spin in rad/s "
                                f"(0 < |p| <= {SPIN_RAD_S_MAX:g})")
        if twist is not None:
            raise ShotFileError("gun.muzzle_spin_rad_s: give the spin or the twist, not both")
    if twist is None and spin is None:
        raise ShotFileError("gun: give the twist (twist_in_per_turn or twist_m_per_turn) or "
                            "the muzzle spin (muzzle_spin_rad_s)")
    return Gun(twist, v, spin)


def _test_mode_from_dict(table) -> TestMode:
    """The ``[test_mode]`` table (absent: free flight in the range)."""
    if table is None:
        return TestMode()
    if not isinstance(table, Mapping):
        raise ShotFileError("test_mode: expected a table")
    _check_unknown(table, set(TEST_MODE_KEYS), "test_mode.")
    kind = _require(table, "kind", "test_mode.")
    stream = _number(table.get("stream_m_s", 0.0), "test_mode.stream_m_s")
    if stream != 0.0:         # 0: still air (a range); TestMode says which kinds need one
        _in_range(stream, "test_mode.stream_m_s", *VELOCITY_M_S_RANGE,
                  "a stream speed in m/s")
    pivot = units.cm_to_m(_vector3(table.get("pivot_from_cg_cm", [0.0, 0.0, 0.0]),
                                   "test_mode.pivot_from_cg_cm"))
    if np.max(np.abs(pivot)) >= CG_CM_MAX / 100:
        raise ShotFileError(f"test_mode.pivot_from_cg_cm: {units.m_to_cm(pivot).tolist()} cm "
                            "is not a pivot on the model (|component| < 100 cm)")
    try:
        return TestMode(kind=str(kind), stream_m_s=stream,
                        pivot_from_cg_body_m=tuple(model_to_body_vector(pivot)))
    except ValueError as exc:
        raise ShotFileError(str(exc)) from None


def _toml(value):
    """``value`` as TOML holds it (a NaN or inf stays: TOML writes them)."""
    return plain(value, nonfinite_as_none=False)


def shot_to_dict(shot: ShotFile) -> dict:
    """The file-unit dictionary of a :class:`ShotFile` (what :func:`save_shot` writes)."""
    c = units.clean_float
    try:
        mass = shot.mass
        inertia = units.kg_m2_to_g_cm2(np.asarray(mass.inertia_model_kg_m2, dtype=float))
        cg = units.m_to_cm(np.asarray(mass.cg_model_m, dtype=float).reshape(3))
        mass_d = {
            "mass_g": c(units.kg_to_g(float(mass.mass_kg))),
            "cg_from_reference_cm": [c(v) for v in cg],
            "inertia_g_cm2": [[c(v) for v in row] for row in inertia.reshape(3, 3)],
        }
        p_torr = c(units.pa_to_torr(float(shot.pressure_pa)))
    except (TypeError, ValueError, AttributeError) as exc:
        raise ShotFileError(f"mass: cannot convert ({exc})") from None
    out = {
        "schema_version": SCHEMA_VERSION,
        "shot_id": shot.shot_id,
        "facility": shot.facility,
        "notes": shot.notes or "",
    }
    if shot.nominal_velocity_m_s is not None:
        out["nominal_velocity_m_s"] = _toml(shot.nominal_velocity_m_s)
    out["model"] = _toml(dict(shot.model))
    out["mass"] = mass_d
    out["range"] = {"pressure_torr": p_torr, "temperature_k": _toml(shot.temperature_k)}
    mode = shot.test_mode
    if mode.kind != "range":
        out["test_mode"] = {"kind": mode.kind, "stream_m_s": c(mode.stream_m_s)}
        if mode.mounted:
            pivot = units.m_to_cm(model_to_body_vector(np.array(mode.pivot_from_cg_body_m)))
            out["test_mode"]["pivot_from_cg_cm"] = [c(float(v)) for v in pivot]
    if shot.gun is not None:
        g = shot.gun
        out["gun"] = {k: c(float(v)) for k, v in (
            ("twist_m_per_turn", g.twist_m_per_turn),
            ("muzzle_velocity_m_s", g.muzzle_velocity_m_s),
            ("muzzle_spin_rad_s", g.muzzle_spin_rad_s)) if v is not None}
    out["stations"] = [{"station": _toml(r.station), "time_s": _toml(r.time_s),
                        "images": {str(k): str(v) for k, v in r.images.items()}}
                       for r in shot.stations]
    return out


# --------------------------------------------------------------------------- TOML text


def _toml_key(key: str) -> str:
    if key and all(ch.isalnum() or ch in "_-" for ch in key):
        return key
    return json.dumps(key, ensure_ascii=False)


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ShotFileError(f"cannot write non-finite number {value!r}")
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, Mapping):
        if not value:
            return "{}"
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}"
                                for k, v in value.items()) + " }"
    raise ShotFileError(f"cannot write {type(value).__name__} value {value!r} to TOML")


def dumps_shot(shot: ShotFile) -> str:
    """TOML text of ``shot`` (validated; raises :class:`ShotFileError` naming the key)."""
    data = shot_to_dict(shot)
    shot_from_dict(data)  # validate exactly what will be written
    lines = [
        "# CADRA shot file (docs/shot_file.md). Units are in the key names; mass properties",
        "# in model axes (x nose, y port, z up, model upright), cg from the body reference",
        "# point, inertia tensor about the cg. Image paths are relative to this file.",
    ]
    for k in ("schema_version", "shot_id", "facility", "notes", "nominal_velocity_m_s"):
        if k in data:
            lines.append(f"{k} = {_toml_value(data[k])}")
    for section in ("model", "mass", "range", "test_mode", "gun"):
        if section not in data:
            continue
        lines.append("")
        lines.append(f"[{section}]")
        for k, v in data[section].items():
            lines.append(f"{_toml_key(k)} = {_toml_value(v)}")
    for rec in data["stations"]:
        lines += ["", "[[stations]]", f"station = {rec['station']}",
                  f"time_s = {_toml_value(rec['time_s'])}",
                  f"images = {_toml_value(rec['images'])}"]
    text = "\n".join(lines) + "\n"
    if tomllib.loads(text) != data:  # the writer must be exact; never write what reads back wrong
        raise ShotFileError("internal error: shot file text does not read back identically")
    return text


def load_shot(path: str | os.PathLike) -> ShotFile:
    """Read and validate a shot file; errors are :class:`ShotFileError` naming the file and
    the key."""
    data = read_toml(path, ShotFileError)
    with prefixed_by(path, ShotFileError):
        return shot_from_dict(data, source_path=Path(path))


def save_shot(shot: ShotFile, path: str | os.PathLike, overwrite: bool = False) -> None:
    """Validate ``shot`` and write it to ``path`` atomically.

    Nothing is written if validation fails (:class:`ShotFileError`) or if ``path`` exists and
    ``overwrite`` is false (:class:`FileExistsError`).
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; refusing to overwrite (pass overwrite=True)")
    text = dumps_shot(shot)
    atomic_write_text(path, text, overwrite=overwrite)


__all__ = [
    "GUN_KEYS", "MODEL_KINDS", "SCHEMA_VERSION", "Gun", "MassProperties", "ShotFile",
    "ShotFileError", "StationRecord", "dumps_shot", "gun_from_dict", "load_shot", "save_shot",
    "shot_from_dict", "shot_to_dict", "validate_inertia", "validate_model_spec",
]
