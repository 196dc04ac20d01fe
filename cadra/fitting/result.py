"""The result of a stage-two fit: values, uncertainties, identifiability, residuals.

:class:`FitResult` is a frozen dataclass. Its ``status`` says whether it is a result at all
(``converged``) or the best point a failed fit reached (``max_iterations``, ``stalled``,
``failed``); ``bool(result)`` is True only for a converged fit, so a failed estimate cannot be
mistaken for one.

Uncertainties (docs/fitting.md, "Uncertainties"):

- ``covariance``: ``(J^T W J)^-1`` with W the measurement weights 1/sigma^2 -- honest when
  the sigmas are (stage one's are, within 0.87-0.99; film-era sigmas are the analyst's).
- ``covariance_coloured``: the sandwich estimate of Morelli & Klein (AIAA 95-3499) for
  coloured residuals, ``N^-1 (sum_ij J_i^T R(i-j) J_j) N^-1`` with the residual
  autocorrelation R estimated per shot and channel over station lags, Bartlett-tapered
  (Newey-West) so it stays positive semi-definite.
- ``sigma_scaled``: the plain sigmas times sqrt(chi^2 / dof) when that exceeds 1.

Identifiability: the normal matrix in correlation form is eigen-decomposed; each direction
whose eigenvalue is below ``IDENT_RCOND`` of the largest is reported with the parameters it
mixes and a suggestion of which to hold.
"""

from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from scipy import sparse

from cadra.aero import AeroModel
from cadra.channels import residual
from cadra.fitting.priors import prior_chi2, prior_names, prior_rows
from cadra.fitting.sensitivity import LOCAL_NAMES
from cadra.flight.data import CHANNELS
from cadra.stats import POOR_MINIMUM_P, chi2_p_value

if TYPE_CHECKING:
    from cadra.fitting.problem import FitProblem

#: eigenvalue ratio (correlation form of the normal matrix) below which a direction is reported
#: as not determined by the data
IDENT_RCOND = 1e-8
#: |correlation| above which a pair of parameters is reported
CORRELATION_REPORT = 0.95


@dataclass(frozen=True, eq=False)
class ShotFit:
    """One shot's fitted initial state (at its epoch ``t0_s``) and fit statistics."""

    shot_id: str
    t0_s: float
    state: np.ndarray                # (13,) cg position, velocity, quaternion, body rates
    local_free: tuple[str, ...]
    local_sigma: np.ndarray          # (12,) sigma of LOCAL_NAMES (NaN where held)
    chi2: float
    n_observations: int
    rms: dict                        # channel -> rms residual (SI)

    @property
    def local_free_indices(self) -> np.ndarray:
        """``local_free`` as indices into :data:`LOCAL_NAMES` (what the solver takes)."""
        return np.array([LOCAL_NAMES.index(n) for n in self.local_free], dtype=int)


