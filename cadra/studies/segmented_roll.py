"""Seed 003's global segmented fit of pure rolling motion (ROMOF; docs/segmented_roll.md).

Cohen, Clare & Stevens fit Eq. 5 -- the roll acceleration as a Fourier series in 4 gamma times
a power series in p = gamma' d / 2V, plus two asymmetry terms -- to air-bearing roll records
in two phases: the record is cut into segments, each with its own initial conditions
(gamma_0, gamma'_0); first each segment's initial conditions are fitted with the aerodynamics
held, then one set of coefficients and every segment's initial conditions together (a
block-arrow normal matrix, B^jk = 0 for j != k). Here:

- :class:`RollRecord` is one measured roll history; :func:`choose_segments` cuts it as the
  paper does (one oscillation cycle from a zero-rate peak to the next-but-one, 180 deg of roll
  in speed-up, 360 deg in steady spin, a short segment split at a pronounced saddle);
- :func:`segment_shots` makes each segment a :class:`cadra.flight.data.ShotData` that
  measures the roll angle only, :func:`segment_states` its reference state from the smoothed
  record; the fits are :func:`cadra.fitting.fit_shots` calls, so every prediction is the fit
  problem's (the roll-bearing 6-DOF with the aero model, :mod:`cadra.dynamics.modes`);
- :func:`equation_error_start` gives starting values (the smoothed record's acceleration
  regressed on the model's own terms); :func:`segmented_fit` runs the local fit and the
  stepwise global fit (the paper's start set, then the others 3-4 at a time, :data:`STEPS`);
- :func:`records_of` takes the records from roll-bearing shots (:class:`ShotData`), and
  :func:`bearing_alpha` the bearing's angle of attack from their measured axes;
- :func:`coefficient_table`, :func:`correlation_table` (seed 003 Tables 2 and 3, the paper's
  beside them from ``cadra/data``, :mod:`cadra.io.seed003`), :func:`segment_table` (bias,
  rms and runs of sign per segment), :func:`steady_spins` (the roots of the roll-averaged
  C_l(p)); :mod:`cadra.report.roll` writes them.

The model must give Cl linear in its parameters (``cadra/aero/models/seed003_romof.toml``);
the record's roll angle is the aircraft roll about the nose axis, which on a roll bearing with
its axis in the vertical plane is the aerodynamic roll angle phi (gamma of Eq. 5).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd
from scipy.signal import savgol_filter

from cadra import channels
from cadra.aero import AeroModel
from cadra.conventions import axis_from_inclinations
from cadra.dynamics.setup import RigidBody
from cadra.dynamics.trajectory import Launch
from cadra.fitting.result import FitResult
from cadra.fitting.sensitivity import LOCAL_NAMES
from cadra.fitting.solver import FitOptions
from cadra.flight.data import ShotData
from cadra.io import seed003
from cadra.stats import runs_of_sign

#: the paper's start set, then the remaining terms 3-4 at a time (Table 1's order)
STEPS: tuple[tuple[str, ...], ...] = (
    ("S01", "C00", "C10", "C11", "C30", "C_ac", "C_as"),
    ("S02", "S03", "C01"),
    ("S04", "S05", "C02", "C12"),
)
#: Table 2's order
TABLE_ORDER = seed003.table2_order()
#: seed 003 Table 2 (alpha = 57 deg): value, standard deviation, printed signal/noise
PAPER_TABLE2 = seed003.table2()
#: a segment's free local unknowns: its roll angle about the axis and its roll rate
ROLL_LOCALS = np.array([LOCAL_NAMES.index("rot_x_rad"), LOCAL_NAMES.index("p_rad_s")])
SEGMENT_KINDS = ("oscillation", "speed-up", "steady", "saddle")


def paper_correlation() -> pd.DataFrame:
    """Seed 003 Table 3 as a full symmetric matrix (Table 2's order)."""
    return seed003.table3()


# ---------------------------------------------------------------------------- records


@dataclass(frozen=True, eq=False)
class RollRecord:
    """One measured roll history (a run), SI.

    Attributes
    ----------
    name : e.g. ``"run1"``.
    t_s : (n,) frame times, s, increasing (a constant frame rate is not required).
    phi_rad : (n,) measured roll angle, rad, on any branch (0-2 pi as the paper plots it, or
        continuous): consecutive frames must turn by less than pi.
    sigma_rad : the measurement's 1-sigma, rad: one for every frame, or (n,), each frame's.
    note : what was done to the record on its way here (a gap it was split at), for the
        report.
    """

    name: str
    t_s: np.ndarray
    phi_rad: np.ndarray
    sigma_rad: float | np.ndarray
    note: str = ""

    def __post_init__(self):
        t = np.asarray(self.t_s, dtype=float)
        phi = np.asarray(self.phi_rad, dtype=float)
        if t.ndim != 1 or phi.shape != t.shape or t.size < 8:
            raise ValueError(f"{self.name}: t_s and phi_rad must be 1-D of one length >= 8")
        if not (np.all(np.isfinite(t)) and np.all(np.diff(t) > 0) and np.all(np.isfinite(phi))):
            raise ValueError(f"{self.name}: times must increase and every value be finite")
        sig = np.asarray(self.sigma_rad, dtype=float)
        if sig.shape not in ((), t.shape) or not np.all(np.isfinite(sig) & (sig > 0)):
            raise ValueError(f"{self.name}: sigma_rad must be positive and finite, one value "
                             "or one per frame")
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "phi_rad", phi)
        object.__setattr__(self, "sigma_rad", float(sig) if sig.ndim == 0 else sig)

    @property
    def sigmas(self) -> np.ndarray:
        """(n,) each frame's sigma, rad."""
        return np.broadcast_to(np.asarray(self.sigma_rad, dtype=float), self.t_s.shape)


