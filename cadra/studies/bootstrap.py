"""The parametric bootstrap of a fit: how sure are we, by resampling (docs/fitting.md,
"Bootstrap").

Each replicate is the fit's own prediction (its forward model at the fitted point,
:class:`cadra.fitting.problem.FitProblem`) plus a fresh draw of the measurement noise, refitted
from the fitted point the way the fit was made: the same model, holds, bounds, extras and
free initial-state unknowns. Two noise models:

- ``"white"``: independent Gaussian noise with each measurement's own sigma (what the
  covariance sigma assumes);
- ``"residuals"``: the fit's own normalized residuals, resampled per shot and channel in
  moving blocks of :data:`BLOCK_STATIONS` stations and scaled by each measurement's sigma.
  The residuals are standardized by sqrt(1 - leverage) first (the fit absorbed that share
  of the noise). This carries what the residuals show and the sigmas do not: their real
  scale, heavy tails, and correlation from station to station (stage one's correlated
  errors, an unmodelled wobble).

:func:`replicate` is one refit, a pure function of plain data that a scheduler can ship
(:mod:`cadra.campaign.bootstrap` runs many on Dask). :func:`summarize` compares the replicates
with the fit: per parameter the bootstrap sigma against the covariance sigma, the bootstrap's
percentile interval, its bias and whether it looks Gaussian.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from cadra.fitting.result import FitResult
from cadra.fitting.solver import FitOptions, fit
from cadra.flight.data import CHANNELS

__all__ = ["BLOCK_STATIONS", "MIN_TO_FLAG", "NOISE_MODELS", "PROFILE_LEVEL", "BootstrapResult",
           "interval_ends", "peak_quantities", "replicate", "replicate_data",
           "sommer_tobak_quantities", "summarize", "with_profiles"]

#: the noise models of a replicate (module doc)
NOISE_MODELS = ("white", "residuals")
#: the block length (stations) of the residual resampling
BLOCK_STATIONS = 3
#: a percentile interval is flagged non-Gaussian when a half-width differs from the
#: covariance's 1.96 sigma by more than this fraction (or the two half-widths from each other)
NON_GAUSSIAN = 0.20
#: the fewest converged refits the flag is judged on: a 2.5 % quantile's own scatter is
#: ~0.19 sigma at 200 (about 10 % of the 1.96-sigma half-width), far more below that
MIN_TO_FLAG = 200
#: the central coverage of the percentile interval
COVERAGE = 0.95
#: how an interval's end is read off B refits: the (B + 1) alpha-th ordered value (Davison &
#: Hinkley 1997, sec. 5.2; numpy's "weibull", p (B + 1)), not numpy's default (B - 1) p + 1.
#: Where the refits and the estimate are exchangeable the former covers at exactly the
#: nominal rate; the default's ends sit one order statistic inside and at B = 100 cover 93.5 %
#: of the time instead of 95 % (tests/test_bootstrap.py)
QUANTILE_METHOD = "weibull"
#: column prefix of a replicate's own covariance sigma of a parameter (``sigma:<name>``)
SIGMA_PREFIX = "sigma:"
#: the profile likelihood's chi^2 rise at the same coverage (one parameter: 1.96^2)
PROFILE_LEVEL = 1.959963984540054 ** 2


def _block_resample(z: np.ndarray, rng: np.random.Generator, block: int) -> np.ndarray:
    """``z`` (n,) resampled in moving blocks of ``block`` consecutive entries."""
    n = z.size
    if n <= block:
        return rng.choice(z, size=n, replace=True)
    starts = rng.integers(0, n - block + 1, size=math.ceil(n / block))
    return np.concatenate([z[s:s + block] for s in starts])[:n]


def replicate_data(result: FitResult, seed: int, noise: str = "white") -> list:
    """The shots of one replicate: the fit's prediction plus noise drawn with ``seed``
    (:data:`NOISE_MODELS`); what was not measured stays unmeasured."""
    if noise not in NOISE_MODELS:
        raise ValueError(f"bootstrap noise must be one of {NOISE_MODELS}, got {noise!r}")
    if result.problem is None:
        raise ValueError("bootstrap: the fit carries no forward model (no Jacobian at its "
                         "start): nothing to resample")
    problem = result.problem
    rng = np.random.default_rng(seed)
    preds = problem.predict()
    out = []
    rr = result.residuals
    for sd, pred in zip(problem.shots, preds, strict=True):
        e = np.zeros(pred.shape)
        if noise == "white":
            e = rng.standard_normal(pred.shape) * sd.sigma
        else:
            mine = rr[rr["shot_id"] == sd.shot_id]
            for j in range(pred.shape[1]):
                rows = np.nonzero(sd.mask[:, j])[0]
                if not rows.size:
                    continue
                z = _channel_residuals(mine, CHANNELS[j], rows.size)
                e[rows, j] = _block_resample(z, rng, BLOCK_STATIONS) * sd.sigma[rows, j]
        meas = np.where(sd.mask, pred + e, sd.meas)
        out.append(replace(sd, meas=meas))
    return out


def _channel_residuals(rows: pd.DataFrame, name: str, n: int) -> np.ndarray:
    """The normalized residuals of channel ``name`` of one shot, in station order, each
    divided by sqrt(1 - leverage): the fit absorbs that share of each measurement's noise,
    which a resampled residual must carry again."""
    r = rows[rows["channel"] == name].sort_values("station")
    h = np.clip(np.nan_to_num(r["leverage"].to_numpy(float), nan=0.0), 0.0, 0.99)
    z = r["normalized"].to_numpy(float) / np.sqrt(1.0 - h)
    if z.size != n:
        raise ValueError(f"bootstrap: {z.size} residuals of channel {name} for {n} "
                         "measurements")
    return z


def replicate(result: FitResult, seed: int, noise: str = "white",
              options: FitOptions | None = None) -> dict:
    """One replicate: resampled data (:func:`replicate_data`) refitted from the fitted point.
    Returns ``{"seed", "status", "chi2", "iterations", <parameter>: value, ...}`` (the free
    aero parameters and extras); never raises (a failed refit is a row with its status)."""
    row: dict = {"seed": int(seed)}
    try:
        shots = replicate_data(result, seed, noise)
        res = fit(shots, result.model, [sf.state for sf in result.shots],
                  options=options or FitOptions(),
                  local_free=[sf.local_free_indices for sf in result.shots],
                  extras=result.extras_at_values())
    except (ValueError, FloatingPointError, np.linalg.LinAlgError) as exc:
        return {**row, "status": "failed", "chi2": math.nan, "iterations": 0,
                "error": f"{type(exc).__name__}: {exc}"}
    row.update(status=res.status, chi2=res.chi2, iterations=res.iterations)
    row.update({n: float(v) for n, v in zip(res.aero_names, res.aero_values, strict=True)})
    row.update({e.name: float(v) for e, v in zip(res.extras, res.extra_values, strict=True)})
    # each refit's own covariance sigmas: the studentized (bootstrap-t) interval's scale
    row.update({SIGMA_PREFIX + n: float(s)
                for n, s in zip(res.aero_names, res.aero_sigma, strict=True)})
    row.update({SIGMA_PREFIX + e.name: float(s)
                for e, s in zip(res.extras, res.extra_sigma, strict=True)})
    return row


@dataclass(frozen=True)
class BootstrapResult:
    """A fit's bootstrap (:func:`summarize`)."""

    samples: pd.DataFrame            # one row per replicate (:func:`replicate`'s)
    table: pd.DataFrame              # one row per parameter (module doc)
    noise: str
    n_requested: int
    seconds: float = math.nan
    derived: pd.DataFrame = field(default_factory=pd.DataFrame)

    @property
    def n_converged(self) -> int:
        return int((self.samples["status"] == "converged").sum())

    def report(self) -> str:
        """The table as text, what ``cadra2 fit --bootstrap`` prints."""
        from cadra.numfmt import pm

        lines = [f"bootstrap ({self.noise} noise): {self.n_converged} of {self.n_requested} "
                 f"refits converged"
                 + (f", {self.seconds:.1f} s" if math.isfinite(self.seconds) else "")
                 + ("" if self.n_converged >= MIN_TO_FLAG else
                    f"; too few to judge whether an interval is Gaussian (< {MIN_TO_FLAG})")]
        lines.append(f"{'parameter':12s} {'value ± sigma':>24s} {'sigma boot':>11s} "
                     f"{'ratio':>6s} {'bias/sigma':>10s}  95 % percentile interval")
        profiled = "profile_lower" in self.table
        for r in self.table.itertuples(index=False):
            flag = "  NON-GAUSSIAN" if r.non_gaussian is True else ""
            prof = (f"  profile [{r.profile_lower:.6g}, {r.profile_upper:.6g}]" if profiled
                    else "")
            lines.append(f"{r.parameter:12s} {pm(r.value, r.sigma_cov):>24s} "
                         f"{r.sigma_boot:>11.3g} {r.ratio:>6.3f} {r.bias_sigma:>10.3f}  "
                         f"[{r.lower:.6g}, {r.upper:.6g}]{prof}{flag}")
        for r in self.derived.itertuples(index=False):
            lines.append(f"{r.parameter:12s} {r.value:>24.6g} {r.sigma_boot:>11.3g} "
                         f"{'':>6s} {r.bias_sigma:>10.3f}  [{r.lower:.6g}, {r.upper:.6g}]"
                         "  (derived)")
        return "\n".join(lines)