@dataclass(frozen=True, eq=False)
class FitResult:
    """Outcome of :func:`cadra.fitting.solver.fit` (see module doc)."""

    status: str
    message: str
    model: AeroModel                 # the model with fitted values (vary/bounds as given)
    aero_names: tuple[str, ...]      # free aerodynamic parameters
    aero_values: np.ndarray
    aero_sigma: np.ndarray
    shots: tuple[ShotFit, ...]
    param_names: tuple[str, ...]     # order of the covariance matrices
    covariance: np.ndarray
    covariance_coloured: np.ndarray
    chi2: float
    n_observations: int
    n_free: int
    iterations: int
    history: tuple[float, ...]
    residuals: pd.DataFrame
    near_singular: tuple[dict, ...]
    warnings: tuple[str, ...]
    elapsed_s: float
    options: dict = field(default_factory=dict)
    extras: tuple = ()               # the fit's extra unknowns (cadra.fitting.extras.Extra)
    extra_values: np.ndarray = field(default_factory=lambda: np.zeros(0))
    extra_sigma: np.ndarray = field(default_factory=lambda: np.zeros(0))
    held_extras: tuple = ()          # extras held at their values (not fitted)
    #: d(fitted / sigma) / d(parameter) at the final point: rows in the order of
    #: ``residuals``, columns ``param_names`` (SI, radians); sparse (``scipy.sparse.csr_array``:
    #: a shot's rows touch only the shared unknowns and its own); None when the fit had none
    jacobian: sparse.csr_array | None = None
    #: the fit's forward model at the final point (:class:`cadra.fitting.problem.FitProblem`:
    #: the fitted model, the extras at their values, each shot's fitted state): what the
    #: report, its plots and the gap diagnosis predict with -- the solver's own physics
    problem: FitProblem | None = None
    #: the free aerodynamic parameters' values the fit started from (SI)
    initial_values: dict = field(default_factory=dict)
    #: Gaussian priors (:mod:`cadra.fitting.priors`): their number (each counts as an
    #: observation in :attr:`dof`) and their share of :attr:`chi2`
    n_priors: int = 0
    prior_chi2: float = 0.0

    def __bool__(self) -> bool:
        return self.status == "converged"

    def __repr__(self) -> str:
        shots = ", ".join(sf.shot_id for sf in self.shots[:3]) + (
            f" +{len(self.shots) - 3}" if len(self.shots) > 3 else "")
        return (f"<FitResult {self.status}: {self.model.name}, {len(self.aero_names)} aero "
                f"of {self.n_free} unknowns, {len(self.shots)} shot(s) ({shots}), "
                f"chi^2/nu = {self.reduced_chi2:.4g}, {self.iterations} iterations>")

    @property
    def params(self):
        """Every parameter by name, lmfit's way (:class:`cadra.fitting.params.FitParameters`):
        ``result.params["Cm_A1"].value``, ``.stderr``, ``.min``, ``.max``, ``.vary``,
        ``.init_value``, ``.correl``."""
        from cadra.fitting.params import FitParameter, FitParameters

        R = self.correlation()
        index = {n: k for k, n in enumerate(self.param_names)}
        sig = np.sqrt(np.maximum(np.diag(self.covariance), 0.0)) if self.param_names else []

        def correl(name):
            k = index[name]
            return {m: float(R[k, j]) for m, j in index.items() if j != k}

        out = []
        for prm in self.model.parameters:
            if prm.name in index:
                k = self.aero_names.index(prm.name)
                out.append(FitParameter(prm.name, prm.value, float(self.aero_sigma[k]), True,
                                        prm.min, prm.max,
                                        self.initial_values.get(prm.name), "aero",
                                        correl(prm.name)))
            else:
                out.append(FitParameter(prm.name, prm.value, None, False, prm.min, prm.max,
                                        prm.value, "aero"))
        for e, v, s in zip(self.extras, self.extra_values, self.extra_sigma, strict=True):
            out.append(FitParameter(e.name, float(v), float(s), True, kind="extra",
                                    correl=correl(e.name)))
        for e in self.held_extras:
            out.append(FitParameter(e.name, float(e.value), None, False, kind="extra"))
        for sf in self.shots:
            for k, local in enumerate(LOCAL_NAMES):
                if local not in sf.local_free:
                    continue
                name = f"{sf.shot_id}:{local}"
                value = 0.0 if local.startswith("rot_") else float(
                    sf.state[k] if k < 6 else sf.state[k + 1])
                out.append(FitParameter(name, value, float(sig[index[name]]), True,
                                        kind="state", correl=correl(name)))
        return FitParameters(out)

    def status_line(self) -> str:
        """One line: status, why, chi^2/nu, iterations (per phase), time."""
        from cadra.fitting.summary import status_line

        return status_line(self)

    def report(self, *, verbose: bool = False, status: bool = True,
               warnings: bool = True) -> str:
        """The fit's text report (:func:`cadra.fitting.summary.fit_report`): the status
        line, statistics, every free parameter ``value ± sigma`` with its start, the held
        ones, high correlations, the phases and the warnings; what ``cadra2 fit`` prints."""
        from cadra.fitting.summary import fit_report

        return fit_report(self, verbose=verbose, status=status, warnings=warnings)

    @property
    def converged(self) -> bool:
        return self.status == "converged"

    @property
    def chi2_p_value(self) -> float:
        """P(chi^2 >= this chi^2) for chi^2 with :attr:`dof` degrees of freedom: how likely
        noise of the stated sigmas alone leaves residuals this large (NaN without dof)."""
        return chi2_p_value(self.chi2, self.dof)

    @property
    def poor_minimum(self) -> bool:
        """Converged, but to residuals its noise does not allow: p(chi^2) below
        :data:`POOR_MINIMUM_P` (a wrong minimum, an aliased start, or physics the model
        lacks: the gap diagnosis asks which)."""
        return self.converged and self.chi2_p_value < POOR_MINIMUM_P    # NaN: False

    @property
    def verdict(self) -> str:
        """:attr:`status`, or ``"poor_minimum"`` for a converged fit far above its noise
        (:attr:`poor_minimum`): what reports and command lines say."""
        return "poor_minimum" if self.poor_minimum else self.status

    def worst_residual(self) -> str:
        """Where the residuals are largest: the channel with the largest share of chi^2 and
        the measurement with the largest normalized residual (shot, station, channel)."""
        r = self.residuals
        if not len(r) or "normalized" not in r:
            return "no residuals"
        z = r["normalized"].to_numpy(float)
        share = (r.assign(z2=z**2).groupby("channel")["z2"].sum() / np.nansum(z**2))
        ch = str(share.idxmax())
        k = int(np.nanargmax(np.abs(z)))
        row = r.iloc[k]
        return (f"channel {ch} carries {100 * share.max():.0f} % of chi^2; the largest "
                f"residual is {z[k]:+.1f} sigma, shot {row['shot_id']} station "
                f"{int(row['station'])} channel {row['channel']}")

    @property
    def dof(self) -> int:
        return self.n_observations + self.n_priors - self.n_free

    @property
    def reduced_chi2(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else math.nan

    @property
    def aero_sigma_coloured(self) -> np.ndarray:
        na = len(self.aero_names)
        return np.sqrt(np.maximum(np.diag(self.covariance_coloured)[:na], 0.0))

    @cached_property
    def consider(self):
        """The consider covariance of the parameters the model holds with an uncertainty
        (:class:`cadra.fitting.consider.ConsiderAnalysis`: conditional and consider sigmas,
        d(free)/d(held)); None when it holds none, or without the fit's forward model."""
        from cadra.fitting.consider import consider, held_with_sigma

        if self.problem is None or not held_with_sigma(self.model) or self.jacobian is None:
            return None
        return consider(self)

    @property
    def aero_sigma_scaled(self) -> np.ndarray:
        return self.aero_sigma * math.sqrt(max(1.0, self.reduced_chi2 if self.dof > 0 else 1))

    def correlation(self, coloured: bool = False) -> np.ndarray:
        C = self.covariance_coloured if coloured else self.covariance
        d = np.sqrt(np.maximum(np.diag(C), 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            R = C / np.outer(d, d)
        R[~np.isfinite(R)] = 0.0
        return R

    def extras_at_values(self) -> list:
        """The fit's extras at their fitted values, then the held ones: what a fit continuing
        from this one takes."""
        from dataclasses import replace

        return [replace(e, value=float(v)) for e, v in
                zip(self.extras, self.extra_values, strict=True)] + list(self.held_extras)

    @property
    def extra_names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.extras)

    def value(self, name: str) -> float:
        if name in self.extra_names:
            return float(self.extra_values[self.extra_names.index(name)])
        for e in self.held_extras:
            if e.name == name:
                return float(e.value)
        return self.model.parameter(name).value

    def sigma(self, name: str) -> float:
        if name in self.extra_names:
            return float(self.extra_sigma[self.extra_names.index(name)])
        if any(e.name == name for e in self.held_extras):
            return 0.0
        return float(self.aero_sigma[self.aero_names.index(name)])

    def rms(self) -> dict:
        """Residual rms per channel over all shots (SI)."""
        out = {}
        for ch in CHANNELS:
            r = self.residuals.loc[self.residuals["channel"] == ch, "residual"]
            out[ch] = float(np.sqrt(np.mean(r**2))) if len(r) else math.nan
        return out

    def dof_by_channel(self) -> dict:
        """Per channel, the degrees of freedom the fit leaves it: sum of (1 - leverage)
        over its residuals (the channels' values add up to ``dof`` when every free
        parameter is determined). NaN where the fit has no Jacobian."""
        r = self.residuals
        # numpy's sum: a missing leverage (NaN) gives NaN, not pandas' skipped 0
        return {ch: float(np.sum(1.0 - r.loc[r["channel"] == ch, "leverage"].to_numpy(float)))
                if (r["channel"] == ch).any() else math.nan for ch in CHANNELS}

    def noise_floor(self) -> dict:
        """Per channel, the residual rms a correct model leaves on noise of the stated
        sigmas: sqrt(mean of sigma^2 (1 - leverage)) (SI). The fit absorbs part of the noise;
        a channel on which many free parameters act keeps well below its sigma."""
        r = self.residuals
        out = {}
        for ch in CHANNELS:
            sel = r["channel"] == ch
            # a leverage of 1 (a residual the fit matches exactly) may come out a rounding
            # above it
            keep = np.clip(1.0 - r.loc[sel, "leverage"].to_numpy(float), 0.0, None)
            out[ch] = (float(np.sqrt(np.mean(r.loc[sel, "sigma"].to_numpy(float) ** 2 * keep)))
                       if sel.any() else math.nan)
        return out

    def coefficient_table(self) -> pd.DataFrame:
        """Seed 004 Table 4 layout: one row per coefficient, its form, A1..A6 with sigma."""
        return coefficient_table(self.model, dict(zip(self.aero_names, self.aero_sigma,
                                                      strict=True)))

    def high_correlations(self, threshold: float = CORRELATION_REPORT) -> list[tuple]:
        R = self.correlation()
        out = []
        for i in range(len(self.param_names)):
            for j in range(i + 1, len(self.param_names)):
                if abs(R[i, j]) >= threshold:
                    out.append((self.param_names[i], self.param_names[j], float(R[i, j])))
        return out


_AK = re.compile(r"^(?P<coef>[A-Za-z]+)_A(?P<k>\d+)$")


def coefficient_table(model: AeroModel, sigmas: dict | None = None) -> pd.DataFrame:
    """Table 4 layout of a model: coefficient, form, A1..A6 (value, sigma, held).

    Parameters named ``<coef>_A<k>`` fill the A columns; the others (``M_ref``,
    ``alpha_ref``) are listed in column ``other``.
    """
    sigmas = sigmas or {}
    rows = []
    for coef, form in model.coefficients.items():
        row = {"coefficient": coef, "form": " ".join(form.split())}
        other = []
        for name in model.parameters_in(coef):
            p = model.parameter(name)
            m = _AK.match(name)
            if m and m.group("coef") == coef and 1 <= int(m.group("k")) <= 9:
                k = int(m.group("k"))
                row[f"A{k}"] = p.value
                row[f"A{k}_sigma"] = sigmas.get(name, math.nan)
                row[f"A{k}_held"] = not p.vary
            else:
                v = p.file_value
                other.append(f"{name} = {v:g}{' ' + p.unit if p.unit else ''}"
                             f"{' (held)' if not p.vary else ''}")
        row["other"] = "; ".join(other)
        rows.append(row)
    table = pd.DataFrame(rows)
    cols = ["coefficient", "form"]
    for k in range(1, 10):
        if f"A{k}" in table:
            cols += [f"A{k}", f"A{k}_sigma", f"A{k}_held"]
    cols.append("other")
    return table.loc[:, cols]


def _coloured_middle(per_shot_blocks) -> np.ndarray:
    """Sum over shots and channels of J^T R(i-j) J (Bartlett-tapered residual autocovariance)."""
    total = None
    for J, r, chan in per_shot_blocks:
        P = J.shape[1]
        M = np.zeros((P, P))
        for c in np.unique(chan):
            sel = chan == c
            Jc, rc = J[sel], r[sel]
            n = rc.size
            L = max(2, n // 4)
            Z = Jc * rc[:, None]                 # score contributions
            M += Z.T @ Z
            for lag in range(1, min(L, n - 1) + 1):
                w = 1.0 - lag / (L + 1.0)
                G = Z[lag:].T @ Z[:-lag]
                M += w * (G + G.T)
        total = M if total is None else total + M
    return total


def _pinv_sym(N: np.ndarray, rcond: float) -> np.ndarray:
    d = np.sqrt(np.maximum(np.diag(N), 0.0))
    d[d == 0] = 1.0
    Ns = N / np.outer(d, d)
    w, V = np.linalg.eigh(0.5 * (Ns + Ns.T))
    top = max(float(w[-1]), 0.0) if w.size else 0.0
    keep = w > rcond * top if top > 0 else np.zeros_like(w, dtype=bool)
    inv = np.zeros_like(w)
    inv[keep] = 1.0 / w[keep]
    return (V * inv) @ V.T / np.outer(d, d)


def _near_singular(N: np.ndarray, names: list[str], n_aero: int) -> list[dict]:
    d = np.sqrt(np.maximum(np.diag(N), 0.0))
    out = []
    zero = np.flatnonzero(d == 0)
    for i in zero:
        out.append({"ratio": 0.0, "parameters": {names[i]: 1.0},
                    "hold": names[i],
                    "text": f"{names[i]} has no effect on any measurement: hold it"})
    d[d == 0] = 1.0
    Ns = N / np.outer(d, d)
    w, V = np.linalg.eigh(0.5 * (Ns + Ns.T))
    top = max(float(w[-1]), 1e-300)
    for k in range(len(w)):
        if w[k] >= IDENT_RCOND * top:
            break
        v = V[:, k]
        if np.any(np.abs(v[zero]) > 0.99):
            continue
        order = np.argsort(-np.abs(v))
        parts = {names[i]: float(v[i]) for i in order if abs(v[i]) >= 0.2}
        aero_parts = [i for i in order if i < n_aero and abs(v[i]) >= 0.2]
        hold = names[aero_parts[0]] if aero_parts else names[order[0]]
        mix = " + ".join(f"{v[i]:+.2f} {names[i]}" for i in order[:4] if abs(v[i]) >= 0.2)
        out.append({"ratio": float(w[k] / top), "parameters": parts, "hold": hold,
                    "text": (f"the data do not separate {mix} (eigenvalue ratio "
                             f"{w[k] / top:.1e}): hold {hold} (or add shots that excite it)")})
    return out


def build_result(problem, params: np.ndarray, states, status: str, message: str, history,
                 warnings, iterations: int, t_start: float, options, lam,
                 extra_values=None) -> FitResult:
    """Assemble the :class:`FitResult` at the solver's final point (see module doc):
    ``problem`` is the fit's :class:`cadra.fitting.problem.FitProblem`, ``params`` the full
    aero parameter vector, ``states`` the solver's per-shot states (final reference states,
    predictions and Jacobians), ``extra_values`` the free extras' values."""
    model = problem.model
    aero_idx = problem.aero_indices
    extras = problem.free_extras
    held_extras = problem.held_extras
    na = aero_idx.size
    ns = na + len(extras)
    names_aero = [model.parameters[i].name for i in aero_idx]
    fitted = model.with_values({n: float(params[i]) for n, i in zip(names_aero, aero_idx,
                                                                    strict=True)})
    extra_values = np.array(extra_values if extra_values is not None else [], dtype=float)
    final = problem.at(params, extra_values if len(extras) else None,
                       [st.y_nom.copy() for st in states])
    names = list(names_aero) + [e.name for e in extras]
    offsets = []
    for st in states:
        offsets.append(len(names))
        names += [f"{st.data.shot_id}:{LOCAL_NAMES[k]}" for k in st.local_free]
    P = len(names)
    N = np.zeros((P, P))
    blocks = []
    rows = []
    shot_fits = []
    chi2_total = 0.0
    n_obs = 0
    # no covariance from a Jacobian that is missing or not finite (a start whose trajectory
    # overflows): the result then carries NaN sigmas and its message, never a LinAlgError
    have_jac = all(st.jac is not None and np.all(np.isfinite(st.jac[st.mask]))
                   for st in states)
    jac_rows = []
    for st, off in zip(states, offsets, strict=True):
        sd = st.data
        pred = st.pred if st.pred is not None else np.full(sd.meas.shape, np.nan)
        res = residual(sd.meas, pred)
        nl = st.local_free.size
        if have_jac:
            Jfull = np.zeros((int(st.mask.sum()), P))
            Jw = st.jac[st.mask] / sd.sigma[st.mask][:, None]
            Jfull[:, :ns] = Jw[:, nl:nl + ns]
            Jfull[:, off:off + nl] = Jw[:, :nl]
            N += Jfull.T @ Jfull
            jac_rows.append((Jfull, np.r_[0:ns, off:off + nl]))
            chan = np.nonzero(st.mask)[1]
            blocks.append((Jfull, (res / sd.sigma)[st.mask], chan))
        chi2_shot = float(np.nansum(((res / sd.sigma)[st.mask]) ** 2))
        chi2_total += chi2_shot
        n_obs += int(st.mask.sum())
        rms = {}
        for j, ch in enumerate(CHANNELS):
            sel = st.mask[:, j]
            rms[ch] = float(np.sqrt(np.mean(res[sel, j] ** 2))) if sel.any() else math.nan
        for i in range(len(sd.t_s)):
            for j, ch in enumerate(CHANNELS):
                if st.mask[i, j]:
                    rows.append({"shot_id": sd.shot_id, "station": int(sd.stations[i]),
                                 "t_s": float(sd.t_s[i]), "channel": ch,
                                 "measured": float(sd.meas[i, j]), "fitted": float(pred[i, j]),
                                 "sigma": float(sd.sigma[i, j]), "residual": float(res[i, j]),
                                 "normalized": float(res[i, j] / sd.sigma[i, j])})
        shot_fits.append((st, off, chi2_shot, rms))
    n_free = P
    # Gaussian priors: pseudo-measurements of the parameters (cadra.fitting.priors)
    Jp = prior_rows(model, names)
    N += Jp.T @ Jp
    chi2_prior = prior_chi2(model, params)
    chi2_total += chi2_prior
    if have_jac and P:
        cov = _pinv_sym(N, options.rcond)
        middle = _coloured_middle(blocks) + Jp.T @ Jp
        cov_c = cov @ middle @ cov
        near = _near_singular(N, names, na)
        # leverage: the diagonal of the weighted hat matrix J (J^T J)^+ J^T, shot by shot
        # on the columns its rows touch
        if jac_rows:
            leverage = np.concatenate([
                np.einsum("ij,jk,ik->i", J[:, c], cov[np.ix_(c, c)], J[:, c])
                for J, c in jac_rows])
            jacobian = sparse.vstack([sparse.csr_array(J) for J, _ in jac_rows], format="csr")
        else:
            leverage, jacobian = np.zeros(0), sparse.csr_array((0, P))
    else:
        cov = np.full((P, P), np.nan)
        cov_c = cov.copy()
        near = []
        jacobian = None
        leverage = np.full(len(rows), 0.0 if have_jac else np.nan)
    residuals = pd.DataFrame(rows)
    if len(rows):
        residuals["leverage"] = leverage
    sig = np.sqrt(np.maximum(np.diag(cov), 0.0)) if P else np.zeros(0)
    undetermined = {d["hold"] for d in near}
    for i, name in enumerate(names):
        if name in undetermined:
            sig[i] = math.inf
    fits = []
    for st, off, chi2_shot, rms in shot_fits:
        ls = np.full(len(LOCAL_NAMES), np.nan)
        ls[st.local_free] = sig[off:off + st.local_free.size]
        fits.append(ShotFit(shot_id=st.data.shot_id, t0_s=st.t0, state=st.y_nom.copy(),
                            local_free=tuple(LOCAL_NAMES[k] for k in st.local_free),
                            local_sigma=ls, chi2=chi2_shot, n_observations=int(st.mask.sum()),
                            rms=rms))
    warnings = list(warnings)
    for i, n in zip(aero_idx, names_aero, strict=True):
        p = model.parameters[i]
        v = params[i]
        if v <= p.min or v >= p.max:
            warnings.append(f"{n} = {v:g} is at a bound [{p.min:g}, {p.max:g}]")
    for d in near:
        warnings.append(d["text"])
    return FitResult(
        status=status, message=message, model=fitted, aero_names=tuple(names_aero),
        aero_values=np.array([params[i] for i in aero_idx], dtype=float),
        aero_sigma=sig[:na].copy(), shots=tuple(fits), param_names=tuple(names),
        covariance=cov, covariance_coloured=cov_c, chi2=chi2_total, n_observations=n_obs,
        n_free=n_free, iterations=iterations, history=tuple(history),
        residuals=residuals, near_singular=tuple(near), warnings=tuple(warnings),
        elapsed_s=time.perf_counter() - t_start,
        extras=tuple(extras),
        extra_values=extra_values,
        extra_sigma=sig[na:ns].copy(), held_extras=tuple(held_extras), jacobian=jacobian,
        problem=final,
        initial_values={n: float(model.parameters[i].value)
                        for n, i in zip(names_aero, aero_idx, strict=True)},
        n_priors=len(prior_names(model)), prior_chi2=chi2_prior,
        options={"max_iterations": options.max_iterations,
                 "step_tol_sigma": options.step_tol_sigma,
                 "integration": options.integration.__dict__, "final_lambda": lam})