def smoothed_roll(record: RollRecord, window: int = 11, order: int = 3):
    """The continuous roll angle, its rate and acceleration from a Savitzky-Golay filter of
    ``window`` frames (rad, rad/s, rad/s^2; the mean frame interval as the step)."""
    phi = np.unwrap(record.phi_rad)
    dt = float(np.mean(np.diff(record.t_s)))
    w = min(window | 1, len(phi) - 1 + len(phi) % 2)     # odd, at most the record
    return (savgol_filter(phi, w, order), savgol_filter(phi, w, order, deriv=1, delta=dt),
            savgol_filter(phi, w, order, deriv=2, delta=dt))


@dataclass(frozen=True)
class Segment:
    """Frames ``start`` to ``stop - 1`` of record ``record``, fitted with their own initial
    conditions; ``kind`` one of :data:`SEGMENT_KINDS`."""

    record: str
    index: int
    start: int
    stop: int
    kind: str

    @property
    def shot_id(self) -> str:
        return f"{self.record}:{self.index:03d}"

    @property
    def n(self) -> int:
        return self.stop - self.start


def zero_rate_points(record: RollRecord, window: int = 11) -> np.ndarray:
    """Frame indices of the zero-rate peaks of the oscillation: where the smoothed rate
    changes sign, at the frame of smaller |rate|; two sign changes closer than ``window``
    frames (the rate touching zero near a saddle without a reversal, or noise) are dropped."""
    _, rate, _ = smoothed_roll(record, window)
    s = np.sign(rate)
    idx = np.where(s[1:] * s[:-1] < 0)[0]
    idx = np.where(np.abs(rate[idx + 1]) < np.abs(rate[idx]), idx + 1, idx)
    keep = (idx >= window // 2) & (idx < len(rate) - window // 2)   # filter's edges
    for i in range(idx.size - 1):
        if keep[i] and idx[i + 1] - idx[i] < window:
            keep[i] = keep[i + 1] = False
    return idx[keep]


def _split_saddles(a: int, b: int, kind: str, rate: np.ndarray, peaks: np.ndarray,
                   fraction: float, min_points: int) -> list[tuple[int, int, str]]:
    """Frames a..b-1 split at each interior slow-down of the rate below ``fraction`` of the
    piece's median |rate| (a saddle), at least ``min_points`` from the ends and from a
    zero-rate peak; the pieces of a split are kind ``saddle``."""
    r = np.abs(rate[a:b])
    inner = np.arange(min_points, b - a - min_points)
    if peaks.size:
        inner = inner[np.min(np.abs(a + inner[:, None] - peaks[None, :]), axis=1) >= min_points]
    if inner.size == 0 or r[inner].min() >= fraction * np.median(r):
        return [(a, b, kind)]
    c = a + int(inner[np.argmin(r[inner])])
    return (_split_saddles(a, c, "saddle", rate, peaks, fraction, min_points)
            + _split_saddles(c, b, "saddle", rate, peaks, fraction, min_points))


def choose_segments(record: RollRecord, *, window: int = 11, steady_tol: float = 0.03,
                    saddle_fraction: float = 0.35, min_points: int = 8) -> list[Segment]:
    """Cut ``record`` as seed 003 does (module doc).

    Oscillation: from each zero-rate peak (:func:`zero_rate_points`) to the next-but-one (one
    cycle), a lone half swing at the end; the frames before the first peak are a segment of
    their own. After the last peak (break-out) the roll turns one way: a segment every 180 deg
    of roll (speed-up), merged in pairs to 360 deg where the mean rate of the half-revolution
    before and after differs by less than ``steady_tol`` of its own (steady spin). A segment
    in which the smoothed rate falls below ``saddle_fraction`` of its median away from its
    ends and its zero-rate peaks is split there, repeatedly (kind ``saddle``: the paper's
    short segments where the motion lingers near a saddle point). Pieces of fewer than
    ``min_points`` frames join the segment before them.
    """
    phi, rate, _ = smoothed_roll(record, window)
    n = len(phi)
    peaks = zero_rate_points(record, window)
    bounds: list[tuple[int, int, str]] = []
    first = int(peaks[0]) if peaks.size else 0
    if first > 0:
        bounds.append((0, first, "oscillation"))
    for i in range(0, max(peaks.size - 1, 0), 2):
        bounds.append((int(peaks[i]), int(peaks[min(i + 2, peaks.size - 1)]), "oscillation"))
    last = int(peaks[-1]) if peaks.size else 0
    # the rotating part: boundaries at every pi of roll from the last peak
    if last < n - 1:
        rel = (phi[last:] - phi[last]) * np.sign(rate[min(last + 1, n - 1)] or 1.0)
        turns = np.floor(rel / math.pi)
        cuts = last + np.where(np.diff(turns) > 0)[0] + 1
        edges = [last, *cuts.tolist()]
        if edges[-1] != n:
            edges.append(n)
        halves = list(zip(edges[:-1], edges[1:], strict=True))
        mean_rate = np.array([abs(phi[min(b, n - 1)] - phi[a]) / max(
            record.t_s[min(b, n - 1)] - record.t_s[a], 1e-12) for a, b in halves])
        steady = np.zeros(len(halves), dtype=bool)
        for h in range(1, len(halves) - 1):
            steady[h] = abs(mean_rate[h + 1] - mean_rate[h - 1]) < steady_tol * mean_rate[h]
        h = 0
        while h < len(halves):
            a, b = halves[h]
            if steady[h] and h + 1 < len(halves) and steady[h + 1]:
                bounds.append((a, halves[h + 1][1], "steady"))
                h += 2
                continue
            bounds.append((a, b, "speed-up"))
            h += 1
    out: list[tuple[int, int, str]] = []
    for a, b, kind in bounds:
        out += _split_saddles(a, b, kind, rate, peaks, saddle_fraction, min_points)
    merged: list[list] = []
    for a, b, kind in out:
        if merged and (b - a < min_points or merged[-1][1] - merged[-1][0] < min_points):
            merged[-1][1] = b
        else:
            merged.append([a, b, kind])
    return [Segment(record.name, k, a, b, kind) for k, (a, b, kind) in enumerate(merged)]


# ---------------------------------------------------------------------------- fit data


def segment_shots(record: RollRecord, segments: Sequence[Segment], rigid: RigidBody
                  ) -> list[ShotData]:
    """Each segment as a :class:`ShotData` that measures the roll angle only (station ids are
    the record's frame numbers)."""
    k = channels.NAMES.index("phi")
    out = []
    for seg in segments:
        sl = slice(seg.start, seg.stop)
        n = seg.n
        meas = np.full((n, channels.N_CHANNELS), np.nan)
        sigma = np.full((n, channels.N_CHANNELS), np.nan)
        meas[:, k] = record.phi_rad[sl]
        sigma[:, k] = record.sigmas[sl]
        out.append(ShotData(shot_id=seg.shot_id, rigid=rigid, body_kind="finner",
                            stations=np.arange(seg.start, seg.stop), t_s=record.t_s[sl].copy(),
                            meas=meas, sigma=sigma,
                            source={"origin": f"roll record {record.name}",
                                    "segment_kind": seg.kind}))
    return out


def segment_states(record: RollRecord, segments: Sequence[Segment], rigid: RigidBody,
                   alpha_rad: float, *, window: int = 11) -> list[np.ndarray]:
    """Each segment's (13,) reference state at its epoch (its middle frame,
    ``ShotData.epoch_index``): the bearing's axis at ``alpha_rad`` in the vertical plane, the
    smoothed roll angle and rate of the record there."""
    phi, rate, _ = smoothed_roll(record, window)
    out = []
    for seg in segments:
        e = seg.start + seg.n // 2
        out.append(Launch(speed_m_s=0.0, theta_rad=alpha_rad, roll_rad=float(phi[e]),
                          p_rad_s=float(rate[e])).state(rigid))
    return out


def roll_constants(rigid: RigidBody) -> tuple[float, float]:
    """(Q, d / 2V) of Eq. 5: Q = q A d / I_x about the bearing axis (1/s^2), V the stream."""
    V = rigid.mode.stream_m_s
    piv = np.asarray(rigid.mode.pivot_from_cg_body_m)
    Ix = rigid.inertia_body_kg_m2[0, 0] + rigid.mass_kg * (piv[1] ** 2 + piv[2] ** 2)
    return 0.5 * rigid.density_kg_m3 * V * V * rigid.area_m2 * rigid.d_m / Ix, rigid.d_m / (2 * V)


def _basis(model: AeroModel, names: Sequence[str], phi, p_hat, mach: float,
           alpha: float) -> np.ndarray:
    """(n, len(names)) the model's Cl per unit of each parameter (Cl is linear in them)."""
    cols = []
    for nm in names:
        e = np.zeros(len(model.names))
        e[model.index(nm)] = 1.0
        cols.append(np.asarray(model.evaluate(alpha, 0.0, alpha, mach, p_hat=p_hat, phi=phi,
                                              params=e)["Cl"], dtype=float))
    return np.column_stack(cols)


def equation_error_start(records: Sequence[RollRecord], model: AeroModel, rigid: RigidBody,
                         names: Sequence[str], *, alpha_rad: float, window: int = 11
                         ) -> AeroModel:
    """``model`` with ``names`` set by equation error: the smoothed records' acceleration
    divided by Q regressed on the model's Cl terms at the smoothed roll angle and rate and
    the bearing's angle of attack ``alpha_rad`` (the other parameters at their values).
    Rough (differentiated noise), but no guess."""
    Q, kd = roll_constants(rigid)
    mach = rigid.mode.stream_m_s / rigid.speed_of_sound_m_s
    zero = np.zeros(len(model.names))
    rows, rhs = [], []
    for rec in records:
        phi, rate, acc = smoothed_roll(rec, window)
        w = min(window | 1, len(phi) - 1 + len(phi) % 2)
        sl = slice(window, len(phi) - window)
        p_hat = rate * kd
        rest = model.values().copy()
        for nm in names:
            rest[model.index(nm)] = 0.0
        args = (alpha_rad, 0.0, alpha_rad, mach)
        other = np.asarray(model.evaluate(*args, p_hat=p_hat, phi=phi, params=rest)["Cl"],
                           dtype=float)
        if not np.allclose(model.evaluate(*args, p_hat=p_hat, phi=phi, params=zero)["Cl"],
                           0.0):
            raise ValueError(f"model {model.name}: Cl is not linear in its parameters")
        # the filter's attenuation of the fast (4k gamma) terms, given to both sides
        basis = savgol_filter(_basis(model, names, phi, p_hat, mach, alpha_rad), w, 3, axis=0)
        rows.append(basis[sl])
        rhs.append(acc[sl] / Q - savgol_filter(other, w, 3)[sl])
    c, *_ = np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=None)
    return model.with_values(dict(zip(names, map(float, c), strict=True)))


