"""Scoring a gap diagnosis against the injected truth.

The statistics of the gap validation, apart from the loop that makes and diagnoses the
cases: the shrink ratio a perfect diagnosis would reach (from the two fits' linearizations),
the rate and tail probability of exceeding the limit, the chi^2 change expected of a correct
model, the fits from the truth, and whether an added effect's size (a body pair by its
magnitude, or a vector with the refit's covariance) lies within 2 sigma of the truth. Pure
functions over the trial rows and the diagnosis's tables.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy import stats

__all__ = ["SHRINK_DRAWS", "SHRINK_LIMIT", "body_truth_in_fit_frame", "dchi2_expected",
           "exceed_expected", "exceed_observed", "exceed_pvalue", "fit_from_truth",
           "effect_size_ok", "linear_shrink", "magnitude_within_2sigma", "pooled_shrink",
           "size_within_2sigma"]

#: the shrink criterion (rms per channel after / clean within 10 %), and the noise
#: vectors drawn to estimate how often a perfect diagnosis fails it (``linear_shrink``)
SHRINK_LIMIT = 1.10
SHRINK_DRAWS = 4000


def linear_shrink(clean, after, noise: dict, rng, draws: int = SHRINK_DRAWS,
                  limit: float = SHRINK_LIMIT):
    """The shrink ratio as the two fits' linearizations give it: a correct model's residual
    is the noise less its projection on the fit's Jacobian, r = (I - J (J^T J)^+ J^T) e (in
    sigmas). With the noise drawn (``noise``: (shot, station, channel) -> e) this predicts
    the trial's ratio (max over channels of rms after / rms clean); with ``draws`` other
    noise vectors it gives the probability that the ratio exceeds ``limit`` when the effect
    added is exactly the one injected: the rate at which a perfect diagnosis fails the
    10 % criterion on this shot. The same for chi^2 after - chi^2 clean (whose mean
    is minus the effect's parameter count; its scatter grows with the difference of the two
    Jacobians). Returns a dict: ``ratio`` (predicted), ``prob``, ``dchi2`` (predicted),
    ``dchi2_mean`` and ``dchi2_var`` over the draws; or None if either fit has no
    Jacobian."""
    if clean.jacobian is None or after.jacobian is None:
        return None
    rc, ra = clean.residuals, after.residuals
    keys = list(zip(rc["shot_id"], rc["station"].astype(int), rc["channel"], strict=True))
    pos = {k: i for i, k in enumerate(zip(ra["shot_id"], ra["station"].astype(int),
                                          ra["channel"], strict=True))}
    Ja = after.jacobian[[pos[k] for k in keys]]
    E = np.column_stack([[noise[k] for k in keys],
                         rng.standard_normal((len(keys), draws))])

    def resid(fit, J):
        return E - J @ (fit.covariance @ (J.T @ E))

    Rc, Ra = resid(clean, clean.jacobian) ** 2, resid(after, Ja) ** 2     # (r / sigma)^2
    dchi2 = Ra.sum(axis=0) - Rc.sum(axis=0)
    w2 = rc["sigma"].to_numpy(float)[:, None] ** 2
    chan = rc["channel"].to_numpy()
    ratio = np.max([np.sqrt((w2 * Ra)[chan == c].sum(axis=0) / (w2 * Rc)[chan == c].sum(axis=0))
                    for c in np.unique(chan)], axis=0)
    return {"ratio": float(ratio[0]), "prob": float(np.mean(ratio[1:] > limit)),
            "dchi2": float(dchi2[0]), "dchi2_mean": float(np.mean(dchi2[1:])),
            "dchi2_var": float(np.var(dchi2[1:], ddof=1))}


def exceed_observed(rows) -> float:
    """Fraction of the trials (effect ranked first) whose shrink ratio exceeds
    SHRINK_LIMIT."""
    r = [x["shrink_ratio"] > SHRINK_LIMIT for x in rows if math.isfinite(x["shrink_ratio"])]
    return float(np.mean(r)) if r else math.nan


def exceed_expected(rows) -> float:
    """The same fraction expected of a perfect diagnosis: the mean over the trials of
    ``linear_shrink``'s probability."""
    r = [x["shrink_exceed_prob"] for x in rows if "shrink_exceed_prob" in x]
    return float(np.mean(r)) if r else math.nan


