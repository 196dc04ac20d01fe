"""Candidate shots for the next-shot planner: what a range engineer can choose, and the shot
each choice would give (docs/design.md).

A candidate is the group's template shot (one of the fitted shots: its model, mass
properties, range air, stations and measurement sigmas) launched differently. Its
dimensions (:data:`DIMENSIONS`):

- ``angle_deg``: the total angle between the nose axis and the flight path at the launch
  point, :data:`LEAD_M` before the first station (seed 004's launch angle), in the template's
  plane of that angle;
- ``rate_deg_s``: the transverse angular rate there, in the template's direction of it;
- ``mach``: the Mach number there (the template's air);
- ``roll_deg``: the roll angle about the nose axis there (0: body z down);
- ``cg_shift_mm``: an axial shift of the cg from the template's (+ toward the nose; the
  mass and inertias stay the template's);
- ``stations``: how many of the template's stations see it (the first ones).

The template's own values of these are read from its fitted flight
(:func:`template_of`), so a candidate that changes nothing is the template's flight again.
:func:`candidate_shot` flies a candidate with the fit problem's own physics and gives the
shot the planner scores: its spark times (the reference point crossing the template's
stations), its noise-free measurements and the group's median sigma per channel.

:class:`CandidateSpace` holds the ranges the user gives (a dimension not given stays at the
template's value) and draws candidates from them: a Latin-hypercube sample, a regular grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace

import numpy as np

from cadra.dynamics.observe import observe
from cadra.dynamics.trajectory import Launch, crossing_times
from cadra.fitting.problem import FitProblem
from cadra.fitting.sensitivity import predict_states
from cadra.flight.data import ShotData

__all__ = ["DIMENSIONS", "LEAD_M", "Candidate", "CandidateSpace", "Template", "candidate_launch",
           "candidate_shot", "template_of"]

#: the candidate's dimensions (module doc), in this order
DIMENSIONS = ("angle_deg", "rate_deg_s", "mach", "roll_deg", "cg_shift_mm", "stations")
#: the launch point's distance before the first station, m (the sample specs' -0.5 m)
LEAD_M = 0.5
#: the id a candidate shot carries
CANDIDATE_ID = "candidate"


@dataclass(frozen=True)
class Candidate:
    """One candidate shot (module doc for the dimensions)."""

    angle_deg: float
    rate_deg_s: float
    mach: float
    roll_deg: float = 0.0
    cg_shift_mm: float = 0.0
    stations: int = 0

    def as_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class Template:
    """What candidates are built from: the template shot of a fit problem (:func:`template_of`)."""

    problem: FitProblem              # a one-shot problem: the template at its fitted state
    launch_state: np.ndarray         # (13,) its state at the launch point
    t_launch_s: float
    base: Candidate                  # the template's own values
    x_planes_m: np.ndarray           # its stations' x (the predicted reference point), m
    sigma: np.ndarray                # (N_CHANNELS,) the group's median sigma (NaN: not measured)
    rate_direction: np.ndarray       # (2,) unit (q, r) direction of the transverse rate

    @property
    def shot(self) -> ShotData:
        return self.problem.shots[0]


def template_of(problem: FitProblem, shot_id: str | None = None) -> Template:
    """The template of ``problem`` (a fit's problem at its fitted point): the shot
    ``shot_id`` (default: the one with the most stations, the first of those)."""
    ids = problem.shot_ids
    if shot_id is None:
        k = int(np.argmax([len(s.t_s) for s in problem.shots]))
    elif shot_id in ids:
        k = ids.index(shot_id)
    else:
        raise ValueError(f"plan: no shot {shot_id!r} in the fit (its shots: {', '.join(ids)})")
    sd = problem.shots[k]
    one = replace(problem, shots=(sd,), epoch_states=(problem.epoch_states[k],),
                  local_free=(problem.local_free[k],))
    y_first = one.states_of(0, times=np.array([sd.t_s[0]]))[0]
    t_launch = float(sd.t_s[0] - LEAD_M / y_first[3])
    y = one.states_of(0, times=np.array([t_launch]))[0]
    _, ref = one.physics(0)
    obs = observe(y[None, :], ref)
    v = y[3:6]
    vhat = v / np.linalg.norm(v)
    axis = obs["axis"][0]
    angle = math.degrees(math.acos(float(np.clip(abs(axis @ vhat), -1.0, 1.0))))
    qr = y[11:13]
    rate = float(np.hypot(*qr))
    base = Candidate(angle_deg=angle, rate_deg_s=math.degrees(rate),
                     mach=float(np.linalg.norm(v) / sd.rigid.speed_of_sound_m_s),
                     roll_deg=math.degrees(float(obs["phi_rad"][0])), cg_shift_mm=0.0,
                     stations=len(sd.t_s))
    sig = np.full(sd.sigma.shape[1], np.nan)
    for j in range(sig.size):
        vals = np.concatenate([s.sigma[s.mask[:, j], j] for s in problem.shots])
        if vals.size and sd.mask[:, j].any():
            sig[j] = float(np.median(vals))
    x_planes = one.predict()[0][:, 0]
    return Template(problem=one, launch_state=y, t_launch_s=t_launch, base=base,
                    x_planes_m=x_planes, sigma=sig,
                    rate_direction=qr / rate if rate > 0 else np.array([1.0, 0.0]))


def candidate_launch(template: Template, c: Candidate) -> Launch:
    """The launch of candidate ``c``: the template's launch point and flight path, with the
    candidate's angle, rate, Mach and roll (module doc); t = 0 at the launch point."""
    y = template.launch_state
    sd = template.shot
    _, ref = template.problem.physics(0)
    obs = observe(y[None, :], ref)
    vhat = y[3:6] / np.linalg.norm(y[3:6])
    axis = obs["axis"][0]
    side = 1.0 if axis @ vhat >= 0 else -1.0
    e = axis - (axis @ vhat) * vhat
    if np.linalg.norm(e) < 1e-9:             # no angle in the template: the vertical plane
        e = np.array([0.0, 0.0, 1.0]) - vhat[2] * vhat
    e = e / np.linalg.norm(e)
    a = math.radians(c.angle_deg)
    new_axis = side * math.cos(a) * vhat + math.sin(a) * e
    theta = math.asin(float(np.clip(new_axis[2], -1.0, 1.0)))
    psi = math.asin(float(np.clip(new_axis[1], -1.0, 1.0)))
    rate = math.radians(c.rate_deg_s) * template.rate_direction
    return Launch(x_m=float(obs["x_m"][0]), y_m=float(obs["y_m"][0]), z_m=float(obs["z_m"][0]),
                  speed_m_s=c.mach * sd.rigid.speed_of_sound_m_s,
                  gamma_rad=math.asin(float(vhat[2])),
                  chi_rad=math.atan2(float(vhat[1]), float(vhat[0])),
                  theta_rad=theta, psi_rad=psi, roll_rad=math.radians(c.roll_deg),
                  p_rad_s=float(y[10]), q_rad_s=float(rate[0]), r_rad_s=float(rate[1]))


def candidate_shot(template: Template, c: Candidate, problem: FitProblem | None = None
                   ) -> FitProblem:
    """The one-shot fit problem of candidate ``c``: flown with the fit's physics (``problem``:
    the model and extras to score with, default the template's), sparked where the template's
    stations are, measured without noise in the template's channels with the group's median
    sigmas. Raises ``ValueError`` for a candidate that does not reach its stations."""
    base = problem or template.problem
    sd = template.shot
    n = int(c.stations) if c.stations else len(sd.t_s)
    if not 2 <= n <= len(sd.t_s):
        raise ValueError(f"plan: a candidate's station count must be within 2-{len(sd.t_s)} "
                         f"(the template's), got {n}")
    rigid = sd.rigid
    if c.cg_shift_mm:
        rigid = replace(rigid, cg_from_ref_body_m=rigid.cg_from_ref_body_m
                        + np.array([1e-3 * c.cg_shift_mm, 0.0, 0.0]))
    y0 = candidate_launch(template, c).state(rigid)
    program = base.model.compile()
    params = base.model.values()
    try:
        times = crossing_times(y0, rigid, program, params, template.x_planes_m[:n])
    except (RuntimeError, FloatingPointError) as exc:
        raise ValueError(f"plan: candidate {c} does not reach its stations ({exc})") from None
    shot = ShotData(shot_id=CANDIDATE_ID, rigid=rigid, body_kind=sd.body_kind,
                    stations=sd.stations[:n].copy(), t_s=times,
                    meas=np.zeros((n, sd.meas.shape[1])), sigma=np.ones((n, sd.meas.shape[1])),
                    facility=sd.facility, source={"candidate": c.as_dict()})
    cand = FitProblem((shot,), base.model, (y0,), base.extras, None, base.integration)
    phys, _ = cand.physics(0)
    y_epoch = predict_states(y0, 0.0, times[shot.epoch_index:shot.epoch_index + 1], phys,
                             program, params, base.integration)[0]
    cand = replace(cand, epoch_states=(y_epoch,))
    pred = cand.predict()[0]
    if not np.all(np.isfinite(pred)):
        raise ValueError(f"plan: candidate {c} gives a non-finite flight")
    measured = np.isfinite(template.sigma)
    meas = np.where(measured[None, :], pred, np.nan)
    sigma = np.where(measured[None, :], np.broadcast_to(template.sigma, pred.shape), np.nan)
    shot = replace(shot, meas=meas, sigma=sigma)
    return replace(cand, shots=(shot,), local_free=None)


@dataclass(frozen=True)
class CandidateSpace:
    """The candidates' ranges: ``ranges`` maps a dimension (:data:`DIMENSIONS`) to
    ``(low, high)``; the others stay at the template's value (``base``)."""

    base: Candidate
    ranges: dict = field(default_factory=dict)

    def __post_init__(self):
        ranges = {}
        for name, r in self.ranges.items():
            if name not in DIMENSIONS:
                raise ValueError(f"plan: no candidate dimension {name!r} (they are: "
                                 f"{', '.join(DIMENSIONS)})")
            lo, hi = (float(r[0]), float(r[1])) if np.ndim(r) else (float(r), float(r))
            if not (math.isfinite(lo) and math.isfinite(hi)) or hi < lo:
                raise ValueError(f"plan: the range of {name} must be low <= high, got {r}")
            ranges[name] = (lo, hi)
        object.__setattr__(self, "ranges", ranges)

    @property
    def varied(self) -> tuple[str, ...]:
        """The dimensions with a range of non-zero width, in :data:`DIMENSIONS` order."""
        return tuple(n for n in DIMENSIONS if n in self.ranges
                     and self.ranges[n][1] > self.ranges[n][0])

    def at(self, u: dict) -> Candidate:
        """The candidate at unit coordinates ``u`` (dimension -> [0, 1]) of the varied
        dimensions; fixed ranges at their value, the rest at the template's."""
        vals = self.base.as_dict()
        for name, (lo, hi) in self.ranges.items():
            x = lo + float(np.clip(u.get(name, 0.5), 0.0, 1.0)) * (hi - lo)
            vals[name] = int(round(x)) if name == "stations" else x
        return Candidate(**vals)

    def unit(self, c: Candidate) -> dict:
        """``c``'s unit coordinates in the varied dimensions."""
        return {n: (getattr(c, n) - self.ranges[n][0]) / (self.ranges[n][1] - self.ranges[n][0])
                for n in self.varied}

    def sample(self, n: int, seed: int = 0) -> list[Candidate]:
        """``n`` candidates from a Latin hypercube over the varied dimensions (each
        dimension's range cut in ``n`` equal strata, one candidate in each)."""
        from scipy.stats import qmc

        names = self.varied
        if not names:
            return [self.at({})]
        u = qmc.LatinHypercube(len(names), seed=seed).random(n)
        return [self.at(dict(zip(names, row, strict=True))) for row in u]

    def corners(self) -> list[Candidate]:
        """The corners of the varied ranges (2^d candidates): an information criterion's
        optimum often lies on the boundary, at the most extreme conditions allowed."""
        import itertools

        names = self.varied
        return [self.at(dict(zip(names, u, strict=True)))
                for u in itertools.product((0.0, 1.0), repeat=len(names))]

    def grid(self, points: int) -> list[Candidate]:
        """A regular grid with ``points`` values along each varied dimension (station counts
        at the integers they round to, duplicates dropped)."""
        names = self.varied
        axes = np.meshgrid(*[np.linspace(0.0, 1.0, points) for _ in names], indexing="ij")
        out, seen = [], set()
        for row in zip(*(a.ravel() for a in axes), strict=True):
            c = self.at(dict(zip(names, row, strict=True)))
            if c not in seen:
                seen.add(c)
                out.append(c)
        return out or [self.at({})]
