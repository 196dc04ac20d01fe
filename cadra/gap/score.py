"""Which unmodelled effect? Gauss-Newton score tests over the candidate library.

At a converged fit, each candidate's sensitivity columns C (per measurement, weighted) are
projected orthogonal to the fit's own Jacobian J (every shot's initial state and the free
aero parameters): ``C_perp = (I - P_J) C``. The weighted residual ``r`` regressed on
``C_perp`` gives, without refitting (DESIGN.md section 9):

- the chi^2 the candidate would remove, ``dchi2 = |P_Cperp r|^2`` (exact for an effect that
  enters linearly, the first Gauss-Newton step otherwise);
- its size ``delta = (C_perp^T C_perp)^-1 C_perp^T r`` and covariance
  ``(C_perp^T C_perp)^-1`` times the residual variance;
- an F test of the added parameters (robust to a sigma scale that is off, as stage one's
  are by ~15 %) and the BIC change ``-dchi2/s^2 + k ln n``.

:func:`diagnose_gap` ranks every candidate, adds the best one if it is significant
(F-test p-value below ``alpha`` / number of candidates, Bonferroni), re-scores the rest against
the augmented fit, and repeats until nothing is significant; what then remains is compared with
the noise floor, and if it is still above it the gap is reported as unexplained, with the
stations and channels where it lies.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import stats

from cadra.aero import AeroModel
from cadra.dynamics.observe import rotation_fb_batch
from cadra.fitting.data import CHANNELS, ShotData
from cadra.fitting.result import FitResult
from cadra.fitting.sensitivity import (
    LOCAL_NAMES,
    Integration,
    predict_with_jacobian,
)
from cadra.gap.candidates import Candidate, augmented_model, library


@dataclass(frozen=True, eq=False)
class GapDiagnosis:
    """What :func:`diagnose_gap` found (SI)."""

    ranking: pd.DataFrame            # first round: every candidate, best first
    added: tuple[dict, ...]          # effects added greedily: name, params, size, sigma, p
    rms_before: dict                 # channel -> rms residual (SI) of the fit as given
    rms_after: dict                  # ... after adding the effects
    reduced_chi2_before: float
    reduced_chi2_after: float
    unexplained: bool
    where: pd.DataFrame              # per shot, station, channel: normalized residual after
    verdict: str


def _columns(result: FitResult, shots: Sequence[ShotData], model: AeroModel,
             cands: Sequence[Candidate], integ: Integration):
    """Per shot: weighted residual, fit Jacobian and each candidate's columns (unweighted
    rows are masked and divided by sigma)."""
    fitted = result.model
    program = fitted.compile()
    params = fitted.values()
    aero_free = fitted.free_indices()
    phys_cands = [c for c in cands if c.kind == "dynamics"]
    phys_dirs = (np.concatenate([c.phys_dirs for c in phys_cands]) if phys_cands
                 else None)
    aero_cands = [c for c in cands if c.kind == "aero"]
    by_id = {s.shot_id: s for s in shots}
    out = []
    for sf in result.shots:
        sd = by_id[sf.shot_id]
        local = np.array([LOCAL_NAMES.index(n) for n in sf.local_free], dtype=int)
        phys = sd.rigid.phys()
        ref = sd.rigid.ref_from_cg_body_m()
        pred, J, states = predict_with_jacobian(sf.state, sf.t0_s, sd.t_s, phys, program,
                                                params, ref, local, aero_free, integ,
                                                phys_dirs=phys_dirs, with_states=True)
        n_fit = local.size + aero_free.size
        R = rotation_fb_batch(states[:, 6:10])
        cols = {}
        at = n_fit
        for c in phys_cands:
            k = c.phys_dirs.shape[0]
            C = J[:, :, at:at + k].copy()
            if c.name == "lateral cg offset":
                # the observed reference point is seen from the true cg: ref - cg shifts by -d
                for j, axis in enumerate((1, 2)):
                    C[:, :3, j] -= R[:, :, axis]
            cols[c.name] = C
            at += k
        for c in aero_cands:
            aug = augmented_model(fitted, c)
            idx = [aug.index(n) for n in c.params]
            _, Ja = predict_with_jacobian(sf.state, sf.t0_s, sd.t_s, phys, aug.compile(),
                                          aug.values(), ref, [], idx, integ)
            cols[c.name] = Ja
        v = states[:, 3:6]
        for c in cands:
            if c.kind != "measurement":
                continue
            C = np.zeros((len(sd.t_s), 5, c.n_params))
            rows = np.flatnonzero(sd.stations == c.station)
            for i in rows:
                if c.measure.startswith("position_"):
                    C[i, "xyz".index(c.measure[-1]), 0] = 1.0
                elif c.measure == "timing":
                    C[i, :3, 0] = v[i]
                elif c.measure == "scale":
                    C[i, 0, 0] = pred[i, 0] - np.median(sd.meas[sd.stations == c.station, 0])
                    C[i, 1, 0] = pred[i, 1]
                    C[i, 2, 0] = pred[i, 2]
            cols[c.name] = C
        mask = sd.mask
        w = 1.0 / sd.sigma[mask]
        r = ((sd.meas - pred)[mask]) * w
        Jfit = J[:, :, :n_fit][mask] * w[:, None]
        out.append({"shot": sd, "fit": sf, "r": r, "J": Jfit, "local": local.size,
                    "cols": {k: C[mask] * w[:, None] for k, C in cols.items()},
                    "mask": mask})
    return out


def _stack(per_shot, n_aero):
    """Dense block-arrow Jacobian of the fit (locals per shot, shared aero) and residual."""
    n_loc = sum(p["local"] for p in per_shot)
    rows = sum(p["r"].size for p in per_shot)
    J = np.zeros((rows, n_loc + n_aero))
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


def score(Q, r, C, n_obs, n_free):
    """Score test of candidate columns C against the fit basis Q: dict of statistics."""
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
    return {"dchi2": dchi2, "k": k, "F": F, "p": p, "delta": delta,
            "sigma": np.sqrt(np.maximum(np.diag(cov), 0.0)),
            "dbic": -dchi2 / max(s2, 1.0) + k * math.log(n_obs), "Cp": Cp}


def _refit_aero(result: FitResult, shots, cand: Candidate, start_values) -> FitResult | None:
    """The fit redone with ``cand``'s terms (their parameters free, started at the score
    estimate), from the fitted states; None if it does not converge."""
    from cadra.fitting.solver import FitOptions, fit

    aug = augmented_model(result.model, cand).with_values(
        dict(zip(cand.params, (float(v) for v in start_values), strict=True)))
    by_id = {s.shot_id: s for s in shots}
    local = [np.array([LOCAL_NAMES.index(n) for n in sf.local_free]) for sf in result.shots]
    try:
        res = fit([by_id[sf.shot_id] for sf in result.shots], aug,
                  [sf.state for sf in result.shots], options=FitOptions(),
                  local_free=local)
    except (ValueError, FloatingPointError):
        return None
    return res if res else None


def diagnose_gap(result: FitResult, shots: Sequence[ShotData], model: AeroModel | None = None,
                 *, candidates: Sequence[Candidate] | None = None, alpha: float = 0.01,
                 max_effects: int = 3, integ: Integration | None = None) -> GapDiagnosis:
    """Rank the candidate effects for a converged fit and add the significant ones greedily
    (module doc). ``model`` is the fitted model (default ``result.model``)."""
    integ = integ or Integration()
    model = model or result.model
    shots = list(shots)
    stations = sorted({int(st) for s in shots for st in s.stations})
    mach = float(np.mean([np.median(np.linalg.norm(np.diff(s.meas[:, :3], axis=0), axis=1)
                                    / np.diff(s.t_s)) / s.rigid.speed_of_sound_m_s
                          for s in shots]))
    cands = list(candidates) if candidates is not None else library(model, stations, mach)
    per = _columns(result, shots, model, cands, integ)
    J, r = _stack(per, result.model.free_indices().size)
    n_obs = r.size
    n_free = J.shape[1]
    Q = _orth(J)
    sig_all = np.concatenate([p["shot"].sigma[p["mask"]] for p in per])
    chan_all = np.concatenate([np.nonzero(p["mask"])[1] for p in per])
    stat_all = np.concatenate([np.broadcast_to(p["shot"].stations[:, None],
                                               p["mask"].shape)[p["mask"]] for p in per])
    shot_all = np.concatenate([np.full(int(p["mask"].sum()), p["shot"].shot_id) for p in per])

    def rms_by_channel(res_w):
        out = {}
        for j, ch in enumerate(CHANNELS):
            sel = chan_all == j
            out[ch] = float(np.sqrt(np.mean((res_w[sel] * sig_all[sel]) ** 2))) if sel.any() \
                else math.nan
        return out

    rms_before = rms_by_channel(r)
    dof0 = n_obs - n_free
    rchi0 = float(r @ r) / max(dof0, 1)
    threshold = alpha / max(len(cands), 1)
    added = []
    ranking = None
    resid = r.copy()
    basis = Q
    n_used = n_free
    remaining = list(cands)
    for round_ in range(max_effects):
        rows = []
        for c in remaining:
            sc = score(basis, resid, _cand_matrix(per, c.name), n_obs, n_used)
            if sc is None:
                continue
            rows.append({"candidate": c.name, "kind": c.kind, "params": ", ".join(c.params),
                         "dchi2": sc["dchi2"], "F": sc["F"], "p_value": sc["p"],
                         "dbic": sc["dbic"],
                         "size": "; ".join(f"{n} = {d:.4g} ± {s:.2g}" for n, d, s in
                                           zip(c.params, sc["delta"], sc["sigma"],
                                               strict=False)),
                         "_sc": sc, "_c": c})
        if not rows:
            break
        table = pd.DataFrame(rows).sort_values("p_value", kind="stable").reset_index(drop=True)
        if ranking is None:
            ranking = table.drop(columns=["_sc", "_c"])
        best = table.iloc[0]
        if not (best["p_value"] < threshold and best["dbic"] < 0):
            break
        sc, c = best["_sc"], best["_c"]
        resid = resid - sc["Cp"] @ sc["delta"]
        basis = _orth(np.column_stack([basis, sc["Cp"]]))
        n_used += sc["k"]
        added.append({"effect": c.name, "kind": c.kind, "params": c.params,
                      "size": [float(v) for v in sc["delta"]],
                      "sigma": [float(v) for v in sc["sigma"]], "p_value": float(sc["p"]),
                      "dchi2": float(sc["dchi2"]), "round": round_ + 1})
        remaining = [x for x in remaining if x.name != c.name]
    rms_after = rms_by_channel(resid)
    dof1 = n_obs - n_used
    rchi1 = float(resid @ resid) / max(dof1, 1)
    if len(added) == 1 and added[0]["kind"] == "aero":
        # confirm a lone aero effect by a nonlinear refit with the augmented model (the score
        # step is one Gauss-Newton step; a large missing term needs the full fit)
        refit = _refit_aero(result, shots, next(c for c in cands
                                                if c.name == added[0]["effect"]),
                            added[0]["size"])
        if refit is not None:
            rr = refit.residuals
            added[0]["size"] = [refit.value(n) for n in added[0]["params"]]
            added[0]["sigma"] = [refit.sigma(n) for n in added[0]["params"]]
            added[0]["refit"] = True
            rms_after = {ch: float(np.sqrt(np.mean(rr.loc[rr["channel"] == ch, "residual"]
                                                   ** 2)))
                         if (rr["channel"] == ch).any() else math.nan for ch in CHANNELS}
            rchi1 = refit.reduced_chi2
            resid_map = {(a, b, c): v for a, b, c, v in
                         zip(rr["shot_id"], rr["station"], rr["channel"], rr["normalized"],
                             strict=True)}
            resid = np.array([resid_map.get((sh, int(st), CHANNELS[ch]), 0.0)
                              for sh, st, ch in zip(shot_all, stat_all, chan_all,
                                                    strict=True)])
    # still above the noise floor? chi^2 test of what remains
    p_floor = float(stats.chi2.sf(float(resid @ resid), max(dof1, 1)))
    unexplained = p_floor < alpha
    where = pd.DataFrame({"shot_id": shot_all, "station": stat_all,
                          "channel": [CHANNELS[j] for j in chan_all], "normalized": resid})
    if unexplained:
        worst = (where.assign(sq=where["normalized"] ** 2)
                 .groupby(["station", "channel"])["sq"].mean().sort_values(ascending=False))
        top = ", ".join(f"station {st} {ch} ({math.sqrt(v):.1f} sigma rms)"
                        for (st, ch), v in worst.head(3).items())
        verdict = (("after " + ", ".join(a["effect"] for a in added) + ": " if added else "")
                   + f"unexplained: the residual stays above the noise floor (chi^2/dof = "
                   f"{rchi1:.2f}, p = {p_floor:.1e}); it lies mostly at {top}")
    elif added:
        verdict = "; ".join(f"{a['effect']}: " + ", ".join(
            f"{n} = {v:.4g} ± {s:.2g}" for n, v, s in zip(a["params"], a["size"], a["sigma"],
                                                        strict=False)) for a in added)
        verdict += f" (chi^2/dof {rchi0:.2f} -> {rchi1:.2f})"
    else:
        verdict = (f"no significant unmodelled effect (chi^2/dof = {rchi0:.2f}; best "
                   f"candidate {ranking.iloc[0]['candidate'] if ranking is not None else '-'}"
                   f", p = {ranking.iloc[0]['p_value'] if ranking is not None else 1:.2g})")
    return GapDiagnosis(ranking=ranking if ranking is not None else pd.DataFrame(),
                        added=tuple(added), rms_before=rms_before, rms_after=rms_after,
                        reduced_chi2_before=rchi0, reduced_chi2_after=rchi1,
                        unexplained=bool(unexplained), where=where, verdict=verdict)


__all__ = ["GapDiagnosis", "diagnose_gap", "score"]
