"""How the images formed their wires: the formation (blur before and after the pixel, fringe
width) and each wire's half-width, fitted from the wires' profiles (docs/stage1.md, "The wires'
image formation").

The formation belongs to the camera, film and scanner, not to one image: a shot's images of
one view are formed alike. So it is fitted once per view of a shot, jointly over a few of its
images (:func:`fit_formation` on their wires' profiles pooled, one half-width for each wire of
each image), and every image then fits only its own wires' half-widths with the formation held
(:func:`fit_widths`): a few Gauss-Newton passes over its profiles instead of a search over
starts. One image alone gives the formation too (:func:`fit_formation` on its wires), as it
does when a view has no shared one.

Whether the shared formation describes an image is a score test (:func:`fit_widths`): the
gradient of the image's residual sum of squares in the three formation parameters at the
shared values, in the image's own Fisher information, is chi^2 with 3 degrees of freedom when
it does. An image beyond :data:`SHARED_P` (a station whose camera or film differs) fits its own
formation, and says so.

The parameters are the two blurs' variances (smooth at 0, where a sigma's derivative
vanishes), the fringe width and the half-widths. A profile's residuals depend on its own wire's
half-width only, so the derivatives in all half-widths come from one perturbed evaluation
(:meth:`_Problem.jacobian`): a fit costs the same few passes whatever the number of wires.
All lengths in pixels.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from cadra.imaging.wires.profile import (
    CENTRE_ITERATIONS,
    CENTRE_TOL_PX,
    FRINGE_W_MIN,
    SENS_TOL_PX,
    SIGMA_MAX,
    Formation,
    WireProfiles,
    _fit,
    _linear_resid,
    _Rows,
)
from cadra.stats import chi2_p_value

__all__ = ["FORMATION_PROFILES", "SHARED_P", "fit_formation", "fit_widths"]

#: Profiles per wire used to fit the formation (evenly picked; all are used for the centres).
FORMATION_PROFILES = 30
#: Starting formations tried (sigma_c, sigma_d, fringe_w), before and after the pixel; the
#: best of each order is refined.
_STARTS = [(s, 0.0, 0.5) for s in (0.4, 0.7, 1.0, 1.5, 2.2)] + \
          [(0.0, s, 0.5) for s in (0.4, 0.7, 1.0, 1.5, 2.2)]
#: Levenberg-Marquardt rounds (each: centres at the current parameters, then one damped step
#: of the parameters with the centres held).
FORMATION_ROUNDS = 5
#: An image whose score test rejects the view's shared formation at this probability fits its
#: own (the shared values' own error, 1/k of one image's for k images pooled, is allowed for).
SHARED_P = 1e-3
#: Finite-difference steps of the parameters: in the fit, and for the covariance.
_STEP_FIT, _STEP_COV = 1e-4, 1e-3


class _Problem:
    """The profiles of some wires (one or several images), their residuals and derivatives
    in the parameters ``q = (sigma_c^2, sigma_d^2, fringe_w, h_1..h_m)``."""

    def __init__(self, wires: list[WireProfiles], per_wire: int = FORMATION_PROFILES):
        self.picks = [np.unique(np.linspace(0, len(w.P) - 1, min(per_wire, len(w.P)))
                                .astype(int)) for w in wires]
        self.wires = wires
        self.rows = _Rows.of(wires, self.picks)
        self.m = len(wires)
        self.scale = float(np.sum(self.rows.P) / max(np.sum(self.rows.m), 1.0))
        if not np.isfinite(self.scale) or self.scale <= 0:
            raise ValueError("wire profiles have no positive background")
        self.h0 = np.array([w.h for w in wires], float)
        self.lo = np.array([0.0, 0.0, FRINGE_W_MIN, *(0.5 * self.h0)])
        self.hi = np.array([SIGMA_MAX ** 2, SIGMA_MAX ** 2, SIGMA_MAX, *(2.0 * self.h0)])

    @staticmethod
    def form(q) -> Formation:
        return Formation(math.sqrt(q[0]), math.sqrt(q[1]), q[2])

    def centres(self, q, start=None, rows=None, tol=CENTRE_TOL_PX):
        """Every row's centre at ``q``, from the centroids or from ``start`` (converged
        centres of nearby parameters: a few steps each), to ``tol`` (px)."""
        rows = self.rows if rows is None else rows
        rs = rows if start is None else replace(rows, c0=start)
        return _fit(rs, q[3:][rows.wire], self.form(q), CENTRE_ITERATIONS, False, tol)[0]

    def resid(self, q, c, rows=None):
        rows = self.rows if rows is None else rows
        return _linear_resid(rows, c, q[3:][rows.wire], self.form(q)).ravel() / self.scale

    def cost(self, q, c) -> float:
        return float(np.sum(self.resid(q, c) ** 2))

    def _steps(self, q, step, cols):
        return {j: (step if q[j] + step <= self.hi[j] else -step) for j in cols}

    def jacobian(self, q, c, r0, step=_STEP_FIT, formation=True):
        """d resid / d q with the centres held (columns: the formation's three if
        ``formation``, then the half-widths; these from one evaluation, every wire's moved
        together: a row sees only its own wire's)."""
        n, k = self.rows.P.shape
        cols = []
        if formation:
            for j, d in self._steps(q, step, range(3)).items():
                dq = q.copy()
                dq[j] += d
                cols.append((self.resid(dq, c) - r0) / d)
        d = np.array(list(self._steps(q, step, range(3, 3 + self.m)).values()))
        dq = q.copy()
        dq[3:] += d
        diff = (self.resid(dq, c) - r0).reshape(n, k) / d[self.rows.wire][:, None]
        Jh = np.zeros((n, k, self.m))
        Jh[np.arange(n), :, self.rows.wire] = diff
        return np.column_stack([*cols, Jh.reshape(n * k, self.m)])

    def centre_sens(self, q, c, step=_STEP_COV) -> np.ndarray:
        """(m, 3 + m): each wire's mean centre shift per unit of each parameter."""
        S = np.zeros((self.m, 3 + self.m))
        wire = self.rows.wire
        c = self.centres(q, c, tol=SENS_TOL_PX)   # both sides of each difference alike
        for j, d in self._steps(q, step, range(3)).items():
            dq = q.copy()
            dq[j] += d
            dc = (self.centres(dq, c, tol=SENS_TOL_PX) - c) / d
            for w in range(self.m):
                S[w, j] = float(np.nanmean(dc[wire == w]))
        d = np.array(list(self._steps(q, step, range(3, 3 + self.m)).values()))
        dq = q.copy()
        dq[3:] += d
        dc = (self.centres(dq, c, tol=SENS_TOL_PX) - c) / d[wire]
        for w in range(self.m):
            S[w, 3 + w] = float(np.nanmean(dc[wire == w]))
        return S

    def dof(self, p: int) -> float:
        return max(float(np.sum(self.rows.m)) - 6.0 * len(self.rows.P) - p, 1.0)

    def refine(self, cost, q, c, formation=True):
        """Levenberg-Marquardt rounds from ``q`` (the formation held unless ``formation``)."""
        lam = 1e-3
        free = slice(0, None) if formation else slice(3, None)
        for _ in range(FORMATION_ROUNDS):
            r0 = self.resid(q, c)
            J = self.jacobian(q, c, r0, formation=formation)
            JtJ, Jtr = J.T @ J, J.T @ r0
            improved = False
            for _ in range(6):
                step = np.linalg.solve(JtJ + lam * np.diag(np.diag(JtJ) + 1e-12), -Jtr)
                qn = q.copy()
                qn[free] = np.clip(q[free] + step, self.lo[free], self.hi[free])
                cn_ = self.centres(qn, c)
                cn = self.cost(qn, cn_)
                if np.isfinite(cn) and cn <= cost:
                    gain = (cost - cn) / max(cost, 1e-300)
                    q, c, cost, lam = qn, cn_, cn, max(lam / 10.0, 1e-6)
                    improved = True
                    break
                lam *= 10.0
            if not improved or gain < 1e-4 or np.max(np.abs(step)) < 1e-4:
                break
        return cost, q, c


def _within_bounds(cov: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``cov`` with no parameter's variance beyond that of a uniform spread over its bounds
    ``(hi - lo)^2 / 12`` (its row and column scaled, correlations kept). A parameter the
    profiles do not determine (the fringe's width when the fringe is faint: a sigma of
    2e2 px was seen, for a width bounded to 0.05-4 px) otherwise carries a variance its
    bounds rule out, which the centres' sensitivities to it, mostly rounding, turned into a
    wire map sigma of millimetres."""
    cap = (np.asarray(hi, float) - np.asarray(lo, float)) ** 2 / 12.0
    var = np.diag(cov)
    f = np.where(var > cap, np.sqrt(cap / np.where(var > 0, var, 1.0)), 1.0)
    return cov * f[:, None] * f[None, :]


def fit_formation(wires: list[WireProfiles], per_wire: int = FORMATION_PROFILES
                  ) -> tuple[Formation, list[float]]:
    """The formation and each wire's half-width along its profiles, by least squares over up
    to ``per_wire`` profiles of each wire (the wires of one image, or of several images
    formed alike).

    The centres and the linear terms are profile-wise; the formation and half-widths are
    shared. They are fitted in alternation: every profile's centre at the current parameters,
    then one Levenberg-Marquardt step of ``(sigma_c, sigma_d, fringe_w, h_1..h_m)`` with the
    centres held (the centres are antisymmetric in the profile, the rest symmetric, so the
    two hardly couple). The start is the best of :data:`_STARTS` in each order (before or
    after the pixel), each refined; the better wins. The covariance is Gauss-Newton's with
    the residuals' own variance. Raises ``ValueError`` if the profiles give no fit.
    """
    pb = _Problem(wires, per_wire)
    with np.errstate(all="ignore"):
        best = {}
        sub = _Rows.of(wires, [p[::3] for p in pb.picks])   # the starts on a third of the rows
        for start in _STARTS:
            before = start[0] > 0.0
            q = np.array([start[0] ** 2, start[1] ** 2, start[2], *pb.h0])
            c = pb.centres(q, rows=sub)
            cost = float(np.sum(pb.resid(q, c, rows=sub) ** 2))
            if np.isfinite(cost) and (before not in best or cost < best[before][0]):
                best[before] = (cost, q)
        if not best:
            raise ValueError("no wire formation fits the profiles")
        # an order whose best start fits 1.2x worse than the other's is not refined
        low = min(b[0] for b in best.values())
        runs = []
        for cost_sub, q in best.values():
            if cost_sub <= 1.2 * low:
                c = pb.centres(q)
                runs.append(pb.refine(pb.cost(q, c), q, c))
        cost, q, _ = min(runs, key=lambda t: t[0])
        c = pb.centres(q)
        r0 = pb.resid(q, c)
        J = pb.jacobian(q, c, r0, _STEP_COV)
        cov = _within_bounds(np.linalg.pinv(J.T @ J) * (cost / pb.dof(len(q))), pb.lo, pb.hi)
        sens = pb.centre_sens(q, c)
    rms = math.sqrt(cost / max(float(np.sum(pb.rows.m)), 1.0))
    return (Formation(math.sqrt(q[0]), math.sqrt(q[1]), float(q[2]), rms, cov, sens),
            [float(v) for v in q[3:]])


def fit_widths(wires: list[WireProfiles], shared: Formation
               ) -> tuple[Formation, list[float], float, float]:
    """One image's wires' half-widths with the view's ``shared`` formation held.

    Parameters
    ----------
    wires : the image's wires' profiles.
    shared : the view's formation (:func:`fit_formation` over ``shared.n_images`` of its
        images; its covariance's first three rows and columns are the formation's).

    Returns
    -------
    formation : the shared values with this image's covariance of ``(sigma_c^2, sigma_d^2,
        fringe_w, h_1..h_m)`` (the shared block, then the half-widths') and centre
        sensitivities, flagged ``shared``.
    hs : the half-widths.
    score : the score statistic of the shared formation on this image (chi^2, 3 degrees of
        freedom, divided by ``1 + 1 / n_images`` for the shared values' own error).
    p : its upper tail probability: below :data:`SHARED_P` the shared formation does not
        describe this image.
    """
    pb = _Problem(wires)
    with np.errstate(all="ignore"):
        q = np.array([shared.sigma_c ** 2, shared.sigma_d ** 2, shared.fringe_w, *pb.h0])
        c = pb.centres(q)
        cost, q, _ = pb.refine(pb.cost(q, c), q, c, formation=False)
        c = pb.centres(q)
        r0 = pb.resid(q, c)
        J = pb.jacobian(q, c, r0, _STEP_COV)
        s2 = cost / pb.dof(3 + pb.m)
        F = J.T @ J
        g = J.T @ r0
        score = float(g @ np.linalg.pinv(F) @ g) / s2 / (1.0 + 1.0 / max(shared.n_images, 1))
        cov = np.zeros((3 + pb.m, 3 + pb.m))
        cov[:3, :3] = shared.cov[:3, :3]
        cov[3:, 3:] = _within_bounds(np.linalg.pinv(F[3:, 3:]) * s2, pb.lo[3:], pb.hi[3:])
        sens = pb.centre_sens(q, c)
    rms = math.sqrt(cost / max(float(np.sum(pb.rows.m)), 1.0))
    p = chi2_p_value(score, 3) if np.isfinite(score) else 0.0
    return (Formation(shared.sigma_c, shared.sigma_d, shared.fringe_w, rms, cov, sens,
                      shared=True, n_images=shared.n_images), [float(v) for v in q[3:]],
            score, p)
