"""Where does the residual lie? Tests on a fit's normalized residuals (seed 003's evidence).

Each function takes plain tables and returns a :class:`pandas.DataFrame`; each row states a
test's statistic and its p-value under "the residual is the measurement noise" (independent,
unit-variance normalized residuals):

- :func:`by_group`: rms of the normalized residual per channel, station, shot (and the time
  of the station);
- :func:`sequence_tests`: per shot and channel, in station (time) order: the Wald-Wolfowitz
  runs test of the signs (too few runs = a systematic misfit, seed 003) and the lag-1
  autocorrelation (normal approximation, variance 1/n);
- :func:`frequency_content`: per shot and channel, the residual's content at the fitted
  motion's pitch and yaw frequencies (the dominant frequencies of the fitted theta and psi
  histories) and at the roll frequency when the model rolls: a sine and cosine at that
  frequency fitted to the normalized residual; their chi^2 drop is chi^2(2) under noise;
- :func:`cross_shot`: per station and channel, over the shots of a multi-fit, the mean
  normalized residual and a test that it repeats from shot to shot (a facility effect does,
  a model or body effect does not);
- :func:`stage_one_consistency`: stage one's own consistency figures (top-minus-side x over
  its sigma, stations with warnings) set beside the stage-two residual, to say whether the
  gap sits where the measurement itself is doubtful.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd
from scipy import stats

from cadra.fitting.problem import result_problem
from cadra.fitting.result import FitResult
from cadra.flight.data import CHANNELS, ShotData
from cadra.stats import runs_of_sign

#: p-value below which a "where" test is reported as significant (before the one-page
#: summary's own multiplicity note)
ALPHA = 0.01


def by_group(where: pd.DataFrame, keys: Sequence[str]) -> pd.DataFrame:
    """rms of ``normalized`` per group of ``keys`` with the chi^2 p-value of its sum."""
    g = where.assign(sq=where["normalized"] ** 2).groupby(list(keys))["sq"]
    out = pd.DataFrame({"n": g.size(), "rms_normalized": np.sqrt(g.mean()),
                        "p_value": stats.chi2.sf(g.sum(), g.size())})
    return out.reset_index().sort_values("rms_normalized", ascending=False,
                                         kind="stable").reset_index(drop=True)


def sequence_tests(where: pd.DataFrame) -> pd.DataFrame:
    """Runs and lag-1 autocorrelation tests per shot and channel (station order)."""
    rows = []
    for (shot, ch), grp in where.groupby(["shot_id", "channel"], sort=False):
        r = grp.sort_values("station")["normalized"].to_numpy()
        n = r.size
        rt = runs_of_sign(r)
        runs, z, p = rt.runs, rt.z, rt.p
        rc = r - r.mean()
        lag1 = float(rc[1:] @ rc[:-1] / (rc @ rc)) if n > 2 and rc @ rc > 0 else math.nan
        p1 = float(2 * stats.norm.sf(abs(lag1) * math.sqrt(n))) if n > 2 else math.nan
        rows.append({"shot_id": shot, "channel": ch, "n": n, "runs": runs, "runs_z": z,
                     "runs_p": p, "lag1_autocorrelation": lag1, "lag1_p": p1})
    return pd.DataFrame(rows)


def _dominant_frequency(t: np.ndarray, y: np.ndarray) -> float:
    """Frequency (Hz) of the largest spectral peak of y(t) on a uniform grid, after removing
    a quadratic trend; NaN when there is no oscillation."""
    y = y - np.polyval(np.polyfit(t, y, 2), t)
    if not np.any(y):
        return math.nan
    spec = np.abs(np.fft.rfft(y * np.hanning(y.size), n=8 * y.size))
    f = np.fft.rfftfreq(8 * y.size, t[1] - t[0])
    k = int(np.argmax(spec[1:])) + 1
    # a peak below one cycle over the record is a trend, not a motion
    return float(f[k]) if f[k] * (t[-1] - t[0]) >= 1.0 else math.nan


def fitted_channels(result: FitResult, shots: Sequence[ShotData] | None = None, *,
                    times=None, n_points: int = 512) -> dict[str, np.ndarray]:
    """Per shot, the fitted (n, N_CHANNELS) channels the where-tests analyse (reference
    point and axis inclinations, SI), predicted by the fit's own forward model
    (:func:`cadra.fitting.problem.result_problem`: the fitted model with every effect the
    fit used) at ``times`` (one array for every shot, or ``{shot_id: array}``; default
    ``n_points`` equally spaced over each shot's stations)."""
    problem = result_problem(result, shots)
    if times is None:
        times = {sd.shot_id: np.linspace(sd.t_s.min(), sd.t_s.max(), n_points)
                 for sd in problem.shots}
    return {sd.shot_id: h["channels"]
            for sd, h in zip(problem.shots, problem.histories(times=times), strict=True)}


def motion_frequencies(result: FitResult, shots: Sequence[ShotData]) -> dict:
    """Per shot: {"pitch": Hz, "yaw": Hz, "roll": Hz} of the fitted motion (dense fitted
    theta / psi histories of the fit's forward model; roll from the fitted roll rate; NaN
    for a motion with less than one cycle over the record)."""
    problem = result_problem(result, shots)
    theta, psi = CHANNELS.index("theta"), CHANNELS.index("psi")
    times = {sd.shot_id: np.linspace(sd.t_s.min(), sd.t_s.max(), 512) for sd in problem.shots}
    histories = problem.histories(times=times)       # every shot at once, each integrated once
    out = {}
    for sd, h in zip(problem.shots, histories, strict=True):
        if not sd.has_angles:
            out[sd.shot_id] = {"pitch": math.nan, "yaw": math.nan, "roll": math.nan}
            continue
        t = times[sd.shot_id]
        y, o = h["states"], h["channels"]
        f_roll = abs(float(np.median(y[:, 10]))) / (2 * math.pi)
        out[sd.shot_id] = {"pitch": _dominant_frequency(t, o[:, theta]),
                           "yaw": _dominant_frequency(t, o[:, psi]),
                           # under one turn over the record: no roll frequency to test
                           "roll": f_roll if f_roll * (t[-1] - t[0]) >= 1.0 else math.nan}
    return out


def frequency_content(where: pd.DataFrame, freqs: Mapping[str, dict]) -> pd.DataFrame:
    """Content of each shot's and channel's normalized residual at its motion frequencies."""
    rows = []
    for (shot, ch), grp in where.groupby(["shot_id", "channel"], sort=False):
        t = grp["t_s"].to_numpy(float)
        r = grp["normalized"].to_numpy(float)
        for motion, f in freqs.get(shot, {}).items():
            if not math.isfinite(f) or r.size < 5:
                continue
            A = np.column_stack([np.sin(2 * math.pi * f * t), np.cos(2 * math.pi * f * t)])
            coef, *_ = np.linalg.lstsq(A, r, rcond=None)
            drop = float(r @ r - np.sum((r - A @ coef) ** 2))
            rows.append({"shot_id": shot, "channel": ch, "motion": motion, "frequency_hz": f,
                         "amplitude_sigma": float(np.hypot(*coef)), "dchi2": drop,
                         "p_value": float(stats.chi2.sf(drop, 2))})
    return pd.DataFrame(rows)


def cross_shot(where: pd.DataFrame) -> pd.DataFrame:
    """Per station and channel over the shots: mean normalized residual, the z test that it
    is not 0 (``p_repeat``: small = the same misfit in every shot, a facility effect), and
    the chi^2 test of the scatter about that mean (``p_scatter``: small = the shots differ)."""
    rows = []
    n_shots = where["shot_id"].nunique()
    if n_shots < 2:
        return pd.DataFrame(columns=["station", "channel", "n_shots", "mean_normalized",
                                     "p_repeat", "p_scatter"])
    for (st, ch), grp in where.groupby(["station", "channel"]):
        r = grp["normalized"].to_numpy(float)
        n = r.size
        if n < 2:
            continue
        m = float(r.mean())
        rows.append({"station": int(st), "channel": ch, "n_shots": n, "mean_normalized": m,
                     "p_repeat": float(2 * stats.norm.sf(abs(m) * math.sqrt(n))),
                     "p_scatter": float(stats.chi2.sf(float(np.sum((r - m) ** 2)), n - 1))})
    return pd.DataFrame(rows).sort_values("p_repeat", kind="stable").reset_index(drop=True)


def stage_one_consistency(where: pd.DataFrame,
                          stage_one: Mapping[str, pd.DataFrame]) -> pd.DataFrame:
    """Per shot and station: stage one's x consistency (top minus side over its sigma) and
    warnings beside the stage-two residual's largest |normalized| at that station.

    ``stage_one``: shot id -> stage one's trajectory table (``station``,
    ``x_consistency``, ``warnings``; :class:`cadra.io.trajectory.Trajectory` ``.table``)."""
    worst = (where.assign(a=where["normalized"].abs())
             .groupby(["shot_id", "station"])["a"].max().rename("stage2_max_abs_normalized"))
    rows = []
    for shot, table in stage_one.items():
        for _, row in table.iterrows():
            st = int(row["station"])
            xc = float(row.get("x_consistency", math.nan))
            warn = str(row.get("warnings", "") or "")
            rows.append({"shot_id": shot, "station": st, "x_consistency": xc,
                         "stage1_warnings": "" if warn == "nan" else warn,
                         "stage2_max_abs_normalized": float(worst.get((shot, st), math.nan))})
    return pd.DataFrame(rows)


def where_analysis(result: FitResult, shots: Sequence[ShotData], where: pd.DataFrame,
                   stage_one: Mapping[str, pd.DataFrame] | None = None) -> dict:
    """All the "where" tables for a fit (``where``: shot_id, station, channel, normalized;
    the station times are taken from the shots) and a few plain sentences for the summary."""
    times = {(s.shot_id, int(st)): float(t) for s in shots
             for st, t in zip(s.stations, s.t_s, strict=True)}
    w = where.assign(t_s=[times.get((a, int(b)), math.nan)
                          for a, b in zip(where["shot_id"], where["station"], strict=True)])
    out = {"by_channel": by_group(w, ["channel"]),
           "by_station": by_group(w, ["station", "channel"]),
           "by_shot": by_group(w, ["shot_id"]),
           "sequence": sequence_tests(w),
           "frequency": frequency_content(w, motion_frequencies(result, shots)),
           "cross_shot": cross_shot(w)}
    if stage_one:
        out["stage_one"] = stage_one_consistency(w, stage_one)
    out["findings"] = findings(out)
    return out


def findings(tables: dict) -> list[str]:
    """Plain sentences for the significant "where" tests (p < :data:`ALPHA`)."""
    lines = []
    seq = tables["sequence"]
    for _, r in seq[seq["runs_p"] < ALPHA].iterrows():
        lines.append(f"{r['shot_id']} {r['channel']}: {r['runs']} runs of sign in {r['n']} "
                     f"stations (z = {r['runs_z']:.1f}, p = {r['runs_p']:.1g}): a systematic "
                     "misfit, not noise")
    for _, r in seq[(seq["lag1_p"] < ALPHA) & ~(seq["runs_p"] < ALPHA)].iterrows():
        lines.append(f"{r['shot_id']} {r['channel']}: lag-1 autocorrelation "
                     f"{r['lag1_autocorrelation']:.2f} (p = {r['lag1_p']:.1g})")
    fr = tables["frequency"]
    if len(fr):
        for _, r in fr[fr["p_value"] < ALPHA].iterrows():
            lines.append(f"{r['shot_id']} {r['channel']}: content at the {r['motion']} "
                         f"frequency ({r['frequency_hz']:.1f} Hz), amplitude "
                         f"{r['amplitude_sigma']:.1f} sigma (p = {r['p_value']:.1g}): the "
                         "dynamics misses something in that mode")
    cs = tables["cross_shot"]
    if len(cs):
        for _, r in cs[cs["p_repeat"] < ALPHA / max(len(cs), 1)].iterrows():
            lines.append(f"station {r['station']} {r['channel']}: the same misfit in all "
                         f"{r['n_shots']} shots (mean {r['mean_normalized']:+.1f} sigma, "
                         f"p = {r['p_repeat']:.1g}): a facility effect")
    s1 = tables.get("stage_one")
    if s1 is not None and len(s1):
        bad = s1[(s1["x_consistency"].abs() > 3) | (s1["stage1_warnings"] != "")]
        big = s1[s1["stage2_max_abs_normalized"] > 3]
        both = set(zip(bad["shot_id"], bad["station"], strict=True)) & set(
            zip(big["shot_id"], big["station"], strict=True))
        if len(big):
            share = len(both) / len(big)
            lines.append(f"{len(both)} of the {len(big)} station(s) with a stage-two residual "
                         "above 3 sigma are doubtful in stage one itself (x consistency > 3 "
                         "or warnings): the gap is "
                         + ("in the measurement" if share >= 0.5 else "not in stage one's "
                            "own consistency figures (look at the dynamics or at biases "
                            "stage one cannot see)"))
    return lines


__all__ = ["ALPHA", "by_group", "cross_shot", "findings", "frequency_content",
           "fitted_channels", "motion_frequencies", "sequence_tests",
           "stage_one_consistency", "where_analysis"]
