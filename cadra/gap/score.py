"""Which unmodelled effect? Score tests and nonlinear refits over the candidate library.

At a fit, each candidate's sensitivity columns C (per measurement, weighted) are projected
orthogonal to the fit's own Jacobian J (every shot's initial state, the free aero parameters,
the effects already added): ``C_perp = (I - P_J) C``. The weighted residual ``r`` regressed on
``C_perp`` gives, without refitting (docs/gap.md):

- the chi^2 the candidate would remove, ``dchi2 = |P_Cperp r|^2`` (exact for an effect that
  enters linearly, the first Gauss-Newton step otherwise);
- its size ``delta = (C_perp^T C_perp)^-1 C_perp^T r`` and covariance
  ``(C_perp^T C_perp)^-1`` times the residual variance;
- an F test of the added parameters (robust to a sigma scale that is off, as stage one's
  are by ~15 %) and the BIC change ``-dchi2/s^2 + k ln n``.

The leading candidates are then refitted for real (:func:`refit_with`: the whole fit redone
with the candidate's parameters free), since a large effect is far from linear.
:func:`diagnose_gap` ranks the candidates, adds the best one if it is significant (weighted
Bonferroni), names the candidates the data cannot tell from it, goes on from its refit, and
repeats until nothing is significant; what then remains is compared with the noise floor, and
if it is still above it the gap is reported as unexplained, with the stations and channels
where it lies (docs/gap.md).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd
from scipy import stats

from cadra.aero import AeroModel
from cadra.channels import POSITION, residual
from cadra.fitting.extras import station_columns
from cadra.fitting.problem import result_problem
from cadra.fitting.result import FitResult
from cadra.fitting.sensitivity import Integration, predict_with_jacobian
from cadra.fitting.solver import FitOptions
from cadra.flight.data import ShotData
from cadra.gap import verdict as vd
from cadra.gap.candidates import Candidate, augmented_model, form_counterpart, library
from cadra.gap.optics import perspective_responses, spark_responses
from cadra.gap.refit import (
    PROFILE_MAX_PARAMS,
    candidate_extras,
    continue_fit,
    fresh_fit,
    param_names,
    profiles,
    refit_with,
)
from cadra.gap.verdict import size_text
from cadra.numfmt import pm


@dataclass(frozen=True, eq=False)
class GapDiagnosis:
    """What :func:`diagnose_gap` found (SI)."""

    ranking: pd.DataFrame            # first round: every candidate, best first
    added: tuple[dict, ...]          # effects added greedily: name, params, size, sigma,
    #                                  covariance (of the params; None if not refitted), p
    rms_before: dict                 # channel -> rms residual (SI) of the fit as given
    rms_after: dict                  # ... after adding the effects
    reduced_chi2_before: float
    reduced_chi2_after: float
    unexplained: bool
    where: pd.DataFrame              # per shot, station, channel: normalized residual after
    verdict: str
    fit_after: FitResult | None = None   # the fit with the added effects (the last refit)
    evidence: pd.DataFrame | None = None  # every test of the final residual (verdict.evidence)
    set_aside: tuple = ()            # (station, channel) misfits set aside as unexplained
    dropped: tuple = ()              # effects added first that left such a misfit standing
    base_note: str = ""              # how the fit given was continued, if it had not converged
    fit_given: FitResult | None = None   # the fit the diagnosis started from (continued)
    #: where the fit as given misses (:func:`cadra.gap.where.where_analysis`), when asked
    where_tables: dict | None = field(default=None, repr=False)

    @property
    def held_inconsistent(self) -> tuple[str, ...]:
        """The held parameters the verdict names inconsistent with the data: freed, no
        misfit left standing, no other candidate explaining as much
        (:func:`cadra.gap.verdict.held_verdict`)."""
        return tuple(a["params"][0] for a in self.added if a["kind"] == "held"
                     and a.get("held_verdict") == "inconsistent")

    def __repr__(self) -> str:
        added = ", ".join(a["effect"] for a in self.added) or "no effect added"
        return (f"<GapDiagnosis: {added}; chi^2/dof {self.reduced_chi2_before:.4g} -> "
                f"{self.reduced_chi2_after:.4g}; {self.verdict[:80]}>")


def _columns(result: FitResult, shots: Sequence[ShotData], cands: Sequence[Candidate],
             integ: Integration):
    """Per shot: weighted residual, the fit's Jacobian (locals, free aero parameters, the
    fit's extras) and each candidate's columns (unweighted rows masked, divided by sigma).
    A dynamics candidate has its parameters per shot: its columns for other shots are 0.
    Predictions and the fit's columns come from the fit's own forward model
    (:func:`cadra.fitting.problem.result_problem`, held extras included), integrated with
    ``integ``; a dynamics candidate's columns are further complex-step runs of the same
    call."""
    problem = replace(result_problem(result, shots), integration=integ)
    fitted = problem.model
    params = fitted.values()
    ids = list(problem.shot_ids)
    xv = np.array([e.value for e in problem.free_extras], dtype=float)
    phys_cands = [c for c in cands if c.kind == "dynamics"]
    aero_cands = [c for c in cands if c.kind in ("aero", "held")]
    meas_cands = [c for c in cands if c.kind == "measurement"]
    more = [np.concatenate([c.phys_dirs for c in phys_cands]) if phys_cands else None
            for _ in ids]
    preds, jacs, sts = problem.jacobian_from(params, xv, list(problem.epoch_states),
                                             extra_phys_dirs=more, with_states=True)
    out = []
    for k_shot, sd in enumerate(problem.shots):
        sid = sd.shot_id
        sf = result.shots[k_shot]
        local = problem.local_free[k_shot]
        pred, J, states = preds[k_shot], jacs[k_shot], sts[k_shot]
        n_fit = local.size + problem.n_shared
        Jfit = J[:, :, :n_fit]
        phys, ref = problem.physics(k_shot, xv)
        cols = {}
        at = n_fit
        for c in phys_cands:
            k = c.phys_dirs.shape[0]
            C = np.zeros(J.shape[:2] + (len(param_names(c, ids)),))
            j0 = 0 if len(ids) == 1 or c.scope == "set" else k_shot * k
            C[:, :, j0:j0 + k] = J[:, :, at:at + k]
            cols[c.name] = C
            at += k
        for c in aero_cands:
            aug = augmented_model(fitted, c)
            idx = [aug.index(n) for n in c.params]
            _, Ja = predict_with_jacobian(problem.epoch_states[k_shot], problem.epochs[k_shot],
                                          sd.t_s, phys, aug.compile(), aug.values(), ref, [],
                                          idx, integ)
            cols[c.name] = Ja
        for c in meas_cands:
            cols[c.name] = station_columns(candidate_extras(c, ids), sid, sd.stations, pred, states)
        mask = sd.mask
        w = 1.0 / sd.sigma[mask]
        r = (residual(sd.meas, pred)[mask]) * w
        out.append({"shot": sd, "fit": sf, "r": r, "J": Jfit[mask] * w[:, None],
                    "local": local.size,
                    "cols": {k: C[mask] * w[:, None] for k, C in cols.items()},
                    "mask": mask})
    return out


def _stack(per_shot, n_shared):
    """Dense block-arrow Jacobian of the fit (locals per shot, shared aero and extras) and
    the weighted residual."""
    n_loc = sum(p["local"] for p in per_shot)
    rows = sum(p["r"].size for p in per_shot)
    J = np.zeros((rows, n_loc + n_shared))
    r = np.zeros(rows)
    at = col = 0
    for p in per_shot:
        m, nl = p["r"].size, p["local"]
        J[at:at + m, col:col + nl] = p["J"][:, :nl]
        J[at:at + m, n_loc:] = p["J"][:, nl:]
        r[at:at + m] = p["r"]
        at += m
        col += nl
    return J, r


def _cand_matrix(per_shot, name):
    return np.concatenate([p["cols"][name] for p in per_shot])


def _orth(A, rcond=1e-10):
    if A.shape[1] == 0:
        return A
    U, s, _ = np.linalg.svd(A, full_matrices=False)
    return U[:, s > rcond * max(s.max(), 1e-300)]


#: a candidate's column whose norm is below this fraction of the fit's largest column is
#: exactly zero: the data do not depend on that parameter. A sphere's pitching-moment terms,
#: say: the positions its record holds do not depend on them, and their computed derivatives
#: are rounding (largest entries 1e-27-1e-13, against column norms of 1e4-1e9 for the fit's
#: own). Scored as a direction, such rounding is a random unit vector: a chi^2 drop drawn from
#: chi^2_k, so the candidate was refitted (one time in twenty, and from scratch if aero) and
#: could be added at the test's false-alarm rate. The margin to any column that matters is
#: many orders of magnitude either way (docs/gap.md, "Ranking").
ZERO_COLUMN_REL = 1e-10


def score(Q, r, C, n_obs, n_free, scale: float | None = None):
    """Score test of candidate columns C against the fit basis Q: dict of statistics, or
    None if no column is left. ``scale``: the fit's largest column norm; a column below
    :data:`ZERO_COLUMN_REL` of it is zero (the parameter's sigma is then not determined)."""
    zero = np.zeros(C.shape[1], dtype=bool)
    if scale is not None:
        zero = np.linalg.norm(C, axis=0) <= ZERO_COLUMN_REL * scale
        if zero.all():
            return None
        C = np.where(zero, 0.0, C)
    Cp = C - Q @ (Q.T @ C)
    Qc = _orth(Cp)
    k = Qc.shape[1]
    if k == 0:
        return None
    proj = Qc.T @ r
    dchi2 = float(proj @ proj)
    chi2 = float(r @ r)
    dof_after = n_obs - n_free - k
    s2 = max((chi2 - dchi2) / max(dof_after, 1), 1e-300)
    F = (dchi2 / k) / s2
    p = float(stats.f.sf(F, k, max(dof_after, 1)))
    delta, *_ = np.linalg.lstsq(Cp, r, rcond=None)
    cov = np.linalg.pinv(Cp.T @ Cp) * max(s2, 1.0)
    sigma = np.sqrt(np.maximum(np.diag(cov), 0.0))
    sigma[zero] = np.inf
    return {"dchi2": dchi2, "k": k, "F": F, "p": p, "delta": delta, "sigma": sigma,
            "dbic": -dchi2 / max(s2, 1.0) + k * math.log(n_obs), "Cp": Cp}


#: refit chi^2 within this of the best: "the data cannot tell them apart" (both refitted, or
#: with collinear columns); a likelihood ratio below e^2 ~ 7
ALIAS_DCHI2 = 4.0
#: canonical correlation of the projected columns above which two candidates are aliases
#: (when they were not both refitted)
ALIAS_CORRELATION = 0.95
#: a candidate is refitted nonlinearly only if its linear score's uncorrected p-value is below
#: this (far above any significance level used: a pre-filter, not a test)
REFIT_P = 0.05


def _sizes(fit_res: FitResult, c: Candidate, shot_ids) -> tuple[list, list, list]:
    names = param_names(c, shot_ids)
    return (list(names), [fit_res.value(n) for n in names], [fit_res.sigma(n) for n in names])


def _cov_block(fit_res: FitResult, names) -> list[list[float]] | None:
    """The fit's covariance of ``names`` (SI), or None if one is not a fitted parameter."""
    pn = list(fit_res.param_names)
    if any(n not in pn for n in names):
        return None
    ii = [pn.index(n) for n in names]
    return np.asarray(fit_res.covariance)[np.ix_(ii, ii)].tolist()


def _canonical_corr(A: np.ndarray, B: np.ndarray) -> float:
    """Largest canonical correlation between the column spans of A and B."""
    qa, qb = _orth(A), _orth(B)
    if qa.shape[1] == 0 or qb.shape[1] == 0:
        return 0.0
    return float(np.linalg.svd(qa.T @ qb, compute_uv=False).max())


def _test(chi2_base, chi2_new, k, n_obs, n_free):
    """F test and BIC change of ``k`` added parameters that took chi^2 from base to new."""
    dchi2 = max(chi2_base - chi2_new, 0.0)
    dof_after = max(n_obs - n_free - k, 1)
    s2 = max(chi2_new / dof_after, 1e-300)
    F = (dchi2 / k) / s2
    return {"dchi2": dchi2, "F": F, "p": float(stats.f.sf(F, k, dof_after)),
            "dbic": -dchi2 / max(s2, 1.0) + k * math.log(n_obs)}


def _take_refit(row: dict, rf: FitResult | None, chi2_base: float, k: int, n_obs: int,
                n_free: int, shot_ids) -> None:
    """A ranking row's test and sizes from a refit (kept linear if the refit failed)."""
    if rf is None or rf.status == "failed" or not math.isfinite(rf.chi2):
        return
    row["_test"] = _test(chi2_base, rf.chi2, k, n_obs, n_free)
    row["_size"] = list(zip(*_sizes(rf, row["_c"], shot_ids), strict=True))
    row["_refit"] = rf


def _held_effects(before: FitResult, after: FitResult, name: str) -> dict:
    """What freeing a held parameter did: its held value, and the free aero parameters it
    moved by more than their sigma in the fit that held it (their sigmas are not valid while
    it is held), largest move first."""
    moved = []
    for n, v, s in zip(before.aero_names, before.aero_values, before.aero_sigma, strict=True):
        if n == name or not (math.isfinite(s) and s > 0):
            continue
        shift = (after.value(n) - v) / s
        if abs(shift) > 1.0:
            moved.append((n, float(shift)))
    moved.sort(key=lambda x: -abs(x[1]))
    return {"held_value": float(before.model.parameter(name).value), "moved": moved}


def _greedy(result: FitResult, shots: Sequence[ShotData], model: AeroModel,
            cands: Sequence[Candidate], *, alpha: float, threshold: dict, max_effects: int,
            integ: Integration, refit_physics: int, refit_measurement: int, profile: bool,
            bar, converged_only: bool = False):
    """The rounds of the ranking (module doc; :func:`diagnose_gap`): returns the effects
    added, the first round's ranking table and the last fit. ``converged_only``: the fit
    given did not converge, so only refits that converge are ranked (every refit from a
    point short of the minimum lowers chi^2)."""
    ids = [sf.shot_id for sf in result.shots]
    added: list[dict] = []
    ranking = None
    current = result
    remaining = list(cands)
    for round_ in range(max_effects):
        per = _columns(current, shots, remaining, integ)
        J, r = _stack(per, current.model.free_indices().size + len(current.extras))
        n_obs, n_free = r.size, J.shape[1]
        Q = _orth(J)
        scale = float(np.linalg.norm(J, axis=0).max(initial=0.0))
        lin = {}
        for c in remaining:
            sc = score(Q, r, _cand_matrix(per, c.name), n_obs, n_free, scale)
            if sc is not None:
                lin[c.name] = sc
        if not lin:
            break
        # refitted: the refit_physics physics and refit_measurement measurement
        # candidates with the largest linear chi^2 drop, if that drop is not plainly noise
        # (uncorrected p < REFIT_P); a large nonlinear effect still makes its candidate's
        # linear drop large, if not exact
        to_refit = []
        for kinds, n_refit in ((("dynamics",), refit_physics), (("aero",), refit_physics),
                               (("held",), refit_physics),
                               (("measurement",), refit_measurement)):
            pool = [c for c in remaining if c.kind in kinds
                    and c.name in lin and lin[c.name]["p"] < REFIT_P]
            pool.sort(key=lambda c, lin=lin: -lin[c.name]["dchi2"])
            to_refit += pool[:n_refit]
        rows = []
        scratch = set()         # candidates fitted from scratch this round
        for c in remaining:
            if c.name not in lin:
                continue
            sc = lin[c.name]
            k = len(param_names(c, ids))
            row = {"candidate": c.name, "kind": c.kind,
                   "params": ", ".join(param_names(c, ids)),
                   "dchi2_linear": sc["dchi2"], "_c": c, "_refit": None}
            test = {"dchi2": sc["dchi2"], "F": sc["F"], "p": sc["p"], "dbic": sc["dbic"]}
            size = [(n, d, e) for n, d, e in zip(param_names(c, ids), sc["delta"],
                                                 sc["sigma"], strict=False)]
            row.update({"_test": test, "_size": size})
            if c in to_refit:
                # physics refits get the full iteration budget: a large effect takes a
                # while to settle, and a half-settled refit would lose the ranking
                rf = refit_with(current, shots, [c], None if c.kind == "measurement"
                                else FitOptions())
                if c.kind in ("aero", "held"):
                    # an aero term also gets a fit from scratch (linear-theory start):
                    # a large one bends the fit without it far from its basin
                    fresh = fresh_fit(current, shots, c, model)
                    scratch.add(c.name)
                    if fresh is not None and (rf is None or fresh.chi2 < rf.chi2):
                        rf = fresh
                if bar is not None:
                    bar.update(1)
                _take_refit(row, rf, current.chi2, k, n_obs, n_free, ids)
            rows.append(row)
        if not any(r["_refit"] is not None and stats.chi2.sf(
                r["_refit"].chi2, max(r["_refit"].dof, 1)) >= alpha for r in rows):
            # no refit reached the noise floor: the body and air effects get a fit from
            # scratch too (a large one can leave the fit in a basin that a refit from
            # there cannot leave; a 0.27 mm cg offset on M2-2429 lost to an aero term)
            for row in rows:
                c = row["_c"]
                if c.kind == "dynamics" and c in to_refit:
                    fresh = fresh_fit(current, shots, c, model)
                    scratch.add(c.name)
                    if bar is not None:
                        bar.update(1)
                    if fresh is not None and (row["_refit"] is None
                                              or fresh.chi2 < row["_refit"].chi2):
                        _take_refit(row, fresh, current.chi2, len(param_names(c, ids)),
                                    n_obs, n_free, ids)
        if converged_only and any(r["_refit"] is not None and r["_refit"].status == "converged"
                                  for r in rows):
            # from a point short of the minimum every refit lowers chi^2: rank only the
            # candidates whose refit converged
            for row in rows:
                if row["_refit"] is None or row["_refit"].status != "converged":
                    row["_test"] = dict(row["_test"], p=1.0, dbic=math.inf)
        for row in rows:
            test, size = row.pop("_test"), row["_size"]
            row.update({"dchi2": test["dchi2"], "F": test["F"], "p_value": test["p"],
                        "dbic": test["dbic"], "refit": row["_refit"] is not None,
                        "size": "; ".join(f"{n} = {pm(v, e)}" for n, v, e in size)})
        table = pd.DataFrame(rows)
        # rank by the Bonferroni-adjusted p-value (p over its kind's level, times alpha),
        # then by the BIC change: where two p-values are both ~0 the information criterion
        # decides, which charges a per-shot form for its parameters against a shared one
        table["p_adjusted"] = [min(1.0, p * alpha / threshold[
            "measurement" if k == "measurement" else "physics"])
            for p, k in zip(table["p_value"], table["kind"], strict=True)]
        table = table.sort_values(["p_adjusted", "dbic"], ascending=[True, True],
                                  kind="stable").reset_index(drop=True)
        best = table.iloc[0]
        # the two forms of a range-air effect (per shot / shared by the set), both
        # significant: the information criterion chooses, charging the per-shot form for
        # its parameters (the F test's p-values of large effects both underflow to 0)
        other_form = form_counterpart(best["candidate"])
        if other_form is not None:
            o = table[table["candidate"] == other_form]
            if len(o) and o["p_adjusted"].iloc[0] < alpha and o["dbic"].iloc[0] < best["dbic"]:
                table = pd.concat([o, table[table["candidate"] != other_form]],
                                  ignore_index=True)
                best = table.iloc[0]
                other_form = form_counterpart(best["candidate"])
        # aliases: collinear with the best in this round's linear columns, and a refit
        # chi^2 drop within ALIAS_DCHI2 of the best's; the other form (per shot / shared)
        # of the same range-air effect is not an alias but the form not chosen
        Cb = _cand_matrix(per, best["candidate"])
        Cb = Cb - Q @ (Q.T @ Cb)
        aliases = []
        for _, row in table.iloc[1:].iterrows():
            if row["dchi2"] < best["dchi2"] - ALIAS_DCHI2 or row["candidate"] == other_form:
                continue
            Cj = _cand_matrix(per, row["candidate"])
            # both refitted: each refit's chi^2 is its own maximum likelihood, so a
            # drop within ALIAS_DCHI2 is a likelihood ratio below e^2 whatever their
            # linear columns (two large effects can reach the same chi^2 along different
            # columns: an inertia asymmetry and products of inertia on a symmetric body
            # that does not spin, 40044 and 40043.98 on one M1 trial)
            both_refit = best["_refit"] is not None and row["_refit"] is not None
            if both_refit or _canonical_corr(Cb, Cj - Q @ (Q.T @ Cj)) >= ALIAS_CORRELATION:
                aliases.append(row["candidate"])
        table["alias_of_best"] = table["candidate"].isin(aliases)
        if ranking is None:
            ranking = table.drop(columns=["_c", "_refit", "_size"])
        if not (best["p_adjusted"] < alpha and best["dbic"] < 0):
            break
        c = best["_c"]
        form = None
        if other_form is not None and other_form in set(table["candidate"]):
            o = table[table["candidate"] == other_form].iloc[0]
            form = {"chosen": "shared by the set" if c.scope == "set" else "per shot",
                    "other": other_form, "dbic_chosen": float(best["dbic"]),
                    "dbic_other": float(o["dbic"]), "other_refit": bool(o["refit"])}
        rf = best["_refit"]
        if rf is not None and rf.status != "converged":
            # the refits run a short iteration budget; the one added is finished properly
            more = refit_with(rf, shots, [], FitOptions())
            if more is not None and more.chi2 <= rf.chi2:
                rf = more
        if rf is not None and c.name not in scratch and stats.chi2.sf(
                rf.chi2, max(rf.dof, 1)) < alpha:
            # still above the noise floor: the fit may have stayed in the basin of the
            # fit without the effect; one fit from scratch with it (unless it had one)
            fresh = fresh_fit(current, shots, c, model)
            if fresh is not None and fresh.chi2 < rf.chi2:
                rf = fresh
        if rf is not best["_refit"]:
            t = _test(current.chi2, rf.chi2, len(param_names(c, ids)), n_obs, n_free)
            best = best.copy()
            best["dchi2"], best["p_value"] = t["dchi2"], t["p"]
            best["_size"] = list(zip(*_sizes(rf, c, ids), strict=True))
        names, vals, sigs = zip(*best["_size"], strict=True)
        # a refit that did not converge: its sigma is a linearization at a point of a
        # flat or curved valley; the profile likelihood is the honest interval
        intervals = None
        if (profile and rf is not None and rf.status != "converged"
                and len(names) <= PROFILE_MAX_PARAMS):
            intervals = profiles(rf, shots, names)
            if bar is not None:
                bar.update(1)
        entry = {"effect": c.name, "kind": c.kind, "params": tuple(names),
                 "size": [float(v) for v in vals], "sigma": [float(v) for v in sigs],
                 "covariance": _cov_block(rf, names) if rf is not None else None,
                 "interval_2sigma": intervals,
                 "p_value": float(best["p_value"]), "dchi2": float(best["dchi2"]),
                 "round": round_ + 1, "refit": rf is not None,
                 "refit_status": rf.status if rf is not None else "linear",
                 "aliases": tuple(aliases), "form": form}
        if c.kind == "held" and rf is not None:
            entry.update(_held_effects(current, rf, c.params[0]))
        added.append(entry)
        remaining = [x for x in remaining if x.name != c.name and x.name != other_form]
        if rf is None:
            break       # a linear-only addition: no fit to go on from
        current = rf
    return added, ranking, current


def diagnose_gap(result: FitResult, shots: Sequence[ShotData], model: AeroModel | None = None,
                 *, candidates: Sequence[Candidate] | None = None, alpha: float = 0.01,
                 max_effects: int = 3, integ: Integration | None = None,
                 refit_physics: int = 3, refit_measurement: int = 3,
                 profile: bool = True, progress: bool = False,
                 facility=None) -> GapDiagnosis:
    """Rank the candidate effects for a fit, add the significant ones greedily, and give one
    verdict from every test.

    A fit short of convergence is first continued (:func:`cadra.gap.refit.continue_fit`);
    if it still falls short, the diagnosis runs from its best point, says so, and ranks only
    the candidates whose refits converge. Each round: every candidate is scored linearly
    against the current fit (module doc); then the ``refit_physics`` best dynamics, aero and
    held-parameter candidates (each kind) and the ``refit_measurement`` best measurement
    candidates (by linear chi^2 drop, among those with an uncorrected linear p-value below
    :data:`REFIT_P`) are refitted nonlinearly; candidates are ranked by the refit's chi^2
    drop where there is one, else the linear one (F test, Bonferroni-adjusted p-value: half
    of ``alpha`` shared by the physics candidates, half by the station ones; then the BIC
    change). The best is added when its adjusted p-value is below ``alpha`` and its BIC
    improves; candidates the data cannot tell from it are named beside it as aliases.

    Then every test of the residual (:func:`cadra.gap.verdict.evidence`: global chi^2, per
    channel, per station and channel, cross-shot repetition, runs of sign, content at the
    motion frequencies; family-wise level ``alpha`` over them all). A misfit localized at a
    few stations and channels that stands after the effects added is set aside as an
    unexplained offset there and the ranking is redone with it: an effect that left it
    standing and is not found again is not the explanation (``dropped``).
    ``model``: the model as given to the fit (default ``result.model``): the library is built
    for it, and fits from scratch start from its values (:func:`fresh_fit`). ``facility``:
    the facility (or its name or file) whose optics the optics candidates are computed from
    (:mod:`cadra.gap.optics`; default each shot's own, ``ShotData.facility``).

    Raises ``ValueError`` for a fit with no degrees of freedom or no finite chi^2 (an
    underdetermined fit has no gap to diagnose: every test would be on nothing)."""
    if result.dof <= 0 or not math.isfinite(result.chi2):
        raise ValueError(f"the fit has {result.n_observations} measurements for "
                         f"{result.n_free} unknowns (chi^2 {result.chi2:.4g}): underdetermined, "
                         "there is no gap to diagnose; hold parameters or add shots")
    integ = integ or Integration()
    model = model or result.model
    shots = list(shots)
    given = result
    result = continue_fit(result, shots)
    base_note = ""
    if result.status != "converged":
        base_note = (f"the fit did not converge ({given.status}; continued, still "
                     f"{result.status}): the diagnosis runs from its best point (chi^2/dof "
                     f"{result.reduced_chi2:.3g}) and ranks only effects whose refits converge")
    elif given.status != "converged":
        base_note = (f"the fit as given had not converged ({given.status}); it was continued "
                     f"to convergence (chi^2/dof {given.reduced_chi2:.3g} -> "
                     f"{result.reduced_chi2:.3g}) before the diagnosis")
    ids = [sf.shot_id for sf in result.shots]
    stations = sorted({int(st) for s in shots for st in s.stations})
    mach = float(np.mean([np.median(np.linalg.norm(np.diff(s.meas[:, POSITION], axis=0), axis=1)
                                    / np.diff(s.t_s)) / s.rigid.speed_of_sound_m_s
                          for s in shots]))
    cands = (list(candidates) if candidates is not None
             else library(model, stations, mach, n_shots=len(ids),
                          sparks=spark_responses(shots, facility),
                          perspective=perspective_responses(shots, facility)))
    # weighted Bonferroni (family-wise error alpha): half of alpha for the physics
    # candidates (dynamics, aero, held: few), half for the per-station measurement ones
    # (many), so the many station candidates do not dilute the test of the few physical ones
    n_phys = sum(c.kind != "measurement" for c in cands)
    n_meas = len(cands) - n_phys
    halves = 2 if n_phys and n_meas else 1
    threshold = {kind: alpha / halves / max(n, 1) for kind, n in
                 (("physics", n_phys), ("measurement", n_meas))}
    opts = {"alpha": alpha, "threshold": threshold, "max_effects": max_effects,
            "integ": integ, "refit_physics": refit_physics,
            "refit_measurement": refit_measurement, "profile": profile,
            "converged_only": result.status != "converged"}
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(desc="cadra2 diagnose", unit="refit", leave=False)
    dropped: list[dict] = []
    set_aside: tuple = ()
    try:
        added, ranking, current = _greedy(result, shots, model, cands, bar=bar, **opts)
        ev = vd.evidence(current, shots, alpha)
        cells = vd.localized_cells(ev)
        if cells:
            # a misfit at a few stations and channels that stands after the effects: set
            # aside as unexplained offsets there (sized by the fit), and the ranking redone
            # with them, without those stations' own candidates
            aside = refit_with(result, shots, [], FitOptions(),
                               extras=vd.offset_extras(cells))
            if aside is not None:
                set_aside = tuple(cells)
                if added:
                    keep = [c for c in cands if not vd.covers(c, cells)]
                    added2, _, current = _greedy(aside, shots, model, keep, bar=bar, **opts)
                    kept = {a["effect"] for a in added2}
                    dropped = [a for a in added if a["effect"] not in kept]
                    added = added2
                else:
                    current = aside
                ev = vd.evidence(current, shots, alpha)
    finally:
        if bar is not None:
            bar.close()
    rr = current.residuals
    where = pd.DataFrame({"shot_id": rr["shot_id"], "station": rr["station"],
                          "channel": rr["channel"], "normalized": rr["normalized"]})
    verdict, unexplained = vd.compose(added, dropped, set_aside, ev, current, base_note,
                                      result.reduced_chi2, ranking)
    return GapDiagnosis(ranking=ranking if ranking is not None else pd.DataFrame(),
                        added=tuple(added), rms_before=result.rms(), rms_after=current.rms(),
                        reduced_chi2_before=result.reduced_chi2,
                        reduced_chi2_after=current.reduced_chi2,
                        unexplained=bool(unexplained), where=where, verdict=verdict,
                        fit_after=current, evidence=ev, set_aside=set_aside,
                        dropped=tuple(dropped), base_note=base_note, fit_given=result)


__all__ = ["GapDiagnosis", "diagnose_gap", "fresh_fit", "refit_with", "score", "size_text"]