# ---------------------------------------------------------------------------- the fits


@dataclass(frozen=True, eq=False)
class SegmentedFit:
    """A global segmented fit: the segments, their shots, the local fit with the
    aerodynamics held (phase 1) and each global step's result (phase 2; the last is the
    answer, :attr:`result`)."""

    segments: tuple[Segment, ...]
    shots: tuple[ShotData, ...]
    local: FitResult
    steps: tuple[FitResult, ...]
    step_names: tuple[tuple[str, ...], ...]
    start: AeroModel
    notes: tuple[str, ...] = field(default_factory=tuple)

    @property
    def result(self) -> FitResult:
        return self.steps[-1] if self.steps else self.local


def _states_of(result: FitResult) -> list[np.ndarray]:
    return [sf.state for sf in result.shots]


def fit_segments(shots: Sequence[ShotData], model: AeroModel, states: Sequence[np.ndarray],
                 *, options: FitOptions | None = None) -> FitResult:
    """One global fit of ``model``'s free parameters and every segment's roll angle and rate
    (:func:`cadra.fitting.fit_shots`, the block-arrow solver), from ``states``."""
    from cadra.fitting import fit_shots

    result, _ = fit_shots(list(shots), model, options=options, auto_start=False,
                          initial=list(states), continuation=None,
                          local_free=[ROLL_LOCALS] * len(shots))
    return result