def dchi2_expected(rows) -> list[float]:
    """chi^2 after - chi^2 clean, mean over the trials, as a perfect diagnosis gives it
    (``linear_shrink``'s draws): [mean, sigma of that mean]."""
    lin = [x["dchi2_linear"] for x in rows if "dchi2_linear" in x]
    return [float(np.mean([d[1] for d in lin])),
            float(math.sqrt(sum(d[2] for d in lin)) / len(lin))]


def exceed_pvalue(rows) -> float:
    """P(at least the observed number of trials above SHRINK_LIMIT) for a perfect diagnosis:
    the trials' counts are independent with the probabilities of ``linear_shrink`` (a
    Poisson-binomial tail). Small: the diagnosis exceeds the limit more often than the noise
    explains."""
    rows = [x for x in rows if "shrink_exceed_prob" in x and math.isfinite(x["shrink_ratio"])]
    if not rows:
        return math.nan
    k = sum(x["shrink_ratio"] > SHRINK_LIMIT for x in rows)
    dist = np.array([1.0])
    for x in rows:
        q = x["shrink_exceed_prob"]
        dist = np.append(dist * (1 - q), 0.0) + np.insert(dist * q, 0, 0.0)
    return float(dist[k:].sum())


def pooled_shrink(rows) -> float:
    """Per channel, sqrt(sum of rms_after^2 / sum of rms_clean^2) over the trials whose
    effect ranked first; the largest over the channels (NaN if none)."""
    pairs = [r["rms_pairs"] for r in rows if r.get("rms_pairs")]
    if not pairs:
        return math.nan
    return float(max(math.sqrt(sum(p[c][0] ** 2 for p in pairs if c in p)
                               / sum(p[c][1] ** 2 for p in pairs if c in p))
                     for c in {c for p in pairs for c in p}))


def fit_from_truth(fa, shots, true_model, truth):
    """``fa``'s model and extras fitted to ``shots`` from the truth: aero values from
    ``true_model`` (a term it lacks at 0), extras at their ``truth`` sizes (0 if absent), the
    states where ``fa`` has them; None if the fit fails."""
    from cadra.fitting import FitOptions
    from cadra.gap.score import refit_with

    names = set(true_model.names)
    m = fa.model.with_values({n: true_model.parameter(n).value if n in names else 0.0
                              for n in fa.model.names
                              if n in names or n.startswith("gap_")})
    at_truth = replace(fa, model=m, extra_values=np.array(
        [float(truth.get(e.name, 0.0)) for e in fa.extras]))
    return refit_with(at_truth, shots, [], FitOptions())


def body_truth_in_fit_frame(case: str, truth: dict, sim, t0_s: float, q_fit) -> dict:
    """``truth`` (a body effect's sizes in the simulator's body frame) in the fit's body frame.

    The two frames differ by the rotation R = A_truth(t0)^T A_fit(t0) (A: body to facility,
    from the quaternions, scalar first; the truth's interpolated to the fit's reference time
    ``t0_s`` along the simulated stations), a roll about the axis up to the fit's attitude
    error. A cg offset c turns as R^T c; an inertia change dI as R^T dI R."""
    from scipy.spatial.transform import Rotation, Slerp

    def rot(q):
        q = np.asarray(q, dtype=float)
        return Rotation.from_quat(np.concatenate([q[..., 1:], q[..., :1]], axis=-1))

    a_truth = Slerp(np.asarray(sim.times_s), rot(np.asarray(sim.states)[:, 6:10]))([t0_s])[0]
    R = (a_truth.inv() * rot(q_fit)).as_matrix()
    out = dict(truth)
    for key in truth:
        name, _, shot = key.partition("@")
        at = "@" + shot if shot else ""
        if case == "cg" and name == "cg_offset_y_m":
            c = R.T @ np.array([0.0, truth[key], truth["cg_offset_z_m" + at]])
            out[key], out["cg_offset_z_m" + at] = float(c[1]), float(c[2])
        elif case == "inertia_asym" and name == "Iyy_minus_Izz_kg_m2":
            a, b = truth[key], truth["Iyz_kg_m2" + at]
            dI = R.T @ np.array([[0, 0, 0], [0, a / 2, b], [0, b, -a / 2]]) @ R
            out[key], out["Iyz_kg_m2" + at] = float(dI[1, 1] - dI[2, 2]), float(dI[1, 2])
        elif case == "products" and name == "Ixy_kg_m2":
            c, d = truth[key], truth["Ixz_kg_m2" + at]
            dI = R.T @ np.array([[0, c, d], [c, 0, 0], [d, 0, 0]]) @ R
            out[key], out["Ixz_kg_m2" + at] = float(dI[0, 1]), float(dI[0, 2])
    return out


