"""Extra unknowns of a fit beyond the aerodynamic model: unmodelled effects made free.

An :class:`Extra` is one scalar unknown shared by the shots it applies to, of one of two kinds:

- **physics**: a direction in the simulator's ``phys`` vector (:mod:`cadra.dynamics.layout`:
  cg offset, inertia tensor, wind, density gradient); the shot's ``phys`` is the nominal one
  plus ``value * direction``, so the fit integrates the same 6-DOF code the simulator does
  with the effect switched on, and its sensitivity is a complex-step column like any other.
  A cg offset also moves the observed reference point (``ref_from_cg -= offset``), which
  :func:`cadra.fitting.sensitivity.predict_with_jacobian` applies per run.
- **station**: a term added to what stage one measured at one station (a facility effect, the
  same in every shot through that station):

  ============  ========================================  =========  =====================
  ``measure``   added to the prediction                   unit       column
  ============  ========================================  =========  =====================
  position_x    ``b`` to x (y, z likewise)                m          1
  timing        ``v dt`` to x, y, z (spark fired ``dt``   s          cg velocity
                after its recorded time)
  scale         ``s (y, z)`` to y, z (image scale off     --         predicted y, z
                about the range axis)
  angle_theta   ``b`` to theta (psi likewise): an offset  rad        1
                of the station's angle reference
  response      ``v g`` to x .. psi: a facility effect    its own    ``g``, given per shot
                whose response ``g`` at the station was                (``response``)
                computed from the facility's geometry
  ============  ========================================  =========  =====================

  A response may also act at every station (``station`` None): its ``g`` is then given per
  shot and station (a facility's optics misdeclared for all its stations).

  Timing: the attitude's change over ``dt`` (rate x tens of ns, ~1e-6 rad) and the
  velocity's dependence on the other unknowns (``dt`` times it) are left out; both are far
  below stage one's precision. Scale: the x part (about the station's optical centre, where
  the model is) is left out for the same reason.

An extra marked ``held`` keeps its ``value``: it acts on the prediction but is not fitted (a
point of a profile likelihood, :mod:`cadra.fitting.profile`).

Pure data: a tuple of extras ships to a scheduler like the rest of the fit's inputs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cadra.channels import NAMES as CHANNELS
from cadra.channels import POSITION
from cadra.dynamics.layout import N_PHYS, P_CG_OFFSET

MEASURES = ("position_x", "position_y", "position_z", "timing", "scale", "angle_theta",
            "angle_psi", "response")
#: the lateral position channels (y, z) a scale error acts on
_YZ = np.array([CHANNELS.index("y"), CHANNELS.index("z")])
#: the channels a response is given in (x, y, z, theta, psi: the roll is left out)
_RESPONSE = np.array([CHANNELS.index(c) for c in ("x", "y", "z", "theta", "psi")])
_N_RESPONSE = len(_RESPONSE)


def phys_direction(*terms) -> tuple[float, ...]:
    """A direction in the physics vector (``cadra.dynamics.layout``) for
    :attr:`Extra.phys_direction`: each term an index (weight 1) or an (index, weight) pair,
    weights at one index adding up."""
    d = np.zeros(N_PHYS)
    for term in terms:
        idx, val = (term, 1.0) if isinstance(term, int | np.integer) else term
        d[idx] += val
    return tuple(d)


@dataclass(frozen=True)
class Extra:
    """One extra unknown (module doc). ``shots``: the shot ids it applies to (None: all);
    ``held``: kept at ``value``, not fitted; ``response`` (measure ``"response"``): ``((shot
    id, (d x, d y, d z, d theta, d psi) per unit value at the station), ...)``, or with
    ``station`` None ``((shot id, station id, (d x, ..., d psi)), ...)``; a shot (or station)
    not listed unaffected."""

    name: str
    phys_direction: tuple[float, ...] | None = None
    station: int | None = None
    measure: str = ""
    shots: tuple[str, ...] | None = None
    value: float = 0.0
    held: bool = False
    response: tuple = ()

    def __post_init__(self):
        if (self.phys_direction is None) == (self.station is None) and not (
                self.phys_direction is None and self.measure == "response"):
            raise ValueError(f"extra {self.name!r}: give a phys direction or a station, "
                             "not both or neither")
        if self.phys_direction is not None:
            d = tuple(float(v) for v in self.phys_direction)
            if len(d) != N_PHYS or not np.all(np.isfinite(d)) or not any(d):
                raise ValueError(f"extra {self.name!r}: phys direction must be {N_PHYS} "
                                 "finite numbers, not all zero")
            object.__setattr__(self, "phys_direction", d)
        elif self.measure not in MEASURES:
            raise ValueError(f"extra {self.name!r}: measure must be one of {MEASURES}")
        elif self.measure == "response":
            # at one station: (shot, g) entries; at every station (station None): (shot,
            # station, g)
            try:
                resp = tuple((str(e[0]), *(() if self.station is not None else (int(e[1]),)),
                              tuple(float(v) for v in e[-1])) for e in self.response)
                ok = all(len(e) == (2 if self.station is not None else 3) for e in
                         self.response)
            except (TypeError, ValueError, IndexError):
                resp, ok = (), False
            if not ok or not resp or any(len(e[-1]) != _N_RESPONSE
                                         or not np.all(np.isfinite(e[-1])) for e in resp):
                where = "shot" if self.station is not None else "shot and station"
                raise ValueError(f"extra {self.name!r}: a response needs, per {where}, "
                                 f"{_N_RESPONSE} finite values (x, y, z, theta, psi)")
            object.__setattr__(self, "response", resp)
        if not np.isfinite(self.value):
            raise ValueError(f"extra {self.name!r}: value must be finite")
        if self.shots is not None:
            object.__setattr__(self, "shots", tuple(str(s) for s in self.shots))

    @property
    def is_phys(self) -> bool:
        return self.phys_direction is not None

    def applies(self, shot_id: str) -> bool:
        return self.shots is None or shot_id in self.shots


def shot_phys(phys: np.ndarray, extras: Sequence[Extra], values, shot_id: str) -> np.ndarray:
    """The shot's ``phys`` with the physics extras at ``values`` added."""
    out = np.array(phys, dtype=float)
    for e, v in zip(extras, values, strict=True):
        if e.is_phys and e.applies(shot_id):
            out += float(v) * np.asarray(e.phys_direction)
    return out