def summarize(result: FitResult, rows: Sequence[dict], noise: str = "white",
              seconds: float = math.nan,
              derived: Mapping[str, Callable] | None = None) -> BootstrapResult:
    """The bootstrap's figures from its replicate ``rows`` (converged ones only), per free
    parameter: the fit's value and covariance sigma, the bootstrap sigma (std of the
    replicates) and their ratio, the bias (replicates' mean minus the fit's value) in
    sigmas, the :data:`COVERAGE` percentile interval (the refits' own quantiles ``q_lo,
    q_hi``: on a fit whose chi^2 is not quadratic it covered the truth more often than the
    basic interval reflected about the value, docs/fitting.md), and ``non_gaussian``: a
    half-width that differs from 1.96 covariance sigma, or from the other half-width, by more than
    :data:`NON_GAUSSIAN` (None, not judged, below :data:`MIN_TO_FLAG` converged refits).
    ``derived``: name -> function of a fitted model (an
    :class:`~cadra.aero.AeroModel`) giving a quantity a range engineer reads (a C_mq peak);
    its value from each replicate's parameters (table ``derived``)."""
    samples = pd.DataFrame(list(rows))
    ok = samples[samples["status"] == "converged"] if len(samples) else samples
    names = list(result.aero_names) + list(result.extra_names)
    values = dict(zip(result.aero_names, result.aero_values, strict=True))
    values.update(zip(result.extra_names, result.extra_values, strict=True))
    sig = dict(zip(result.aero_names, result.aero_sigma, strict=True))
    sig.update(zip(result.extra_names, result.extra_sigma, strict=True))
    table = pd.DataFrame([_figures(n, values[n], sig[n], ok[n].to_numpy(float)
                                   if n in ok else np.zeros(0),
                                   ok[SIGMA_PREFIX + n].to_numpy(float)
                                   if SIGMA_PREFIX + n in ok else None) for n in names])
    der = pd.DataFrame()
    if derived:
        der = _derived(result, ok, derived)
    return BootstrapResult(samples=samples, table=table, noise=noise,
                           n_requested=len(samples), seconds=seconds, derived=der)


