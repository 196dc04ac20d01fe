"""Sphere calibration shots: per-station measurement biases (seed 004, "Uncertainties").

A sphere's aerodynamics are simple (drag only, C_D a weak function of Mach), so what remains
of its trajectory fit at a station, consistently over several sphere shots, is that station's
bias. Model (docs/calibration.md):

    measured_{s,k} = true position of shot s at station k + b_k + v_{s,k} dt_k + noise

with ``b_k`` the station's position bias (x, y, z; what the station adds to every measured
position, e.g. a survey error of its fiducial wires) and ``dt_k`` its timing bias (the spark
really fires ``dt_k`` after the recorded time, so the model is seen ``v dt_k`` further on).
Shots at different speeds separate an x-survey bias from a timing bias.

Not every bias is observable: a common offset of all stations, or one growing linearly along
the range, is the same as a change of each shot's initial position or velocity
(docs/calibration.md). Along the range (x) and in time it is worse: a bias pattern quadratic in the
stations' x is the same as a change of the drag level (b = c x^2 looks like a deceleration
2 c V^2, the same Delta C_D for every shot), and a quadratic timing pattern the same as a change
of the drag's Mach slope. These patterns are roughly polynomials in the stations' x (degree 1
for y and z, 2 for x and time), but only roughly -- the drag-absorbed pattern is only nearly
quadratic, and decelerating shots do not see a trend in x as a trend in time exactly. So the
estimator imposes no polynomial: it estimates every station's bias, takes the unobservable
directions from the null space of the normal matrix, and reports the estimate in the *robust
gauge* (:func:`robust_gauge`): the null-space component that puts the unbiased majority of
the stations at ~0, so a biased station reads its full size.

Method: the sphere shots are fitted together (point mass: the 6-DOF code with the sphere
model; each shot's position and velocity, one drag law C_D(M) shared by all, :mod:`cadra.fitting`);
at the solution the station-bias problem is linear: with ``J`` the stacked weighted Jacobian of
every fitted unknown and ``D`` the weighted design of the biases, ``r = (I - P) D beta + noise``
where ``P`` projects on the columns of ``J`` (what the shots' own unknowns and the drag law
absorb). The normal equations give ``beta`` and its covariance; the data are then corrected,
the shots refitted and the estimate refined (three passes).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from cadra.aero import AeroModel, load_bundled_model
from cadra.channels import POSITION
from cadra.fitting import FitOptions, fit_shots
from cadra.fitting.problem import result_problem
from cadra.flight import ShotData

#: bias channels: position x, y, z (m) and spark time (s)
BIAS_CHANNELS = ("x", "y", "z", "time")
#: fewest stations a sphere shot must have for the check
MIN_STATIONS = 6


class CalibrationError(ValueError):
    """Input the sphere check refuses; the message says why."""


@dataclass(frozen=True, eq=False)
class StationBiasEstimate:
    """Station biases from sphere shots (SI; channels :data:`BIAS_CHANNELS`).

    ``bias``/``sigma`` (n, 4); sigma NaN where a channel was not estimated (bias 0 there).
    ``covariance`` is that of the estimate in the robust gauge, mapped to stations:
    (n*4, n*4) in station-major order. ``shot_rms_before``/``after``: per shot, residual rms of
    x, y, z (m) before and after correcting the data by the estimate.
    """

    facility: str
    stations: np.ndarray
    bias: np.ndarray
    sigma: np.ndarray
    covariance: np.ndarray
    shots: tuple[str, ...]
    shot_speeds_m_s: tuple[float, ...]
    timing_estimated: bool
    chi2: float
    dof: int
    shot_rms_before: dict
    shot_rms_after: dict
    warnings: tuple[str, ...]
    method: str

    def to_table(self, created_utc: str | None = None, note: str = ""):
        """The estimate as a :class:`cadra.calibration.history.BiasTable`."""
        from cadra.calibration.history import BiasTable, utc_now

        return BiasTable(facility=self.facility, created_utc=created_utc or utc_now(),
                         stations=self.stations.copy(), bias=self.bias.copy(),
                         sigma=self.sigma.copy(), shots=self.shots, method=self.method,
                         note=note)


#: relative eigenvalue (scaled normal matrix) below which a bias direction counts as
#: unobservable. Measured on the sphere samples: 4 exact zeros (common offsets of x, y, z and
#: time), 6 near zeros 1e-9..2e-7 (trends along the range, which decelerating shots do not see
#: exactly as trends in time, and the drag-like curvature of x and time), then a gap to 2e-2:
#: the 10 directions below the gap are the gauge (determined ~1e3 times worse than any bias).
NULL_RCOND = 1e-5
#: Tukey biweight constant of the robust gauge, in sigma
TUKEY_C = 4.685


def robust_gauge(beta: np.ndarray, cov: np.ndarray, null: np.ndarray, k: float = 2.0,
                 iterations: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """Add to the minimum-norm estimate ``beta`` the unobservable part (columns of ``null``)
    that makes most stations read zero (Huber weights, ``k`` sigma), and carry ``cov``
    through the final-weight linear map. Any null-space component can be added without
    changing the fit; this one puts a sparse set of biased stations at their full size and
    the unbiased majority at ~0 (module doc)."""
    if null.shape[1] == 0:
        return beta, cov
    from scipy.optimize import least_squares

    # an orthonormal basis of the same directions (the raw vectors differ in size by many
    # orders of magnitude between the position and timing channels)
    null, _ = np.linalg.qr(null / np.linalg.norm(null, axis=0))

    sig = np.sqrt(np.maximum(np.diag(cov), 1e-300))
    # robust start (soft L1), then Huber iterations from its weights
    sol = least_squares(lambda c: (beta + null @ c) / sig, np.zeros(null.shape[1]),
                        loss="soft_l1", f_scale=k, x_scale="jac", max_nfev=2000)
    r0 = np.abs(beta + null @ sol.x) / sig
    w = np.minimum(1.0, k / np.maximum(r0, 1e-12))
    # Huber iterations, then Tukey's biweight (redescending: a biased station, thousands of
    # sigma off, then has no say at all in the gauge)
    for weight in (lambda r: np.minimum(1.0, k / np.maximum(r, 1e-12)),
                   lambda r: np.where(r < TUKEY_C, (1 - (r / TUKEY_C) ** 2) ** 2, 0.0)):
        for _ in range(iterations):
            W = w / sig**2
            c = -np.linalg.lstsq(null.T @ (null * W[:, None]), null.T @ (W * beta),
                                 rcond=None)[0]
            r = np.abs(beta + null @ c) / sig
            w_new = weight(r)
            if np.allclose(w_new, w, rtol=1e-7, atol=1e-10):
                break
            w = w_new
    W = w / sig**2
    H = null @ np.linalg.lstsq(null.T @ (null * W[:, None]), (null * W[:, None]).T,
                               rcond=None)[0]
    T = np.eye(beta.size) - H
    return T @ beta, T @ cov @ T.T


def check_sphere_shot(shot: ShotData) -> None:
    """Refuse what the sphere check cannot use (with the reason)."""
    if shot.body_kind != "sphere":
        raise CalibrationError(f"{shot.shot_id} is a {shot.body_kind} shot: the sphere check "
                               "needs sphere calibration shots (point-mass aerodynamics)")
    n = int(np.isfinite(shot.meas[:, POSITION]).all(axis=1).sum())
    if n < MIN_STATIONS:
        raise CalibrationError(f"{shot.shot_id}: {n} stations with a position; the sphere "
                               f"check needs at least {MIN_STATIONS}")


def _velocity_at_stations(shot: ShotData) -> np.ndarray:
    """(n, 3) velocity at each station from quadratic fits of the measured positions."""
    t = shot.t_s - shot.t_s.mean()
    v = np.zeros((len(t), 3))
    for j in range(3):
        ok = np.isfinite(shot.meas[:, j])
        c = np.polyfit(t[ok], shot.meas[ok, j], 2)
        v[:, j] = np.polyval(np.polyder(c), t)
    return v


def _design(shot: ShotData, index: dict, nc: int, v: np.ndarray) -> np.ndarray:
    """Design (n, 3, n_stations * nc) of the station biases for one shot (unweighted),
    station-major: column ``k * nc + c`` is station k's channel c (x, y, z, and time when
    ``nc == 4``: a timing bias dt moves the image by v dt, ``v`` (n, 3) the shot's velocity at
    its stations)."""
    D = np.zeros((len(shot.t_s), 3, len(index) * nc))
    for i, st in enumerate(shot.stations):
        k = index.get(int(st))
        if k is None:
            continue
        for c in range(3):
            D[i, c, k * nc + c] = 1.0
        if nc == 4:
            D[i, :, k * nc + 3] = v[i]
    return D


def _corrected(shots, designs, beta):
    """The shots with the biases ``beta`` (through each shot's design) taken out."""
    out = []
    for s, D in zip(shots, designs, strict=True):
        meas = s.meas.copy()
        meas[:, POSITION] -= D @ beta
        out.append(replace(s, meas=meas))
    return out


def _joint_fit(shots: list[ShotData], model: AeroModel, options: FitOptions):
    """Multi-fit of the sphere shots (one drag law, each shot's own position and velocity);
    per shot the prediction, the Jacobian (n, N_CHANNELS, n_local + n_aero: the shot's free
    locals -- position and velocity for a sphere --, then the drag law's free parameters)
    at the solution, the cg velocity at the stations and the number of local columns. All
    from the fit's own forward model (:class:`cadra.fitting.problem.FitProblem`)."""
    res, _ = fit_shots(shots, model, options=options)
    problem = replace(result_problem(res, shots), integration=options.integration)
    preds, jacs, states = problem.predict_with_jacobian(with_states=True)
    out = [(pred, J, y[:, 3:6], int(lf.size))
           for pred, J, y, lf in zip(preds, jacs, states, problem.local_free, strict=True)]
    return res, out


def estimate_station_biases(shots: Sequence[ShotData], *, facility: str = "",
                            model: AeroModel | None = None, timing: bool | None = None,
                            options: FitOptions | None = None,
                            passes: int = 3) -> StationBiasEstimate:
    """Station biases (x, y, z and timing) from sphere shots; see the module doc.

    ``timing``: estimate timing biases (default: when the shots' speeds differ by more than
    10 %, which is what separates them from x-survey biases; otherwise they are not estimated
    and a warning says why).
    """
    shots = list(shots)
    if not shots:
        raise CalibrationError("no sphere shots given")
    for s in shots:
        check_sphere_shot(s)
    if len({s.shot_id for s in shots}) != len(shots):
        raise CalibrationError("a shot is listed twice")
    options = options or FitOptions()
    model = model or load_bundled_model("sphere")
    warnings: list[str] = []
    stations = np.array(sorted({int(st) for s in shots for st in s.stations}))
    index = {int(st): k for k, st in enumerate(stations)}
    speeds = tuple(float(np.median(np.linalg.norm(_velocity_at_stations(s), axis=1)))
                   for s in shots)
    spread = (max(speeds) - min(speeds)) / max(np.mean(speeds), 1e-9)
    if timing is None:
        timing = len(shots) >= 2 and spread > 0.10
        if not timing:
            warnings.append(
                "timing biases not estimated: the shots' speeds differ by "
                f"{100 * spread:.0f} % (an x-survey bias and a timing bias look alike unless "
                "the shots fly at clearly different speeds)")
    if len(stations) < MIN_STATIONS:
        raise CalibrationError(f"{len(stations)} stations: at least {MIN_STATIONS} are needed "
                               "(a common offset, trend and, along the range, curvature are "
                               "not observable)")
    channels = BIAS_CHANNELS if timing else BIAS_CHANNELS[:3]
    nS, nc = len(stations), len(channels)
    n_beta = nS * nc                     # station-major: beta[k * nc + c]
    beta = np.zeros(n_beta)
    # first pass: velocities from the measurements; later passes: from the fitted trajectories
    designs = [_design(s, index, nc, _velocity_at_stations(s)) for s in shots]
    rms_before = {}
    rms_after = {}
    chi2 = 0.0
    dof = 0
    cov_b = np.zeros((n_beta, n_beta))
    null = np.zeros((n_beta, 0))
    for p in range(max(1, passes)):
        corrected = _corrected(shots, designs, beta)
        res, fits = _joint_fit(corrected, model, options)
        n_aero = len(res.aero_names)
        new_designs = [_design(s, index, nc, v) for s, (_, _, v, _) in zip(shots, fits,
                                                                             strict=True)]
        rows_J, rows_D, rows_r = [], [], []
        n_loc = sum(f[3] for f in fits)
        at = 0
        for s, sc, D, (pred, J, _, nl) in zip(shots, corrected, new_designs, fits,
                                              strict=True):
            ok = np.isfinite(sc.meas[:, POSITION])
            w = 1.0 / s.sigma[:, POSITION][ok]
            rows_r.append(((sc.meas[:, POSITION] - pred[:, POSITION])[ok]) * w)
            Jk = J[:, POSITION, :][ok] * w[:, None]
            block = np.zeros((Jk.shape[0], n_loc + n_aero))
            block[:, at:at + nl] = Jk[:, :nl]
            block[:, n_loc:] = Jk[:, nl:]
            at += nl
            rows_J.append(block)
            rows_D.append(D[ok] * w[:, None])
            rms = {c: float(np.sqrt(np.nanmean((sc.meas[:, j] - pred[:, j]) ** 2)))
                   for j, c in enumerate("xyz")}
            if p == 0:
                rms_before[s.shot_id] = rms
            rms_after[s.shot_id] = rms
        Jt, Dt, r = np.vstack(rows_J), np.vstack(rows_D), np.concatenate(rows_r)
        # project out what the shots' own unknowns and the shared drag law absorb
        U, sv, _ = np.linalg.svd(Jt, full_matrices=False)
        U = U[:, sv > 1e-12 * sv.max()]
        A = Dt - U @ (U.T @ Dt)
        N = A.T @ A
        g = A.T @ r
        chi2 = float(r @ r)
        dof = r.size - U.shape[1]
        # the normal matrix is singular: its null space is exactly what the data cannot see
        d = np.sqrt(np.maximum(np.diag(N), 1e-300))
        w_, V = np.linalg.eigh(N / np.outer(d, d))
        keep = w_ > NULL_RCOND * w_.max()
        cov_b = (V[:, keep] / w_[keep]) @ V[:, keep].T / np.outer(d, d)
        null = V[:, ~keep] / d[:, None]
        # the data were corrected with the old design: re-express the correction in the new
        correction = np.concatenate([(D @ beta).reshape(-1) for D in designs])
        designs = new_designs
        Dall = np.concatenate([D.reshape(-1, n_beta) for D in designs])
        beta = np.linalg.lstsq(Dall, correction, rcond=None)[0] + cov_b @ g
    dof -= n_beta - null.shape[1]
    # final pass: residual after correction
    corrected = _corrected(shots, designs, beta)
    _, fits = _joint_fit(corrected, model, options)
    for sc, (pred, _, _, _) in zip(corrected, fits, strict=True):
        rms_after[sc.shot_id] = {c: float(np.sqrt(np.nanmean((sc.meas[:, j] - pred[:, j]) ** 2)))
                                 for j, c in enumerate("xyz")}
    beta, cov_b = robust_gauge(beta, cov_b, null)
    b = np.zeros((nS, 4))
    b[:, :nc] = beta.reshape(nS, nc)
    M = np.zeros((nS * 4, n_beta))
    for k in range(nS):
        for c in range(nc):
            M[k * 4 + c, k * nc + c] = 1.0
    cov = M @ cov_b @ M.T
    sig = np.sqrt(np.maximum(np.diag(cov), 0.0)).reshape(nS, 4)
    if not timing:
        sig[:, 3] = np.nan
    if dof > 0 and chi2 / dof > 2.0:
        warnings.append(f"chi^2/dof = {chi2 / dof:.2f} after the bias correction: the sphere "
                        "shots are not explained by station biases alone (or the sigmas are "
                        "too small)")
    method = (f"cadra2 calibrate: {len(shots)} sphere shot(s), joint point-mass fit "
              f"({model.name}), robust gauge of the {null.shape[1]} unobservable bias "
              f"patterns{', timing biases estimated' if timing else ''}")
    return StationBiasEstimate(
        facility=facility, stations=stations, bias=b, sigma=sig, covariance=cov,
        shots=tuple(s.shot_id for s in shots), shot_speeds_m_s=speeds,
        timing_estimated=bool(timing), chi2=chi2, dof=dof, shot_rms_before=rms_before,
        shot_rms_after=rms_after, warnings=tuple(warnings), method=method)


def apply_bias_table(shot: ShotData, table, *, min_significance: float | None = 3.0
                     ) -> ShotData:
    """``shot`` with its measurements corrected by a bias table (measured - b - v dt).

    Only the components the table shows as significant (``|b| > min_significance * sigma``)
    are applied, with their sigma added in quadrature; the others are left alone: station
    biases are sparse, and applying every station's estimate would add the table's own noise
    (sigma / sqrt(number of sphere shots)) to every measurement. ``min_significance=None``
    applies everything. Stations the table lacks are left as they are.
    """
    meas = shot.meas.copy()
    sigma = shot.sigma.copy()
    v = _velocity_at_stations(shot)
    rows = {int(st): k for k, st in enumerate(table.stations)}
    for i, st in enumerate(shot.stations):
        k = rows.get(int(st))
        if k is None:
            continue
        b = np.array(table.bias[k], dtype=float)
        sb = np.nan_to_num(np.array(table.sigma[k], dtype=float), nan=0.0)
        if min_significance is not None:
            keep = np.abs(b) > min_significance * sb
            b = np.where(keep, b, 0.0)
            sb = np.where(keep, sb, 0.0)
        meas[i, :3] -= b[:3] + v[i] * b[3]
        sigma[i, :3] = np.sqrt(sigma[i, :3] ** 2 + sb[:3] ** 2 + (v[i] * sb[3]) ** 2)
    return replace(shot, meas=meas, sigma=sigma,
                   source={**shot.source, "bias_table": getattr(table, "created_utc", "")})


__all__ = ["BIAS_CHANNELS", "CalibrationError", "StationBiasEstimate", "apply_bias_table",
           "check_sphere_shot", "estimate_station_biases", "robust_gauge"]