def shot_ref(ref: np.ndarray, phys_nominal: np.ndarray, phys: np.ndarray) -> np.ndarray:
    """Reference point from the cg (body axes) when ``phys`` moves the cg off the nominal one
    (``ref`` belongs to ``phys_nominal``)."""
    cg = slice(P_CG_OFFSET, P_CG_OFFSET + 3)
    return np.asarray(ref) - (np.asarray(phys)[cg] - np.asarray(phys_nominal)[cg])


def station_columns(extras: Sequence[Extra], shot_id: str, stations: np.ndarray,
                    pred: np.ndarray, states: np.ndarray) -> np.ndarray:
    """(n, 5, len(extras)) d(prediction)/d(value) of the station extras (0 for the others and
    for extras that do not apply to the shot)."""
    n = len(stations)
    C = np.zeros((n, len(CHANNELS), len(extras)))
    for j, e in enumerate(extras):
        if e.is_phys or not e.applies(shot_id):
            continue
        rows = np.flatnonzero(np.asarray(stations) == e.station)
        if e.measure.startswith("position_"):
            C[rows, CHANNELS.index(e.measure[-1]), j] = 1.0
        elif e.measure.startswith("angle_"):
            C[rows, CHANNELS.index(e.measure[len("angle_"):]), j] = 1.0
        elif e.measure == "timing":
            C[rows[:, None], POSITION, j] = states[rows, 3:6]
        elif e.measure == "response":
            for entry in e.response:
                if entry[0] != shot_id:
                    continue
                at = rows if e.station is not None else np.flatnonzero(
                    np.asarray(stations) == entry[1])
                C[at[:, None], _RESPONSE, j] = np.asarray(entry[-1])
        else:
            C[rows[:, None], _YZ, j] = pred[rows[:, None], _YZ]
    return C


def add_station_terms(pred: np.ndarray, extras: Sequence[Extra], values, shot_id: str,
                      stations: np.ndarray, states: np.ndarray) -> np.ndarray:
    """``pred`` with the station extras at ``values`` added (the terms of the module doc;
    linear in the values, so ``pred + C @ values`` with :func:`station_columns`)."""
    if not any(not e.is_phys for e in extras):
        return pred
    C = station_columns(extras, shot_id, stations, pred, states)
    return pred + C @ np.asarray(values, dtype=float)


__all__ = ["MEASURES", "Extra", "add_station_terms", "phys_direction", "shot_phys", "shot_ref",
           "station_columns"]