def interval_ends(x: np.ndarray, coverage: float = COVERAGE) -> tuple[float, float]:
    """The ends of the central ``coverage`` interval of the refits ``x``: their
    (B + 1) alpha-th and (B + 1)(1 - alpha)-th ordered values (:data:`QUANTILE_METHOD`),
    interpolated between neighbours. Below 1/alpha - 1 refits the ends are the extremes."""
    a = (1.0 - coverage) / 2.0
    lo, hi = np.quantile(np.asarray(x, dtype=float), [a, 1.0 - a], method=QUANTILE_METHOD)
    return float(lo), float(hi)


def _studentized(value: float, sigma: float, x: np.ndarray, s) -> tuple[float, float]:
    """The studentized (bootstrap-t) interval: the refits' t = (x - value) / s, their own
    sigmas s, quantiles t_lo, t_hi; [value - t_hi sigma, value - t_lo sigma] (Efron &
    Tibshirani, ch. 12). NaN without the refits' sigmas."""
    if s is None or not (sigma > 0):
        return math.nan, math.nan
    s = np.asarray(s, dtype=float)
    ok = np.isfinite(x) & np.isfinite(s) & (s > 0)
    if ok.sum() < 2:
        return math.nan, math.nan
    t_lo, t_hi = interval_ends((x[ok] - value) / s[ok])
    return float(value - t_hi * sigma), float(value - t_lo * sigma)


