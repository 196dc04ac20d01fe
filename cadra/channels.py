"""The observed channels as data: one registry for names, units, file columns and display.

Each channel stage one measures per station and stage two fits is one :class:`Channel`
entry of :data:`OBSERVED`; the order of that tuple is the order of the columns of
:class:`cadra.flight.data.ShotData`'s ``meas`` and ``sigma`` and of every prediction
(``(n, N_CHANNELS)`` arrays). Code that needs "the angles" or "the positions" asks the
registry (:func:`indices`) instead of slicing ``[:, 3:]``, so a channel added later (a roll
angle ``phi``, the spark time as an observed channel) is one more entry here plus the
observation model that predicts it.

Units: values inside CADRA are SI (m, rad, s); the trajectory file (``docs/stage1.md``)
stores angles in degrees (``file_unit``), reports show values in ``display_unit`` and
residuals, rms and noise floors in ``residual_unit`` (µm and degrees: a residual of a few
micrometres reads badly in metres). Every unit is an entry of the one unit table
(:data:`cadra.units.UNITS`); :func:`to_si` / :func:`from_si` convert through it (degrees
bit for bit as numpy's ``radians`` / ``degrees``, what the file reader always did).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cadra import units

#: kinds of channel (what a channel measures), and the quantity of the unit table they are
KINDS = ("position", "angle", "time")
_QUANTITY = {"position": "length", "angle": "angle", "time": "time"}
_SI_UNIT = {"position": "m", "angle": "rad", "time": "s"}
#: the unit residuals are shown in, by kind
_RESIDUAL_UNIT = {"position": "um", "angle": "deg", "time": "us"}


@dataclass(frozen=True)
class Channel:
    """One observed channel.

    Attributes
    ----------
    name : short name (``"x"``, ``"theta"``), the ``channel`` column of residual tables.
    kind : ``"position"``, ``"angle"`` or ``"time"`` (:data:`KINDS`).
    file_unit : the unit of the trajectory file's columns (``"m"``, ``"deg"``, ``"s"``).
    display_unit : the unit of reports and residual files (values).
    label : the name on plots (``"θ"``).
    description : one line, for documentation.
    periodic : an angle defined modulo 2 pi (the roll angle): a residual is wrapped to
        (-pi, pi] (:func:`residual`), and a file may carry it unwrapped (continuous along a
        shot) or wrapped.
    optional : a trajectory or truth file may leave out its two columns (read as "not
        measured"): stage one measures it only for some bodies (the roll of a finned body).
    """

    name: str
    kind: str
    file_unit: str
    display_unit: str
    label: str
    description: str = ""
    periodic: bool = False
    optional: bool = False

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"channel {self.name!r}: kind must be one of {KINDS}")
        known = units.units_of(_QUANTITY[self.kind])
        for u in (self.file_unit, self.display_unit):
            if u not in known:
                raise ValueError(f"channel {self.name!r}: unit {u!r} is not a "
                                 f"{self.kind} unit ({sorted(known)})")

    @property
    def unit(self) -> str:
        """SI unit (inside CADRA)."""
        return _SI_UNIT[self.kind]

    @property
    def display_scale(self) -> float:
        """Display value per SI value (180/pi for an angle shown in degrees)."""
        return _per_si(self.display_unit)

    @property
    def residual_unit(self) -> str:
        """The unit of residuals, their rms and noise floors in reports (µm, deg)."""
        return _RESIDUAL_UNIT[self.kind]

    @property
    def residual_scale(self) -> float:
        """Residual display value per SI value (1e6 for µm)."""
        return _per_si(self.residual_unit)

    @property
    def residual_label(self) -> str:
        """The residual unit as printed (``µm``, ``deg``)."""
        return {"um": "µm", "us": "µs"}.get(self.residual_unit, self.residual_unit)

    @property
    def value_column(self) -> str:
        """Trajectory-file column of the value (``theta_deg``)."""
        return f"{self.name}_{self.file_unit}"

    @property
    def sigma_column(self) -> str:
        """Trajectory-file column of the 1-sigma (``sigma_theta_deg``)."""
        return f"sigma_{self.name}_{self.file_unit}"

    @property
    def si_column(self) -> str:
        """Column of the value in SI (``theta_rad``: the loaded table, histories)."""
        return f"{self.name}_{self.unit}"

    @property
    def si_sigma_column(self) -> str:
        """Column of the 1-sigma in SI (``sigma_theta_rad``)."""
        return f"sigma_{self.name}_{self.unit}"

    @property
    def display_column(self) -> str:
        """Column name in display units (``theta_deg``)."""
        return f"{self.name}_{self.display_unit}"


def _per_si(unit: str) -> float:
    """Value in ``unit`` per SI value (the unit table's conversion of 1)."""
    return float(units.from_si(1.0, unit))


#: the observed channels, in the order of every (n, N_CHANNELS) array
OBSERVED: tuple[Channel, ...] = (
    Channel("x", "position", "m", "m", "x", "reference point along the range, F"),
    Channel("y", "position", "m", "m", "y", "reference point across the range, F"),
    Channel("z", "position", "m", "m", "z", "reference point, up, F"),
    Channel("theta", "angle", "deg", "deg", "θ",
            "inclination of the nose axis to the x-y plane, + up"),
    Channel("psi", "angle", "deg", "deg", "ψ",
            "inclination of the nose axis to the x-z plane, + port"),
    Channel("phi", "angle", "deg", "deg", "φ",
            "roll angle about the nose axis (aircraft 3-2-1 roll: 0 = body z in the vertical "
            "plane, pointing down; docs/conventions.md)", periodic=True, optional=True),
)

#: channel names in order (``("x", "y", "z", "theta", "psi", "phi")``)
NAMES: tuple[str, ...] = tuple(c.name for c in OBSERVED)
#: SI units in order
UNITS: tuple[str, ...] = tuple(c.unit for c in OBSERVED)
N_CHANNELS = len(OBSERVED)
#: name -> channel
BY_NAME: dict[str, Channel] = {c.name: c for c in OBSERVED}


def channel(name: str) -> Channel:
    """The registry's entry for ``name`` (KeyError naming the known channels)."""
    try:
        return BY_NAME[name]
    except KeyError:
        raise KeyError(f"unknown channel {name!r} (known: {NAMES})") from None


def indices(kind: str) -> np.ndarray:
    """Column indices (into an (n, N_CHANNELS) array) of the channels of ``kind``."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}")
    return np.array([i for i, c in enumerate(OBSERVED) if c.kind == kind], dtype=int)


def _read_only(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


#: column indices of the position channels (x, y, z) and of the angle channels (theta, psi,
#: phi)
POSITION = _read_only(indices("position"))
ANGLE = _read_only(indices("angle"))
#: the nose axis's inclinations (theta, psi): the angle channels that are not periodic
AXIS = _read_only(np.array([i for i, c in enumerate(OBSERVED)
                            if c.kind == "angle" and not c.periodic], dtype=int))
#: the roll channel(s) (phi): periodic angles
ROLL = _read_only(np.array([i for i, c in enumerate(OBSERVED) if c.periodic], dtype=int))
_TWO_PI = 2.0 * math.pi


def wrap_angle(a):
    """``a`` (rad) wrapped to [-pi, pi) (real or complex: the imaginary part, a complex
    step's derivative, is kept)."""
    return a - _TWO_PI * np.floor((np.real(a) + math.pi) / _TWO_PI)


def residual(meas: np.ndarray, pred: np.ndarray) -> np.ndarray:
    """``meas - pred`` over (..., N_CHANNELS) arrays (SI), the periodic channels (roll)
    wrapped to [-pi, pi): a roll measured continuously along a shot and a prediction in
    (-pi, pi] differ by whole turns that are no error. NaN stays NaN."""
    d = np.asarray(meas) - np.asarray(pred)
    if ROLL.size:
        d = np.array(d, copy=True)
        d[..., ROLL] = wrap_angle(d[..., ROLL])
    return d


def to_si(values, unit: str):
    """``values`` in ``unit`` converted to SI through the unit table (deg -> rad as
    ``np.radians``, bit for bit); an SI unit returns ``values`` as given."""
    if unit in _SI_UNIT.values():
        return values
    try:
        return units.to_si(values, unit)
    except KeyError:
        raise ValueError(f"unknown unit {unit!r}") from None


def from_si(values, unit: str):
    """SI ``values`` converted to ``unit`` through the unit table (rad -> deg as
    ``np.degrees``, bit for bit)."""
    if unit in _SI_UNIT.values():
        return values
    try:
        return units.from_si(values, unit)
    except KeyError:
        raise ValueError(f"unknown unit {unit!r}") from None


def trajectory_value_columns() -> list[str]:
    """The trajectory file's value columns in channel order (``x_m`` .. ``psi_deg``)."""
    return [c.value_column for c in OBSERVED]


def trajectory_sigma_columns() -> list[str]:
    """The trajectory file's sigma columns in channel order."""
    return [c.sigma_column for c in OBSERVED]


__all__ = ["ANGLE", "AXIS", "BY_NAME", "Channel", "KINDS", "NAMES", "N_CHANNELS", "OBSERVED",
           "POSITION", "ROLL", "UNITS", "channel", "from_si", "indices", "residual", "to_si",
           "trajectory_sigma_columns", "trajectory_value_columns", "wrap_angle"]