def segmented_fit(records: Sequence[RollRecord], model: AeroModel, rigid: RigidBody,
                  alpha_rad: float, *, steps: Sequence[Sequence[str]] = STEPS,
                  start: AeroModel | None = None, options: FitOptions | None = None,
                  window: int = 11, segments: Sequence[Segment] | None = None
                  ) -> SegmentedFit:
    """Seed 003's procedure on ``records`` (one body, one flight condition).

    1. segments (:func:`choose_segments`, or ``segments``) and their reference states from
       the smoothed records;
    2. ``start`` (default: every parameter of ``steps`` at 0, the first step's by
       :func:`equation_error_start`) with the aerodynamics held: each segment's roll angle
       and rate alone;
    3. the global fit with ``steps[0]`` free, then each further step's parameters freed from
       the previous step's solution (new ones start at ``start``'s values), every segment's
       initial conditions refitted with them. Parameters of ``model`` in no step are held at
       their values.
    """
    options = options or FitOptions()
    records = list(records)
    segs = (list(segments) if segments is not None else
            [s for r in records for s in choose_segments(r, window=window)])
    shots, states = [], []
    for r in records:
        mine = [s for s in segs if s.record == r.name]
        shots += segment_shots(r, mine, rigid)
        states += segment_states(r, mine, rigid, alpha_rad, window=window)
    stepped = [n for st in steps for n in st]
    if start is None:
        start = model.with_values({n: 0.0 for n in stepped})
        start = equation_error_start(records, start, rigid, list(steps[0]),
                                     alpha_rad=alpha_rad, window=window)
    held = start.with_vary({n: False for n in start.names})
    local = fit_segments(shots, held, states, options=options)
    notes = [r.note for r in records if r.note]
    if not local.converged:
        notes.append(f"local fit: {local.status}")
    results, current = [], start
    prev = local
    free: list[str] = []
    for st in steps:
        free += list(st)
        trial = current.with_vary({n: n in free for n in current.names})
        res = fit_segments(shots, trial, _states_of(prev), options=options)
        if not res.converged:
            notes.append(f"step {len(results) + 1} ({', '.join(st)}): {res.status}")
        results.append(res)
        prev = res
        current = res.model
    return SegmentedFit(tuple(segs), tuple(shots), local, tuple(results),
                        tuple(tuple(s) for s in steps), start, tuple(notes))