def _figures(name: str, value: float, sigma: float, x: np.ndarray, s=None) -> dict:
    t_lower, t_upper = _studentized(value, sigma, np.asarray(x, dtype=float), s)
    x = x[np.isfinite(x)]
    if x.size < 2:
        return {"parameter": name, "value": value, "sigma_cov": sigma, "sigma_boot": math.nan,
                "ratio": math.nan, "bias": math.nan, "bias_sigma": math.nan,
                "lower": math.nan, "upper": math.nan, "t_lower": t_lower, "t_upper": t_upper,
                "non_gaussian": None, "n": int(x.size)}
    sb = float(np.std(x, ddof=1))
    lower, upper = interval_ends(x)
    half = 1.959963984540054 * sigma
    lo_w, hi_w = value - lower, upper - value
    non_gauss = None if x.size < MIN_TO_FLAG else bool(
        half > 0 and (abs(lo_w / half - 1.0) > NON_GAUSSIAN
                      or abs(hi_w / half - 1.0) > NON_GAUSSIAN
                      or abs(lo_w - hi_w) > NON_GAUSSIAN * max(lo_w, hi_w)))
    bias = float(np.mean(x) - value)
    return {"parameter": name, "value": value, "sigma_cov": sigma, "sigma_boot": sb,
            "ratio": sb / sigma if sigma > 0 else math.nan, "bias": bias,
            "bias_sigma": bias / sigma if sigma > 0 else math.nan, "lower": float(lower),
            "upper": float(upper), "t_lower": t_lower, "t_upper": t_upper,
            "non_gaussian": non_gauss, "n": int(x.size)}


def with_profiles(boot: BootstrapResult, result: FitResult,
                  names: Sequence[str] | None = None) -> BootstrapResult:
    """``boot`` with each parameter's profile-likelihood interval at the same coverage
    (:func:`cadra.fitting.profile.profile_parameter`, chi^2 rise :data:`PROFILE_LEVEL`) beside
    its percentile interval: columns ``profile_lower``, ``profile_upper`` (+-inf where the
    profile never rose that far) and ``profile_unsettled`` (held fits that did not converge:
    the interval may then be too narrow). One profile is ~10-20 held fits of the whole fit;
    ``names`` (default: every parameter) limits them (the others get NaN)."""
    from cadra.fitting.profile import profile_parameter

    shots = list(result.problem.shots)
    rows = []
    for name in boot.table["parameter"]:
        if names is not None and name not in names:
            rows.append((math.nan, math.nan, 0))
            continue
        pr = profile_parameter(result, shots, name, level=PROFILE_LEVEL)
        rows.append((pr.lower, pr.upper, pr.n_unsettled))
    table = boot.table.copy()
    table["profile_lower"] = [r[0] for r in rows]
    table["profile_upper"] = [r[1] for r in rows]
    table["profile_unsettled"] = [r[2] for r in rows]
    return replace(boot, table=table)


