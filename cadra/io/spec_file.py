"""Shot specifications: the simulator's input file, read and validated (docs/simulation.md).

A specification (TOML) names the model, its mass properties and range conditions (or a
seed-004 shot whose Tables 2/3 rows supply them), the aerodynamic model used as truth, the
launch, optional effects, optional per-station biases and the render settings. It is read into
a frozen :class:`ShotSpec` in SI; :mod:`cadra.synthetic.simulate` flies it. Errors are
:class:`SpecError` naming the key (``mass.mass_g: must be positive``); :func:`load_shot_spec`
puts the file's path in front.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from cadra import units
from cadra.body import body_from_spec
from cadra.dynamics.effects import Effects
from cadra.dynamics.setup import DT_MAX_TRUTH
from cadra.dynamics.trajectory import Launch
from cadra.io.seed004 import load_seed004_table
from cadra.io.shotfile import (
    INERTIA_MAX_G_CM2,
    Gun,
    ShotFileError,
    gun_from_dict,
    validate_inertia,
)
from cadra.io.toml_file import Fields, prefixed_by, read_toml

#: keys of one station's entry in ``[station_biases]`` (m, m, m, s), in this order
BIAS_KEYS = ("x_m", "y_m", "z_m", "time_s")
#: plausibility limits of an injected bias: each position component (m), the time (s)
BIAS_POSITION_MAX_M = 0.01
BIAS_TIME_MAX_S = 1e-4
#: how the gun may be aimed (``"centre"``: slanted so the path stays centred in view)
AIMS = ("none", "centre")

_TOP_KEYS = ("shot_id", "seed004_shot", "model", "mass", "range", "aero_model", "aero_values",
             "launch", "effects", "facility", "n_stations", "trigger", "film", "render", "seed",
             "dt_max_s", "aim", "station_biases", "gun")
_MASS_KEYS = ("mass_g", "x_cg_from_base_cm", "x_cg_from_ref_cm", "y_cg_cm", "z_cg_cm",
              "inertia_g_cm2", "uniform_density_g_cm3")
_TRIGGER_KEYS = ("offset_mean_m", "offset_sd_m")


class SpecError(ValueError):
    """A shot specification that cannot be simulated; the message names the key."""


_F = Fields(SpecError)


@dataclass(frozen=True)
class FilmPlacement:
    """Per-image random placement of the film/scan relative to the nominal image map (1-sigma).

    Stage one must solve each image's map from its fiducial wires; this makes that necessary.
    """

    shift_px: float = 4.0
    rotation_deg: float = 0.05
    scale_rel: float = 5e-4


@dataclass(frozen=True)
class ShotSpec:
    """Everything that defines a synthetic shot (SI inside; see docs/simulation.md)."""

    shot_id: str
    model: dict
    mass_kg: float
    cg_model_m: tuple[float, float, float]          # nominal cg minus reference point, model axes
    inertia_model_kg_m2: tuple                      # 3x3 about the cg, model axes
    pressure_pa: float
    temperature_k: float
    aero_model: str
    launch: Launch
    effects: Effects = field(default_factory=Effects)
    aero_values: dict = field(default_factory=dict)  # parameter overrides (SI)
    facility: str = "hffaf"
    n_stations: int | None = None
    trigger_offset_mean_m: float = 0.004
    trigger_offset_sd_m: float = 0.002
    film: FilmPlacement = field(default_factory=FilmPlacement)
    render: dict = field(default_factory=dict)
    seed: int = 0
    dt_max_s: float = DT_MAX_TRUTH
    source_path: str | None = None
    seed004_shot: int | None = None
    aim: str = "none"            # "centre": slant the gun so the path stays centred in view
    # injected biases: station id -> (x_m, y_m, z_m, time_s); absent = unbiased
    station_biases: dict = field(default_factory=dict)
    # the launcher's twist and muzzle velocity, written into the shot file's [gun] (the
    # reduction's spin; the flight itself spins at launch.p_rad_s)
    gun: Gun | None = None


def load_shot_spec(path: str | os.PathLike) -> ShotSpec:
    """Read a shot specification TOML; errors name the file and the offending key."""
    data = read_toml(path, SpecError)
    with prefixed_by(path, SpecError):
        return spec_from_dict(data, source_path=Path(path))


def _get(d, key: str, where: str) -> float:
    """A required number ``d[key]``."""
    return _F.number(_F.require(d, key, where), f"{where}{key}")


def _optional(d, key: str, where: str, default: float) -> float:
    return _F.number(d[key], f"{where}{key}") if key in d else default


def _table(data, key: str) -> dict:
    return dict(_F.table(data, key, required=False))


def spec_from_dict(data: dict, source_path: Path | None = None) -> ShotSpec:
    """Build a :class:`ShotSpec` from plain data (file units: see docs/simulation.md)."""
    data = dict(_F.as_table(data, "shot specification"))
    _F.check_unknown(data, _TOP_KEYS)
    row = None
    if "seed004_shot" in data:
        shot = _F.integer(data["seed004_shot"], "seed004_shot", 1)
        table = load_seed004_table()
        hit = table[table["shot"] == shot]
        if hit.empty:
            raise _F.fail("seed004_shot", f"no shot {shot} in Tables 2/3")
        row = hit.iloc[0]
    model = _table(data, "model")
    if not model:
        raise _F.fail("model", "missing (e.g. {kind = \"capsule\", preset = \"M2\"})")
    if row is not None and model.get("kind") == "capsule":
        model.setdefault("d_cm", float(row["d_cm"]))
        model.setdefault("h_cm", float(row["h_cm"]))
    try:
        body = body_from_spec(model)
    except ValueError as exc:
        raise _F.fail("model", str(exc)) from None
    mass_kg, cg_model, inertia = _mass(_uniform_solid(_table(data, "mass"), body), row,
                                       body.base_s_m)
    p_pa, t_k = _range(_table(data, "range"), row)
    launch = _launch(_table(data, "launch"), row)
    try:
        effects = Effects.from_dict(data.get("effects"))
    except ValueError as exc:
        raise SpecError(str(exc)) from None
    aero_model = _F.string(_F.require(data, "aero_model"), "aero_model", empty=False,
                           what="a bundled name such as \"m2_m070\" or a path")
    trig = _table(data, "trigger")
    _F.check_unknown(trig, _TRIGGER_KEYS, "trigger.")
    film = _table(data, "film")
    _F.check_unknown(film, [f.name for f in fields(FilmPlacement)], "film.")
    film_placement = FilmPlacement(**{k: _F.number(v, f"film.{k}") for k, v in film.items()})
    aero_values = {}
    for k, v in _table(data, "aero_values").items():
        x = _F.number(v, f"aero_values.{k}")
        aero_values[k[:-4] if k.endswith("_deg") else k] = (
            units.to_si(x, "deg") if k.endswith("_deg") else x)
    shot_id = data.get("shot_id") or (f"{row['model']}-{int(row['shot'])}"
                                      if row is not None else "")
    return ShotSpec(
        shot_id=_F.string(shot_id, "shot_id") or "shot",
        model=body.to_spec(), mass_kg=mass_kg, cg_model_m=cg_model,
        inertia_model_kg_m2=tuple(map(tuple, inertia)), pressure_pa=p_pa, temperature_k=t_k,
        aero_model=aero_model, launch=launch, effects=effects,
        aero_values=aero_values,
        facility=_F.string(data.get("facility", "hffaf"), "facility", empty=False,
                           what="a facility name or path"),
        n_stations=(_F.integer(data["n_stations"], "n_stations", 1)
                    if "n_stations" in data else None),
        trigger_offset_mean_m=_optional(trig, "offset_mean_m", "trigger.", 0.004),
        trigger_offset_sd_m=_optional(trig, "offset_sd_m", "trigger.", 0.002),
        film=film_placement, render=_table(data, "render"),
        seed=_F.integer(data.get("seed", 0), "seed", 0),
        dt_max_s=(_F.positive(data["dt_max_s"], "dt_max_s") if "dt_max_s" in data
                  else DT_MAX_TRUTH),
        source_path=str(source_path) if source_path else None,
        seed004_shot=int(row["shot"]) if row is not None else None,
        aim=_aim(data.get("aim", "none")),
        station_biases=_station_biases(data.get("station_biases")),
        gun=_gun(data.get("gun")),
    )


def _gun(table) -> Gun | None:
    try:
        return gun_from_dict(table)
    except ShotFileError as exc:
        raise SpecError(str(exc)) from None


def _uniform_solid(mass: dict, body) -> dict:
    """``[mass]`` with ``uniform_density_g_cm3`` replaced by the uniform solid's mass, axial cg
    and inertia (:func:`cadra.body.finner_mass_properties` for a finned body, else
    :func:`cadra.body.mass.solid_properties`; on the axis, so y, z of the cg are 0). The
    density excludes the other mass keys (a model is either measured or a uniform solid)."""
    if "uniform_density_g_cm3" not in mass:
        return mass
    others = sorted(set(mass) - {"uniform_density_g_cm3"})
    if others:
        raise _F.fail(f"mass.{others[0]}", "give either uniform_density_g_cm3 (a uniform "
                                           "solid of the model's geometry) or the mass keys")
    rho_g_cm3 = _F.positive(mass["uniform_density_g_cm3"], "mass.uniform_density_g_cm3")
    rho_kg_m3 = units.g_to_kg(rho_g_cm3) / units.cm_to_m(1.0) ** 3
    from cadra.body import FinnedBody, finner_mass_properties
    from cadra.body.mass import solid_properties

    if isinstance(body, FinnedBody):
        mp = finner_mass_properties(body, rho_kg_m3)
        m, cg, inertia = mp.mass_kg, mp.cg_s_m, np.diag(mp.inertia_kg_m2)
    else:
        sp = solid_properties(body, rho_kg_m3)
        m, cg = sp.mass_kg, sp.centroid_s_m
        inertia = np.array([sp.ixx_kg_m2, sp.itrans_kg_m2, sp.itrans_kg_m2])
    # body-axis diagonal = model-axis diagonal (I_M = D I_B D, D = diag(1, -1, -1))
    return {"mass_g": units.kg_to_g(m), "x_cg_from_ref_cm": units.m_to_cm(cg),
            "inertia_g_cm2": [float(units.kg_m2_to_g_cm2(i)) for i in inertia]}


def _mass(mass: dict, row, base_s_m: float) -> tuple[float, tuple, np.ndarray]:
    """Mass (kg), cg from the reference point (m, model axes), inertia (kg m^2) of ``[mass]``,
    the seed-004 Table 2 ``row`` (if any) filling what is not given."""
    _F.check_unknown(mass, _MASS_KEYS, "mass.")
    if "x_cg_from_base_cm" in mass and "x_cg_from_ref_cm" in mass:
        raise _F.fail("mass.x_cg_from_ref_cm", "give x_cg_from_base_cm or x_cg_from_ref_cm, "
                                               "not both")
    if row is not None:
        mass.setdefault("mass_g", float(row["mass_g"]))
        if "x_cg_from_ref_cm" not in mass:
            mass.setdefault("x_cg_from_base_cm", float(row["x_cg_from_base_cm"]))
        mass.setdefault("y_cg_cm", float(row["y_cg_cm"]))
        mass.setdefault("z_cg_cm", float(row["z_cg_cm"]))
        mass.setdefault("inertia_g_cm2", [float(row["Ixx_g_cm2"]), float(row["Iyy_g_cm2"]),
                                          float(row["Izz_g_cm2"])])
    mass_kg = units.g_to_kg(_F.positive(_F.require(mass, "mass_g", "mass."), "mass.mass_g"))
    if "x_cg_from_base_cm" in mass:
        x_cg = base_s_m + units.cm_to_m(_get(mass, "x_cg_from_base_cm", "mass."))
    else:
        x_cg = units.cm_to_m(_get(mass, "x_cg_from_ref_cm", "mass."))
    cg_model = (x_cg, units.cm_to_m(_optional(mass, "y_cg_cm", "mass.", 0.0)),
                units.cm_to_m(_optional(mass, "z_cg_cm", "mass.", 0.0)))
    key = "mass.inertia_g_cm2"
    if "inertia_g_cm2" not in mass:
        raise _F.fail(key, "missing ([Ixx, Iyy, Izz] or a 3x3 tensor)")
    raw = mass["inertia_g_cm2"]
    if isinstance(raw, list | tuple) and raw and all(isinstance(r, list | tuple) for r in raw):
        if len(raw) != 3:
            raise _F.fail(key, "expected [Ixx, Iyy, Izz] or a 3x3 tensor")
        inertia = np.array([_F.vector(r, 3, f"{key}[{i}]") for i, r in enumerate(raw)])
    else:
        inertia = np.diag(_F.vector(raw, 3, key, " [Ixx, Iyy, Izz] or a 3x3 tensor"))
    if np.max(np.abs(inertia)) > INERTIA_MAX_G_CM2:  # beyond it the eigen-check overflows
        raise _F.fail(key, f"{np.max(np.abs(inertia)):g} g cm^2 is implausibly large "
                           f"(> {INERTIA_MAX_G_CM2:g}; check the unit)")
    try:
        validate_inertia(inertia, key)
    except ShotFileError as exc:
        raise SpecError(str(exc)) from None
    return mass_kg, cg_model, units.g_cm2_to_kg_m2(inertia)


def _range(rng: dict, row) -> tuple[float, float]:
    """Range pressure (Pa) and temperature (K) of ``[range]`` (or Table 3's ``row``)."""
    _F.check_unknown(rng, ("pressure_torr", "temperature_k"), "range.")
    if row is not None:
        rng.setdefault("pressure_torr", float(row["pressure_torr"]))
        rng.setdefault("temperature_k", float(row["temperature_k"]))
    p_pa = units.torr_to_pa(_get(rng, "pressure_torr", "range."))
    t_k = _get(rng, "temperature_k", "range.")
    if not (1.0 < p_pa < 1e6):
        raise _F.fail("range.pressure_torr",
                      f"{rng['pressure_torr']} torr is not a range pressure")
    if not (150.0 < t_k < 400.0):
        raise _F.fail("range.temperature_k", f"{t_k} K is not a range temperature")
    return p_pa, t_k


def _launch(launch: dict, row) -> Launch:
    """The :class:`Launch` of ``[launch]`` (Table 3's speed if ``row`` and none given): each key
    is a ``Launch`` field in SI or in another unit of the same quantity (``theta_deg``,
    ``q_deg_s``), converted through the unit table."""
    if row is not None:
        launch.setdefault("speed_m_s", float(row["velocity_m_s"]))
    si_keys = {f.name for f in fields(Launch)}
    known = set(si_keys)
    for key in si_keys:  # the same quantity in any unit of the table
        base, unit = units.split_unit_key(key)
        known |= {f"{base}_{u}" for u in units.units_of(units.unit(unit).quantity)}
    _F.check_unknown(launch, known, "launch.")
    kwargs = {}
    for key, value in launch.items():
        x = _F.number(value, f"launch.{key}")
        base, unit = units.split_unit_key(key)
        si = next(k for k in si_keys if units.split_unit_key(k)[0] == base)
        if si in kwargs:
            raise _F.fail(f"launch.{key}", f"{base!r} is given twice")
        kwargs[si] = units.to_si(x, unit)
    launch = Launch(**kwargs)
    if not launch.speed_m_s > 0:
        raise _F.fail("launch.speed_m_s", "must be positive")
    return launch


def _station_biases(table) -> dict[int, tuple[float, float, float, float]]:
    """Parse ``[station_biases]``: ``{"5": {"y_m": 5e-4}, ...}`` -> ``{5: (0, 5e-4, 0, 0)}``.

    Keys are station ids (strings in TOML); each value a table with any of ``x_m``, ``y_m``,
    ``z_m`` (m) and ``time_s`` (s), the rest 0. Each position component must be within
    :data:`BIAS_POSITION_MAX_M` and the time within :data:`BIAS_TIME_MAX_S`. Whether the
    stations exist is checked against the facility by ``cadra.synthetic.simulate``.
    """
    if table is None:
        return {}
    if not isinstance(table, dict):
        raise _F.fail("station_biases", "expected a table of station id -> "
                                        "{x_m, y_m, z_m, time_s}")
    out = {}
    for key, entry in table.items():
        where = f"station_biases.{key}"
        try:
            station = int(str(key).strip())
        except ValueError:
            raise _F.fail(where, "not a station id (an integer such as \"5\")") from None
        if station in out:
            raise _F.fail(where, f"station {station} given twice")
        if not isinstance(entry, dict):
            raise _F.fail(where, f"expected a table with any of {list(BIAS_KEYS)}, "
                                 f"got {entry!r}")
        _F.check_unknown(entry, BIAS_KEYS, f"{where}.")
        values = []
        for name in BIAS_KEYS:
            value = _F.number(entry.get(name, 0.0), f"{where}.{name}")
            limit = BIAS_TIME_MAX_S if name == "time_s" else BIAS_POSITION_MAX_M
            if abs(value) > limit:
                raise _F.fail(f"{where}.{name}", f"{value:g} is not a plausible bias "
                                                 f"(|{name}| <= {limit:g})")
            values.append(value)
        out[station] = tuple(values)
    return out


def _aim(value) -> str:
    if value not in AIMS:
        raise _F.fail("aim", f"expected \"none\" or \"centre\", got {value!r}")
    return value


__all__ = ["AIMS", "BIAS_KEYS", "BIAS_POSITION_MAX_M", "BIAS_TIME_MAX_S", "FilmPlacement",
           "ShotSpec", "SpecError", "load_shot_spec", "spec_from_dict"]