# ---------------------------------------------------------------------------- tables


def coefficient_table(result: FitResult, paper: Mapping | None = None) -> pd.DataFrame:
    """Seed 003 Table 2's layout: per free coefficient (Table 2's order first) the value, its
    sigma and signal/noise c / sigma; with ``paper`` (default :data:`PAPER_TABLE2`) the
    paper's value, sigma and printed signal/noise and our signal/noise over the paper's."""
    paper = PAPER_TABLE2 if paper is None else paper
    names = [n for n in TABLE_ORDER if n in result.aero_names]
    names += [n for n in result.aero_names if n not in names]
    rows = []
    for nm in names:
        c, s = result.value(nm), result.sigma(nm)
        row = {"coefficient": nm, "value": c, "sigma": s,
               "signal_noise": abs(c) / s if s > 0 else math.inf}
        if nm in paper:
            pv, ps, pr = paper[nm]
            row |= {"paper_value": pv, "paper_sigma": ps, "paper_signal_noise": pr,
                    "snr_over_paper": row["signal_noise"] / abs(pv / ps)}
        rows.append(row)
    return pd.DataFrame(rows).set_index("coefficient")


def correlation_table(result: FitResult) -> pd.DataFrame:
    """The free coefficients' correlation matrix (signed), Table 3's order."""
    names = [n for n in TABLE_ORDER if n in result.aero_names]
    names += [n for n in result.aero_names if n not in names]
    R = result.correlation()
    idx = [result.param_names.index(n) for n in names]
    return pd.DataFrame(R[np.ix_(idx, idx)], index=names, columns=names)