def _derived(result: FitResult, ok: pd.DataFrame, derived: Mapping[str, Callable]
             ) -> pd.DataFrame:
    names = list(result.aero_names)
    at = derived_values(result.model, derived)
    reps = [derived_values(result.model.with_values({n: float(r[n]) for n in names}), derived)
            for _, r in ok.iterrows()]
    rows = []
    for k in derived:
        x = np.array([r[k] for r in reps], dtype=float)
        f = _figures(k, at[k], float(np.std(x, ddof=1)) if x.size > 1 else math.nan, x)
        for key in ("sigma_cov", "ratio", "t_lower", "t_upper"):
            f.pop(key)
        rows.append(f)
    return pd.DataFrame(rows)


def peak_quantities(result: FitResult, coefficient: str = "Cmq", n_points: int = 201
                    ) -> dict[str, Callable]:
    """Derived quantities a range engineer reads off a fitted form: the largest value of
    ``coefficient`` over the angles the flights covered (the total angle for a total-angle
    model, alpha otherwise), at their mean Mach, and the angle (deg) where it lies; e.g. seed
    004's C_mq peak. The angles and Mach are the fit's own histories
    (:func:`cadra.fitting.histories.fitted_histories`). Empty when the model has no such
    coefficient or its form does not vary over those angles."""
    from cadra.fitting.histories import flown_angles

    model = result.model
    if coefficient not in model.coefficients or result.problem is None:
        return {}
    flown = flown_angles(result, n_points=n_points)

    def curve(m):
        return np.asarray(m.evaluate(*flown.path(), flown.mach)[coefficient], dtype=float)

    c = curve(model)
    if np.ptp(c) <= 1e-12 * max(1.0, float(np.max(np.abs(c)))):
        return {}
    return {f"{coefficient} peak": lambda m: float(np.max(curve(m))),
            f"{coefficient} peak {flown.angle} (deg)": lambda m: float(np.degrees(
                flown.grid_rad[int(np.argmax(curve(m)))]))}


def sommer_tobak_quantities(result: FitResult, n_points: int = 201) -> dict[str, Callable]:
    """Seed 004's Eq. (1), the Sommer-Tobak criterion of a planar oscillation in a range:
    ``C_D - C_L_alpha + C_mq m d^2 / I_yy``, negative where the oscillation is dynamically
    stable. Evaluated over the angles the flights covered at their mean Mach (as
    :func:`peak_quantities`), ``C_L_alpha`` the slope of C_L against that angle (per rad, by
    complex step), ``m d^2 / I_yy`` the mean of the fit's shots'; the derived quantities are
    its largest value (the least stable angle flown) and the angle where it lies. Empty when
    the model lacks C_D, C_L or C_mq."""
    from cadra.fitting.histories import flown_angles

    model = result.model
    if not {"CD", "CL", "Cmq"} <= set(model.coefficients) or result.problem is None:
        return {}
    flown = flown_angles(result, n_points=n_points)
    ratio = float(np.mean([sd.rigid.mass_kg * sd.rigid.d_m ** 2
                           / sd.rigid.inertia_body_kg_m2[1, 1]
                           for sd in result.problem.shots]))
    h = 1e-20

    def curve(m):
        a, b, sg = flown.path()
        c = m.evaluate(a + 1j * h, b, None if sg is None else sg + 1j * h, flown.mach)
        return (np.real(c["CD"]) - np.imag(c["CL"]) / h
                + np.real(c["Cmq"]) * ratio).astype(float)

    return {"Sommer-Tobak sum, largest": lambda m: float(np.max(curve(m))),
            f"Sommer-Tobak sum, largest at {flown.angle} (deg)": lambda m: float(np.degrees(
                flown.grid_rad[int(np.argmax(curve(m)))]))}


def derived_values(model, derived: Mapping[str, Callable]) -> dict:
    """Each derived quantity of ``model`` (name -> function of the model)."""
    return {k: float(fn(model)) for k, fn in derived.items()}