def _group_cov(added: dict, ii) -> np.ndarray:
    """The refit's covariance of the parameters ``ii`` of an added effect (its sigmas alone,
    correlations unknown, where it has none)."""
    cov = added.get("covariance")
    if cov is not None:
        return np.asarray(cov, dtype=float)[np.ix_(ii, ii)]
    return np.diag([added["sigma"][i] ** 2 for i in ii])


def magnitude_within_2sigma(added: dict, truth: dict, groups) -> bool:
    """Is each body pair's *magnitude* (its size across the axis: the cg offset, the
    principal inertia difference sqrt((Iyy - Izz)^2 + 4 Iyz^2), the products' resultant)
    within two sigma of the truth's? Tested by the linearized profile likelihood of the
    magnitude: the smallest (v - t(phi))^T C^-1 (v - t(phi)) over the orientations phi of a
    pair of the truth's magnitude, within 4 (one parameter, two sigma); C the refit's
    covariance (the sigmas alone without one). No frame is needed, and a pair the data see in
    one combination only (its other direction free) is not held to a sigma it does not have.
    A zero truth is a point: the vector test of ``size_within_2sigma``."""
    params = list(added["params"])
    phi = np.linspace(0.0, 2.0 * math.pi, 7200, endpoint=False)
    for group in groups:
        ii = [params.index(p) for p in group]
        v = np.array([added["size"][i] for i in ii])
        w = np.array([2.0 if p.startswith("Iyz") else 1.0 for p in group])
        t = float(np.linalg.norm(w * np.array([truth.get(p, 0.0) for p in group])))
        if t == 0.0:
            if not size_within_2sigma(added, truth, [group]):
                return False
            continue
        T = t * np.stack([np.cos(phi), np.sin(phi)], axis=1) / w      # (n, 2) candidates
        D = v - T
        Ci = np.linalg.pinv(_group_cov(added, ii))
        if float(np.min(np.einsum("ni,ij,nj->n", D, Ci, D))) > 4.0:
            return False
    return True


def effect_size_ok(added: dict, truth: dict, groups=None) -> bool:
    """The size score of an added effect. A body pair (``groups``) by its magnitude
    (:func:`magnitude_within_2sigma`, frame-free); any other effect of k > 1 parameters (a
    cross-flow's two winds, a cg offset per shot of a set) as one vector with the refit's
    covariance against the chi-square quantile of two sigma for k (:func:`size_within_2sigma`):
    a perfect diagnosis passes that 95.45 % of the time whatever k and the correlations,
    where "every parameter within 2 sigma" passes 0.9545^k or less. One parameter: within its
    2 sigma (or its profile interval)."""
    if groups is not None:
        return magnitude_within_2sigma(added, truth, groups)
    params = tuple(added["params"])
    return size_within_2sigma(added, truth, [params] if len(params) > 1 else None)


def size_within_2sigma(added: dict, truth: dict, groups=None) -> bool:
    """Is every parameter of an added effect within two sigma of its truth? Where the
    diagnosis gave a profile-likelihood interval (``interval_2sigma``), within that interval.
    ``groups``: tuples of parameters compared as vectors instead (a body effect's pair,
    ``BODY_PAIRS``, with ``truth`` in the fit's frame): (v - t)^T C^-1 (v - t) within the
    chi-square quantile of two sigma (95.45 %) for the group's size, C the refit's
    covariance of the group (``covariance``; the sigmas alone if it has none). A pair whose
    two components the data tell apart only in one combination (a body swinging in one plane
    sees the inertia about its swing axis: correlations of 0.99999) has no honest sigma per
    component or of its magnitude; as a vector with its covariance it has."""
    ivs = added.get("interval_2sigma") or [None] * len(added["params"])
    params = list(added["params"])
    est = {p: (v, s, iv) for p, v, s, iv in zip(params, added["size"], added["sigma"], ivs,
                                                  strict=True)}
    if groups is None:
        for p, (v, s, iv) in est.items():
            t = truth.get(p, 0.0)
            if not (iv[0] <= t <= iv[1] if iv is not None else abs(v - t) <= 2 * s):
                return False
        return True
    for group in groups:
        ii = [params.index(p) for p in group]
        d = np.array([est[p][0] - truth.get(p, 0.0) for p in group])
        if not float(d @ np.linalg.pinv(_group_cov(added, ii)) @ d) <= stats.chi2.ppf(
                stats.chi2.cdf(4.0, 1), len(group)):
            return False
    return True