def segment_table(fit: SegmentedFit | FitResult) -> pd.DataFrame:
    """Per segment: record, kind, frames, time span, the roll residuals' bias and rms (deg),
    the runs of sign (:func:`cadra.stats.runs_of_sign`) and the longest run in seconds."""
    result = fit.result if isinstance(fit, SegmentedFit) else fit
    kinds = ({s.shot_id: s.kind for s in fit.segments} if isinstance(fit, SegmentedFit)
             else {})
    res = result.residuals
    res = res[res["channel"] == "phi"]
    rows = []
    for sid, g in res.groupby("shot_id", sort=False):
        r = g["residual"].to_numpy()
        t = g["t_s"].to_numpy()
        runs = runs_of_sign(r)
        dt = float(np.median(np.diff(t))) if t.size > 1 else math.nan
        rows.append({"segment": sid, "record": sid.split(":")[0], "kind": kinds.get(sid, ""),
                     "frames": int(r.size), "t0_s": float(t[0]), "t1_s": float(t[-1]),
                     "bias_deg": math.degrees(float(r.mean())),
                     "rms_deg": math.degrees(float(np.sqrt(np.mean(r * r)))),
                     "runs": runs.runs, "expected_runs": runs.expected,
                     "runs_z": runs.z, "longest_run": runs.longest,
                     "longest_run_s": runs.longest * dt})
    return pd.DataFrame(rows).set_index("segment")


