"""A shot's measured flight as plain data: what stage two and the classic methods read.

:class:`ShotData` holds what the fit needs of a shot and nothing else: the rigid body and air
(:class:`cadra.dynamics.setup.RigidBody`), the spark times and the measured reference point and
nose-axis inclinations with their sigmas, SI. It is a frozen dataclass of numpy arrays, so a
scheduler can ship it. It is built

- from stage one's trajectory and the shot's record, in memory
  (:func:`shot_data_from_trajectory`), or from the two files (:func:`load_shot_data`), which
  refuse pairs that do not belong together;
- from a simulated shot's exact truth plus seeded noise (:func:`shot_data_from_truth`: tests,
  benchmarks, Monte Carlo).

Channels (columns of ``meas`` and ``sigma``), in this order: :data:`CHANNELS`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from cadra import channels as channel_registry
from cadra.atmosphere import Atmosphere
from cadra.body import body_from_spec
from cadra.dynamics.effects import Effects
from cadra.dynamics.setup import RigidBody, rigid_body_from_mass

#: measured channels, SI (m, m, m, rad, rad): names and units from the channel registry
#: (:mod:`cadra.channels`; these names stay as aliases)
CHANNELS = channel_registry.NAMES
CHANNEL_UNITS = channel_registry.UNITS
N_CHANNELS = channel_registry.N_CHANNELS
_POS, _ANG = channel_registry.POSITION, channel_registry.ANGLE
_AXIS, _ROLL = channel_registry.AXIS, channel_registry.ROLL
#: the channels every measurement has a column for (not optional: x, y, z, theta, psi)
_REQUIRED = np.array([i for i, c in enumerate(channel_registry.OBSERVED) if not c.optional])
#: typical film-range measurement noise (seed 004 era): 0.1 mm, 0.1 deg, 10 ns
FILM_SIGMAS = {"position_m": 1e-4, "angle_rad": math.radians(0.1), "time_s": 1e-8}
#: fewest stations with a measured position a trajectory file must give (a fit's starting
#: values fit a parabola to x(t))
MIN_STATIONS = 3


class FitDataError(ValueError):
    """Stage-two input that cannot be right; the message names the file and what is wrong."""


@dataclass(frozen=True, eq=False)
class ShotData:
    """One shot's measurements for stage two (SI).

    Attributes
    ----------
    shot_id : e.g. ``"M2-2429"``.
    rigid : mass properties, air and effects of the shot (the dynamics' view).
    body_kind : the body's kind (``"sphere"``, ``"capsule"``, ``"cone"``, ...).
    stations : (n,) station ids of the measured stations.
    t_s : (n,) spark times, s.
    meas : (n, N_CHANNELS) measured x, y, z (m, reference point, facility frame), theta, psi
        (rad) and the roll angle phi (rad; :mod:`cadra.channels`); NaN where not measured (a
        sphere's angles, a body of revolution's roll, a failed channel).
    sigma : (n, N_CHANNELS) 1-sigma of ``meas`` (same units), timing included (see
        ``sigma_t_s``). Both may also be given with the required channels' columns only
        (x .. psi, (n, 5)): the optional ones (phi) are then not measured.
    sigma_t_s : timing sigma, s, already folded into ``sigma`` (x as V sigma_t).
    source : where the data came from (paths or "simulated").
    facility : the facility the shot was measured in (its name or file, as the shot's record
        gives it; "" when not known): a station bias table applies to its stations only.
    """

    shot_id: str
    rigid: RigidBody
    body_kind: str
    stations: np.ndarray
    t_s: np.ndarray
    meas: np.ndarray
    sigma: np.ndarray
    sigma_t_s: float = 0.0
    source: dict = field(default_factory=dict)
    facility: str = ""
    #: the spin at the muzzle (rad/s; NaN: not known), from the shot file's ``[gun]``: the
    #: twist and muzzle velocity or the spin itself. Stage one cannot see a body of
    #: revolution's spin; the fit's start takes it from here (docs/spark_range.md)
    launch_spin_rad_s: float = math.nan
    #: the rifling's twist, m per turn (NaN: not known): with no muzzle velocity the start
    #: takes the spin as 2 pi V / twist at the speed measured in the range
    twist_m_per_turn: float = math.nan

    def __post_init__(self):
        n = len(self.t_s)
        for name in ("meas", "sigma"):       # the required channels only: optional ones NaN
            a = np.asarray(getattr(self, name), dtype=float)
            if a.ndim == 2 and a.shape == (n, _REQUIRED.size) and _REQUIRED.size < N_CHANNELS:
                full = np.full((n, N_CHANNELS), np.nan)
                full[:, _REQUIRED] = a
                object.__setattr__(self, name, full)
        for name, shape in (("stations", (n,)), ("meas", (n, N_CHANNELS)),
                            ("sigma", (n, N_CHANNELS))):
            if np.shape(getattr(self, name)) != shape:
                raise FitDataError(f"{self.shot_id}: {name} must have shape {shape}, "
                                   f"got {np.shape(getattr(self, name))}")
        if not np.all(np.isfinite(self.t_s)) or np.any(np.diff(self.t_s) <= 0):
            raise FitDataError(f"{self.shot_id}: spark times must be finite and increasing")
        bad = np.isfinite(self.meas) & ~(np.isfinite(self.sigma) & (self.sigma > 0))
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise FitDataError(f"{self.shot_id}: station {self.stations[i]} channel "
                               f"{CHANNELS[j]}: a measurement without a positive sigma")

    @property
    def mask(self) -> np.ndarray:
        """(n, N_CHANNELS) True where a channel was measured."""
        return np.isfinite(self.meas)

    @property
    def n_observations(self) -> int:
        return int(self.mask.sum())

    @property
    def epoch_index(self) -> int:
        """Index of the station whose time is the fit's epoch (the middle one)."""
        return len(self.t_s) // 2

    @property
    def has_angles(self) -> bool:
        """Whether the nose axis's inclinations (theta, psi) were measured anywhere."""
        return bool(self.mask[:, _AXIS].any())

    @property
    def has_roll(self) -> bool:
        """Whether the roll angle phi was measured anywhere."""
        return bool(self.mask[:, _ROLL].any())

    def with_effects(self, effects: Effects) -> ShotData:
        return replace(self, rigid=self.rigid.with_effects(effects))


def _floor(sigma: np.ndarray, floor: dict) -> np.ndarray:
    """``sigma`` floored; a NaN sigma (a channel not measured) stays NaN."""
    out = sigma.copy()
    out[:, _POS] = np.maximum(out[:, _POS], floor.get("position_m", 0.0))
    out[:, _ANG] = np.maximum(out[:, _ANG], floor.get("angle_rad", 0.0))
    return out


def floor_sigmas(shot: ShotData, floor: dict) -> ShotData:
    """``shot`` with its sigmas floored at ``floor`` (``{"position_m": .., "angle_rad": ..}``).
    An unmeasured channel keeps its NaN sigma: it carries no weight and enters nothing."""
    return replace(shot, sigma=_floor(shot.sigma, floor))


def rigid_body_from_shot(shot, effects: Effects | None = None) -> RigidBody:
    """The dynamics' view of a :class:`cadra.io.shotfile.ShotFile` (mass properties, air,
    test mode)."""
    body = body_from_spec(shot.model)
    return rigid_body_from_mass(shot.mass.mass_kg, shot.mass.cg_model_m,
                                shot.mass.inertia_model_kg_m2, body.diameter_m,
                                Atmosphere.from_pt(shot.pressure_pa, shot.temperature_k),
                                effects, shot.test_mode)


def _fold_timing(t_s, meas, sigma, sigma_t_s):
    """x sigma with the timing error V sigma_t added in quadrature (V from the data)."""
    if sigma_t_s <= 0:
        return sigma
    sigma = sigma.copy()
    ok = np.isfinite(meas[:, 0])
    if ok.sum() >= 2:
        V = abs(np.polyfit(t_s[ok], meas[ok, 0], 1)[0])
        sigma[:, 0] = np.hypot(sigma[:, 0], V * sigma_t_s)
    return sigma


def load_shot_data(shot_path: str | os.PathLike, trajectory_path: str | os.PathLike, *,
                   sigma_t_s: float = 0.0, min_sigma: dict | None = None,
                   effects: Effects | None = None) -> ShotData:
    """A shot's measurements from its shot file and a trajectory measurement file
    (:func:`shot_data_from_trajectory` on what the two files hold). Raises
    :class:`FitDataError` naming the file when either cannot be read or they do not belong
    together."""
    from cadra.io.shotfile import ShotFileError, load_shot
    from cadra.io.trajectory import TrajectoryFileError, load_trajectory

    try:
        shot = load_shot(shot_path)
    except (ShotFileError, OSError) as exc:
        msg = str(exc)   # the shot file's errors name it already: not twice
        raise FitDataError(msg if msg.startswith(str(shot_path)) else f"{shot_path}: {msg}"
                           ) from None
    try:
        traj = load_trajectory(trajectory_path)
    except (TrajectoryFileError, FileNotFoundError) as exc:
        raise FitDataError(str(exc)) from None
    return shot_data_from_trajectory(
        traj, shot, sigma_t_s=sigma_t_s, min_sigma=min_sigma, effects=effects,
        source={"shot_file": str(Path(shot_path)), "trajectory_file": str(trajectory_path)})


def shot_data_from_trajectory(traj, shot, *, sigma_t_s: float = 0.0,
                              min_sigma: dict | None = None, effects: Effects | None = None,
                              source: dict | None = None) -> ShotData:
    """A shot's measurements from a stage-one trajectory (:class:`cadra.io.trajectory.
    Trajectory`: a loaded file, or :func:`cadra.io.trajectory.trajectory_from_table` of a
    table in memory) and the shot's record (:class:`cadra.io.shotfile.ShotFile`: body, mass
    properties, air, spark times).

    Stations whose status is ``failed`` are left out; a NaN value or sigma masks that channel.
    ``sigma_t_s``: the spark-time sigma (s), folded into x's sigma as V sigma_t.
    ``min_sigma`` (``{"position_m": .., "angle_rad": ..}``) floors the stage-one sigmas (for
    an analyst who does not trust them below some level). ``source`` names where the data
    came from (the messages use its ``trajectory_file`` and ``shot_file``). Raises
    :class:`FitDataError` when the two do not belong together: another shot id, a station the
    shot does not have, or a spark time that differs from the shot's.
    """
    source = dict(source or {"shot_file": f"shot {shot.shot_id}",
                             "trajectory_file": f"stage one's trajectory of {shot.shot_id}"})
    trajectory_path, shot_path = source.get("trajectory_file"), source.get("shot_file")
    tid = traj.meta.get("shot_id")
    if tid is not None and tid != shot.shot_id:
        raise FitDataError(f"{trajectory_path}: measurements of shot {tid!r}, but the shot file "
                           f"{shot_path} is shot {shot.shot_id!r}: they do not belong together")
    table = traj.measured
    shot_times = {rec.station: rec.time_s for rec in shot.stations}
    unknown = sorted(set(table["station"]) - set(shot_times))
    if unknown:
        raise FitDataError(f"{trajectory_path}: station(s) {unknown} are not in the shot file "
                           f"{shot_path} (stations {sorted(shot_times)})")
    for st, t in zip(table["station"], table["t_s"], strict=True):
        if not math.isclose(t, shot_times[st], rel_tol=0, abs_tol=1e-9):
            raise FitDataError(f"{trajectory_path}: station {st} time {t} s differs from the "
                               f"shot file's {shot_times[st]} s: the files do not belong together")
    table = table.sort_values("t_s")
    positions = np.isfinite(table[[c.si_column for c in channel_registry.OBSERVED
                                   if c.name in ("x", "y", "z")]].to_numpy(float)).all(axis=1)
    mounted = shot.test_mode.mounted
    angles = np.isfinite(table[[c.si_column for c in channel_registry.OBSERVED
                                if c.name in ("theta", "psi")]].to_numpy(float)).all(axis=1)
    rolls = np.isfinite(table[[c.si_column for c in channel_registry.OBSERVED
                               if c.periodic]].to_numpy(float)).all(axis=1)
    if mounted and angles.sum() < MIN_STATIONS and not (
            shot.test_mode.kind == "roll_bearing" and rolls.sum() >= MIN_STATIONS):
        raise FitDataError(f"{trajectory_path}: {int(angles.sum())} measured frame(s) with "
                           f"both angles (theta, psi); a {shot.test_mode.kind} record needs "
                           f"at least {MIN_STATIONS}"
                           + (" (a roll bearing's: or its roll, phi)"
                              if shot.test_mode.kind == "roll_bearing" else ""))
    if not mounted and positions.sum() < MIN_STATIONS:
        raise FitDataError(f"{trajectory_path}: {int(positions.sum())} measured station(s) with "
                           f"a position (x_m, y_m, z_m); stage two needs at least "
                           f"{MIN_STATIONS}")
    meas = table[[c.si_column for c in channel_registry.OBSERVED]].to_numpy(float)
    sigma = table[[c.si_sigma_column for c in channel_registry.OBSERVED]].to_numpy(float)
    if min_sigma:
        sigma = _floor(sigma, min_sigma)
    bad = ~np.isfinite(sigma) | ~(sigma > 0)
    meas = np.where(bad, np.nan, meas)
    t_s = table["t_s"].to_numpy(float)
    kind = body_from_spec(shot.model).kind
    return ShotData(
        shot_id=shot.shot_id, rigid=rigid_body_from_shot(shot, effects), body_kind=kind,
        stations=table["station"].to_numpy(int), t_s=t_s, meas=meas,
        sigma=_fold_timing(t_s, meas, sigma, sigma_t_s), sigma_t_s=float(sigma_t_s),
        source=source, facility=str(shot.facility), **gun_fields(shot.gun))


def gun_fields(gun) -> dict:
    """:class:`ShotData`'s spin fields from a shot file's :class:`cadra.io.shotfile.Gun`
    (or None)."""
    if gun is None:
        return {}
    spin = gun.spin_rad_s()
    twist = gun.twist_m_per_turn
    return {"launch_spin_rad_s": spin,
            "twist_m_per_turn": math.nan if twist is None else float(twist)}


def with_launch_spin(shot: ShotData, *, spin_rad_s: float | None = None,
                     twist_m_per_turn: float | None = None,
                     muzzle_velocity_m_s: float | None = None) -> ShotData:
    """``shot`` launched at a known spin: ``spin_rad_s`` itself, or the rifling's
    ``twist_m_per_turn`` (negative: left-hand) with ``muzzle_velocity_m_s`` (without it the
    start uses the speed measured in the range), or the shot's own twist with a muzzle
    velocity. Values not given keep the shot's (its shot file's ``[gun]``)."""
    if spin_rad_s is not None and twist_m_per_turn is not None:
        raise ValueError("give the spin or the twist, not both")
    if spin_rad_s is not None:
        if not (math.isfinite(spin_rad_s) and spin_rad_s != 0):
            raise ValueError(f"spin: a finite, non-zero spin in rad/s, got {spin_rad_s!r}")
        return replace(shot, launch_spin_rad_s=float(spin_rad_s))
    twist = shot.twist_m_per_turn if twist_m_per_turn is None else float(twist_m_per_turn)
    if twist_m_per_turn is not None and not (math.isfinite(twist) and twist != 0):
        raise ValueError(f"twist: a finite, non-zero twist, got {twist_m_per_turn!r}")
    if muzzle_velocity_m_s is not None and not muzzle_velocity_m_s > 0:
        raise ValueError(f"muzzle velocity: a positive speed in m/s, got {muzzle_velocity_m_s!r}")
    if twist_m_per_turn is None and muzzle_velocity_m_s is None:
        return shot
    if not math.isfinite(twist):
        raise ValueError(f"{shot.shot_id}: a muzzle velocity without a twist gives no spin "
                         "(give the twist too)")
    spin = (2.0 * math.pi * muzzle_velocity_m_s / twist if muzzle_velocity_m_s is not None
            else (math.nan if twist_m_per_turn is not None else shot.launch_spin_rad_s))
    return replace(shot, twist_m_per_turn=twist, launch_spin_rad_s=spin)


def launch_spin(shot: ShotData, speed_m_s: float | None = None) -> float:
    """The shot's spin at launch (rad/s): given, or 2 pi V / twist at ``speed_m_s`` (the speed
    in the range) when only the twist is known; NaN when neither is."""
    if np.isfinite(shot.launch_spin_rad_s):
        return float(shot.launch_spin_rad_s)
    if np.isfinite(shot.twist_m_per_turn) and speed_m_s is not None:
        return 2.0 * math.pi * float(speed_m_s) / shot.twist_m_per_turn
    return math.nan


def shot_data_from_truth(truth: pd.DataFrame, rigid: RigidBody, shot_id: str, body_kind: str, *,
                         sigma_position_m: float, sigma_angle_rad: float,
                         sigma_t_s: float = 0.0, rng: np.random.Generator | None = None,
                         angles: bool | None = None, roll: bool | None = None,
                         sigma_roll_rad: float | None = None,
                         positions: bool = True, facility: str = "") -> ShotData:
    """Measurements made from a simulated shot's exact truth (``truth.csv`` columns).

    With ``rng`` the measurements get Gaussian noise of the given sigmas, and the spark times
    a timing error of ``sigma_t_s`` (the data then carry times that are off, as real ones are);
    without it they are exact (noise-free tests) but still carry the sigmas as weights.
    ``angles=False`` drops theta and psi (a sphere shows none); default: not for a sphere.
    ``roll`` keeps the roll angle phi (sigma ``sigma_roll_rad``, default
    ``sigma_angle_rad``); default: only for a finned body (``"finner"``), whose roll stage one
    measures. ``positions=False`` drops x, y, z (a mounted wind-tunnel record).
    A truth table without an optional channel's column (an older ``truth.csv`` without
    ``phi_deg``) reads it as not measured. ``facility``: the facility's name, when a bias
    table is to be applied.
    """
    n = len(truth)
    meas = np.column_stack([channel_registry.to_si(truth[c.value_column].to_numpy(float),
                                                   c.file_unit)
                            if c.value_column in truth or not c.optional
                            else np.full(n, np.nan)
                            for c in channel_registry.OBSERVED])
    t_s = truth["t_s"].to_numpy(float).copy()
    sigma = np.empty((n, N_CHANNELS))
    sigma[:, _POS] = sigma_position_m
    sigma[:, _ANG] = sigma_angle_rad
    sigma[:, _ROLL] = sigma_angle_rad if sigma_roll_rad is None else sigma_roll_rad
    if angles is None:
        angles = body_kind != "sphere"
    if roll is None:
        roll = body_kind == "finner"
    if not angles:
        meas[:, _AXIS] = np.nan
    if not roll:
        meas[:, _ROLL] = np.nan
    if not positions:
        meas[:, _POS] = np.nan
    stations = truth["station"].to_numpy(int)
    if rng is not None:
        # the required channels' noise first, the optional ones' (phi) after the timing's and
        # only when measured: a seeded draw of a shot without them is what it always was
        core = np.array([not c.optional for c in channel_registry.OBSERVED])
        meas = meas.copy()
        meas[:, core] += rng.standard_normal((n, int(core.sum()))) * sigma[:, core]
        dt = rng.standard_normal(n) * sigma_t_s if sigma_t_s > 0 else np.zeros(n)
        extra = ~core & np.isfinite(meas).any(axis=0)
        if extra.any():
            meas[:, extra] += rng.standard_normal((n, int(extra.sum()))) * sigma[:, extra]
        if sigma_t_s > 0:
            t_s = t_s + dt
            order = np.argsort(t_s)
            t_s, meas, stations = t_s[order], meas[order], stations[order]
    return ShotData(shot_id=shot_id, rigid=rigid, body_kind=body_kind,
                    stations=stations, t_s=t_s, meas=meas,
                    sigma=_fold_timing(t_s, meas, sigma, sigma_t_s), sigma_t_s=sigma_t_s,
                    source={"origin": "simulated truth" + (" + noise" if rng else "")},
                    facility=facility)