def steady_spins(values: Mapping[str, float] | AeroModel) -> pd.DataFrame:
    """The steady spins of the roll-averaged moment C_l(p) = sum_j C_j0 p^j (the k = 0 terms;
    C00 + C10 p + C30 p^3 for Table 2): real roots p of numpy's ``roots``, the slope dC_l/dp
    there and ``stable`` (slope < 0), in increasing p."""
    if isinstance(values, AeroModel):
        values = {n: float(values.parameter(n).value) for n in values.names}
    js = [j for j in range(10) if f"C{j}0" in values]
    if not js:
        raise ValueError("no C_j0 coefficient: no roll-averaged moment")
    c = np.zeros(max(js) + 1)
    for j in js:
        c[j] = float(values[f"C{j}0"])
    poly = np.polynomial.Polynomial(c).trim()
    if poly.degree() < 1:
        return pd.DataFrame(columns=["p_hat", "slope", "stable"])
    roots = np.roots(poly.coef[::-1])
    real = np.sort(roots[np.abs(roots.imag) <= 1e-9 * np.maximum(1.0, np.abs(roots))].real)
    slope = poly.deriv()(real)
    return pd.DataFrame({"p_hat": real, "slope": slope, "stable": slope < 0})


def steady_spin_sigmas(result: FitResult) -> pd.DataFrame:
    """:func:`steady_spins` of ``result`` with each root's sigma from the fitted covariance
    of the C_j0 (linearised: dp = -dC / slope, with dC = sum p^j dC_j0)."""
    values = {n: float(result.model.parameter(n).value) for n in result.model.names}
    tab = steady_spins(values)
    js = [j for j in range(10) if f"C{j}0" in result.aero_names]
    idx = [result.param_names.index(f"C{j}0") for j in js]
    C = result.covariance[np.ix_(idx, idx)]
    sig = []
    for p, sl in zip(tab["p_hat"], tab["slope"], strict=True):
        g = np.array([p**j for j in js]) / -sl
        sig.append(math.sqrt(max(float(g @ C @ g), 0.0)))
    return tab.assign(sigma=sig)


def seed003_tables(fit: SegmentedFit | FitResult) -> dict[str, pd.DataFrame]:
    """The report's tables: ``table2`` (:func:`coefficient_table`), ``table3``
    (:func:`correlation_table`), ``paper_table3`` (:func:`paper_correlation`), ``segments``
    (:func:`segment_table`), ``steady_spins`` (:func:`steady_spin_sigmas`)."""
    result = fit.result if isinstance(fit, SegmentedFit) else fit
    return {"table2": coefficient_table(result), "table3": correlation_table(result),
            "paper_table3": paper_correlation(), "segments": segment_table(fit),
            "steady_spins": steady_spin_sigmas(result)}


# ---------------------------------------------------------------------------- records of shots


def bearing_alpha(shots, alpha_deg: float | None) -> float:
    """The bearing's angle of attack (rad): ``alpha_deg`` when given, else the angle between
    the mean measured nose axis and the stream (+x of F)."""
    if alpha_deg is not None:
        if not (0.0 < alpha_deg < 90.0):
            raise ValueError(f"alpha_deg (--alpha-deg): {alpha_deg:g} is not an angle of attack "
                             "in (0, 90)")
        return math.radians(alpha_deg)
    th, ps = channels.NAMES.index("theta"), channels.NAMES.index("psi")
    axes = [axis_from_inclinations(m[th], m[ps]) for s in shots for m in s.meas
            if np.isfinite(m[th]) and np.isfinite(m[ps])]
    if not axes:
        raise ValueError("the records measure no nose axis (theta, psi): give --alpha-deg")
    a = np.mean(axes, axis=0)
    a /= np.linalg.norm(a)
    if abs(a[1]) > math.sin(math.radians(0.5)):
        raise ValueError(f"the measured axis is {math.degrees(math.asin(a[1])):.2f} deg out of "
                         "the vertical plane: the segments' states put it in that plane; "
                         "give --alpha-deg to accept that")
    return math.acos(float(np.clip(a[0], -1.0, 1.0)))


#: frames further apart than this many times the record's typical interval are a gap: the
#: roll across it is unknown (it may have turned by more than pi), so the record is split
GAP_FRAMES = 1.5


def _split_at_gaps(shot_id: str, name, t, phi, sigmas) -> list:
    """The record as one :class:`RollRecord`, or as pieces split where frames are lost (each
    unwrapped on its own, named ``ID.1``, ``ID.2``, ...; a piece under 8 frames dropped),
    each piece's ``note`` saying why."""
    dt = np.diff(t)
    typical = float(np.median(dt))
    cuts = np.flatnonzero(dt > GAP_FRAMES * typical) + 1
    if cuts.size == 0:
        return [RollRecord(shot_id, t, np.unwrap(phi), sigmas)]
    said = "; ".join(f"{int(round(dt[c - 1] / typical)) - 1} frame(s) lost at t = "
                     f"{t[c - 1]:.4g}-{t[c]:.4g} s" for c in cuts)
    note = (f"{name}: {said}: the roll across a gap is unknown (it may turn by more than "
            f"pi), so the record is split there into {cuts.size + 1} pieces fitted apart")
    out, dropped = [], 0
    for k, (a, b) in enumerate(zip([0, *cuts], [*cuts, len(t)], strict=True)):
        if b - a < 8:
            dropped += 1
            continue
        out.append(RollRecord(f"{shot_id}.{k + 1}", t[a:b], np.unwrap(phi[a:b]),
                              sigmas[a:b], note=note if not out else ""))
    if dropped and out:
        out[0] = replace(out[0], note=f"{note} ({dropped} piece(s) under 8 frames left out)")
    return out


def records_of(shots):
    """A :class:`~cadra.studies.segmented_roll.RollRecord` of each roll-bearing shot."""
    k = channels.NAMES.index("phi")
    out = []
    for s in shots:
        name = s.source.get("trajectory_file", s.shot_id)
        if s.rigid.mode.kind != "roll_bearing":
            raise ValueError(f"{name}: a {s.rigid.mode.kind!r} record; cadra2 roll fits roll "
                             "bearings (the shot file's [test_mode] kind = 'roll_bearing')")
        ok = np.isfinite(s.meas[:, k])
        if ok.sum() < 8:
            raise ValueError(f"{name}: {int(ok.sum())} frame(s) with a measured roll (phi); "
                             "a roll record needs at least 8")
        t, phi, sigmas = s.t_s[ok], s.meas[ok, k], s.sigma[ok, k]   # each frame's own sigma
        sigma = float(np.median(sigmas))
        whole = np.unwrap(phi)
        if not float(np.std(whole)) > 3.0 * sigma:
            raise ValueError(f"{name}: the roll angle scatters {np.degrees(np.std(whole)):.3g} "
                             f"deg rms about its mean, {np.std(whole) / max(sigma, 1e-300):.2g}"
                             " of its sigma: no roll motion above the noise, nothing to fit")
        out += _split_at_gaps(s.shot_id, name, t, phi, sigmas)
    if not out:
        raise ValueError("no piece of any record is long enough to fit (8 frames)")
    r0 = shots[0].rigid
    for s in shots[1:]:
        if (s.rigid.mode != r0.mode or not np.allclose(s.rigid.phys(), r0.phys())):
            raise ValueError(f"{s.shot_id}: another body, air or bearing than "
                             f"{shots[0].shot_id}'s; one segmented fit is one flight "
                             "condition")
    return out


__all__ = ["PAPER_TABLE2", "ROLL_LOCALS", "STEPS", "TABLE_ORDER", "RollRecord", "Segment",
           "SegmentedFit", "bearing_alpha", "choose_segments", "coefficient_table",
           "correlation_table", "equation_error_start", "fit_segments", "paper_correlation",
           "records_of", "roll_constants", "seed003_tables", "segment_shots", "segment_states",
           "segment_table", "segmented_fit", "smoothed_roll", "steady_spin_sigmas",
           "steady_spins", "zero_rate_points"]
