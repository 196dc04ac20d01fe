"""Plots of a stage-two fit: coefficients, angle histories, residuals, a 3-D view.

Every function takes the fit result (and the :class:`cadra.flight.data.ShotData` it used),
draws on a given figure (``fig=``) or a new one, and returns the figure; none shows anything.
matplotlib is imported lazily and used through :class:`matplotlib.figure.Figure` (Agg canvas,
no pyplot state), so headless use never loads a GUI stack. The 3-D view is rendered
off-screen by pyvista/VTK (:func:`render_trajectory_3d`); where VTK cannot render it raises
:class:`RenderingUnavailable` and :func:`trajectory_3d_matplotlib` draws a simpler view.

Angles are classical (docs/conventions.md): alpha = 0 with the nose (a capsule's heat shield)
into the wind; the CEV angle of attack is 180 deg - alpha and is shown as a second axis.
"""

from __future__ import annotations

import functools
import math
import os
import subprocess
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from cadra.aero.program import COEFFICIENTS
from cadra.channels import BY_NAME, POSITION, wrap_angle
from cadra.fitting.histories import fitted_histories
from cadra.fitting.result import FitResult
from cadra.flight.data import CHANNELS, ShotData
from cadra.report import figures

#: display names of the coefficients (mathtext)
COEFFICIENT_LABELS = {"CD": "$C_D$", "CL": "$C_L$", "CC": "$C_C$", "Cl": "$C_l$",
                      "Cm": "$C_m$", "Cn": "$C_n$", "Clp": "$C_{l_p}$", "Cmq": "$C_{m_q}$",
                      "Cnr": "$C_{n_r}$"}
_CHANNEL_LABELS = {name: c.label for name, c in BY_NAME.items()}
_EPS = 1e-20   # complex step


class RenderingUnavailable(RuntimeError):
    """VTK cannot render off-screen here (no EGL/OSMesa/X display); the message says why and
    what would be needed."""


# --------------------------------------------------------------------------- helpers


def _new_figure(fig, figsize):
    """``fig`` cleared for reuse, or a new figure of the one style."""
    if fig is not None:
        fig.clear()
        return fig
    return figures.new_figure(figsize)


def _histories(result, shots, histories):
    if histories is not None:
        return histories
    return fitted_histories(result, shots)


def _shot_map(shots: Sequence[ShotData]) -> dict[str, ShotData]:
    return {s.shot_id: s for s in shots}


def _title(result: FitResult, what: str, title: str | None = None) -> str:
    ids = ", ".join(s.shot_id for s in result.shots)
    if len(ids) > 60:
        ids = f"{len(result.shots)} shots"
    head = title or f"{result.model.name} ({ids})"
    tail = "" if result.converged else f"  [{result.status.upper()}: NOT A RESULT]"
    return f"{head}: {what}{tail}"


def coefficient_curves(model, free_names: Sequence[str], covariance: np.ndarray,
                       alpha, beta, sigma, mach) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each coefficient of ``model`` and its 1-sigma along a path of flight conditions.

    The sigma propagates ``covariance`` (of the parameters ``free_names``, SI) through the
    exact derivatives of the coefficients with respect to those parameters (complex step of
    :meth:`cadra.aero.AeroModel.evaluate`). Rates are zero: damping coefficients are the
    coefficient values themselves.

    Returns ``{coefficient: (value, sigma)}`` for the coefficients the model defines.
    """
    p0 = model.values()
    base = model.evaluate(alpha, beta, sigma, mach)
    idx = [model.index(n) for n in free_names]
    J = {c: np.zeros((len(idx),) + np.shape(base[c])) for c in model.coefficients}
    for row, i in enumerate(idx):
        pc = p0.astype(np.complex128)
        pc[i] += 1j * _EPS
        out = model.evaluate(alpha, beta, sigma, mach, params=pc)
        for c in model.coefficients:
            J[c][row] = np.imag(out[c]) / _EPS
    C = np.asarray(covariance, dtype=float)
    res = {}
    for c in model.coefficients:
        if len(idx) and np.all(np.isfinite(C)):
            var = np.einsum("i...,ij,j...->...", J[c], C, J[c])
            s = np.sqrt(np.maximum(var, 0.0))
        else:
            s = np.full(np.shape(base[c]), np.nan)
        res[c] = (np.real(np.asarray(base[c], dtype=float)), s)
    return res


def _varies(v: np.ndarray) -> bool:
    v = np.asarray(v, dtype=float)
    return bool(np.ptp(v) > 1e-12 * (1.0 + np.max(np.abs(v))))


# --------------------------------------------------------------------------- coefficients


def plot_coefficients(result: FitResult, shots: Sequence[ShotData], *, fig=None,
                      histories: Mapping[str, pd.DataFrame] | None = None,
                      reference_model=None, reference_label: str = "reference",
                      n_points: int = 200):
    """The fitted coefficients over the range of angles the flights cover (seed 004 Figs. 9-14).

    ``alpha_beta`` models: every coefficient that varies with alpha is drawn vs the classical
    alpha (deg; CEV alpha = 180 - alpha on the top axis) at beta = 0; those that depend on
    beta only (C_C, C_n) vs beta at the flights' mean alpha. ``sigma`` models: vs the total
    angle sigma. Mach is the flights' mean. The band is +-1 sigma from the covariance of the
    free aerodynamic parameters; ticks along the bottom mark the fitted angles at the
    stations. ``reference_model`` (e.g. the truth of a synthetic shot) is drawn dashed.

    Returns the matplotlib figure.
    """
    model = result.model
    hist = _histories(result, shots, histories)
    allh = pd.concat(list(hist.values()), ignore_index=True)
    sm = _shot_map(shots)
    stations = []
    for sid, h in hist.items():
        t = sm[sid].t_s
        stations.append(pd.DataFrame({c: np.interp(t, h["t_s"], h[c])
                                      for c in ("alpha_deg", "beta_deg", "sigma_deg")}))
    st = pd.concat(stations, ignore_index=True)
    mach = float(allh["mach"].mean())
    coefs = [c for c in COEFFICIENTS if c in model.coefficients]
    na = len(result.aero_names)
    cov = result.covariance[:na, :na]
    n = max(len(coefs), 1)
    ncols = 3 if n > 4 else 2
    nrows = math.ceil(n / ncols)
    fig = _new_figure(fig, (5.2 * ncols, 3.6 * nrows))
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False)).ravel()
    for ax in axes[len(coefs):]:
        ax.set_visible(False)

    def pad(lo, hi, minimum):
        mid, half = 0.5 * (lo + hi), max(0.5 * (hi - lo), 0.5 * minimum)
        return mid - 1.05 * half, mid + 1.05 * half

    if model.angle_plane == "sigma":
        lo, hi = pad(allh["sigma_deg"].min(), allh["sigma_deg"].max(), 1.0)
        s_deg = np.linspace(max(lo, 0.0), hi, n_points)
        s = np.radians(s_deg)
        paths = {"sigma": (s_deg, s, np.zeros_like(s), s, st["sigma_deg"].to_numpy(),
                           "σ, total angle of attack (deg)")}
        which = {c: "sigma" for c in coefs}
    else:
        lo, hi = pad(allh["alpha_deg"].min(), allh["alpha_deg"].max(), 1.0)
        a_deg = np.linspace(lo, hi, n_points)
        a = np.radians(a_deg)
        blo, bhi = pad(allh["beta_deg"].min(), allh["beta_deg"].max(), 1.0)
        b_deg = np.linspace(blo, bhi, n_points)
        b = np.radians(b_deg)
        a_mean = np.full_like(b, math.radians(float(allh["alpha_deg"].mean())))
        paths = {"alpha": (a_deg, a, np.zeros_like(a), None, st["alpha_deg"].to_numpy(),
                           "α, classical angle of attack (deg)"),
                 "beta": (b_deg, a_mean, b, None, st["beta_deg"].to_numpy(),
                          f"β, sideslip (deg) at α = {np.degrees(a_mean[0]):.1f}°")}
        on_alpha = model.evaluate(a, np.zeros_like(a), None, mach)
        on_beta = model.evaluate(a_mean, b, None, mach)
        which = {c: ("beta" if not _varies(on_alpha[c]) and _varies(on_beta[c]) else "alpha")
                 for c in coefs}
    curves = {}
    ref_curves = {}
    for key, (_, aa, bb, ss, _, _) in paths.items():
        curves[key] = coefficient_curves(model, result.aero_names, cov, aa, bb, ss, mach)
        if reference_model is not None:
            ref_curves[key] = reference_model.evaluate(aa, bb, ss, mach)
    for ax, c in zip(axes, coefs, strict=False):
        key = which[c]
        xdeg, _, _, _, xst, xlabel = paths[key]
        v, s = curves[key][c]
        if np.any(np.isfinite(s)):
            ax.fill_between(xdeg, v - s, v + s, color="C0", alpha=0.25, lw=0,
                            label="±1σ")
        ax.plot(xdeg, v, "-", color="C0", lw=1.8, label="fitted")
        if reference_model is not None and c in reference_model.coefficients:
            ax.plot(xdeg, np.real(ref_curves[key][c]), "--", color="C3", lw=1.2,
                    label=reference_label)
        ax.plot(xst, np.full(len(xst), 0.03), "|", color="k", ms=9, alpha=0.7,
                transform=ax.get_xaxis_transform(), label="stations")
        params = [p for p in model.parameters_in(c) if p in result.aero_names]
        ax.set_title(f"{COEFFICIENT_LABELS.get(c, c)}"
                     + (f"   (free: {', '.join(params)})" if params else "   (all held)"),
                     fontsize=9)
        ax.set_xlabel(xlabel, fontsize=9)
        ax.set_ylabel(COEFFICIENT_LABELS.get(c, c))
        ax.grid(alpha=0.3)
        if key == "alpha":
            sec = ax.secondary_xaxis("top", functions=(lambda x: 180.0 - x,
                                                       lambda x: 180.0 - x))
            sec.set_xlabel("CEV α = 180° − α (deg)", fontsize=8)
            sec.tick_params(labelsize=8)
    if coefs:
        axes[0].legend(fontsize=8, loc="best")
    fig.suptitle(_title(result, f"fitted coefficients at M = {mach:.3f} (flights' mean)"
                        + (", β = 0" if model.angle_plane == "alpha_beta" else "")
                        + "; band ±1σ"), fontsize=11)
    return fig


# --------------------------------------------------------------------------- angle histories


def plot_angle_histories(result: FitResult, shots: Sequence[ShotData], *, fig=None,
                         histories: Mapping[str, pd.DataFrame] | None = None):
    """Measured (points, 1-sigma bars) and fitted (line) theta and psi vs distance x for each
    shot, with the fitted angle of attack (alpha for ``alpha_beta`` models, the total angle
    sigma otherwise) vs x (seed 004 Fig. 11 style). One row per shot. A shot without measured
    angles (a sphere) shows z, y (mm) and the Mach number instead. Returns the figure."""
    hist = _histories(result, shots, histories)
    sm = _shot_map(shots)
    ids = [sf.shot_id for sf in result.shots]
    nrows = len(ids)
    roll = any(sm[sid].has_roll for sid in ids)      # a finned body: a fourth panel, φ
    fig = _new_figure(fig, (20 if roll else 15, 3.0 * nrows + 0.6))
    axes = fig.subplots(nrows, 4 if roll else 3, squeeze=False, sharex="row")
    third = ("sigma_deg", "σ, total angle (deg)") if result.model.angle_plane == "sigma" \
        else ("alpha_deg", "α, classical (deg)")
    deg = 180.0 / math.pi
    for r, sid in enumerate(ids):
        h, sd = hist[sid], sm[sid]
        xm = sd.meas[:, 0]
        x_st = np.where(np.isfinite(xm), xm, np.interp(sd.t_s, h["t_s"], h["x_m"]))
        if sd.has_angles:
            panels = (("theta_deg", CHANNELS.index("theta"), deg, "θ (deg, + nose up)"),
                      ("psi_deg", CHANNELS.index("psi"), deg, "ψ (deg, + nose to port)"))
        else:   # no attitude measured (a sphere): the lateral positions instead
            panels = (("z_m", CHANNELS.index("z"), 1e3, "z (mm, + up)"),
                      ("y_m", CHANNELS.index("y"), 1e3, "y (mm, + port)"))
        for c, (col, j, f, label) in enumerate(panels):
            ax = axes[r, c]
            hf = 1e3 if col.endswith("_m") else 1.0
            ax.plot(h["x_m"], h[col] * hf, "-", color="C0", lw=1.3, label="fitted")
            ok = np.isfinite(sd.meas[:, j])
            if ok.any():
                ax.errorbar(x_st[ok], sd.meas[ok, j] * f, yerr=sd.sigma[ok, j] * f,
                            fmt="o", ms=4, color="k", ecolor="C3", capsize=2,
                            label="measured (±1σ)")
            ax.set_ylabel(label)
            ax.set_title(f"{sid}: {label.split(' ')[0]}"
                         + ("" if sd.has_angles else " (no angles measured)"), fontsize=9)
            ax.grid(alpha=0.3)
        ax = axes[r, 2]
        col, label = third if sd.has_angles else ("mach", "Mach number")
        ax.plot(h["x_m"], h[col], "-", color="C2", lw=1.3, label="fitted")
        ax.plot(x_st, np.interp(sd.t_s, h["t_s"], h[col]), "o", ms=3.5, color="C2",
                label="at the stations")
        ax.set_ylabel(label)
        ax.set_title(f"{sid}: fitted {label.split(',')[0]}", fontsize=9)
        if col == "mach":
            ax.ticklabel_format(axis="y", useOffset=False)
        ax.grid(alpha=0.3)
        if col == "alpha_deg":
            sec = ax.secondary_yaxis("right", functions=(lambda x: 180.0 - x,
                                                         lambda x: 180.0 - x))
            sec.set_ylabel("CEV α (deg)", fontsize=8)
        if r == 0:
            axes[r, 0].legend(fontsize=8, loc="best")
            ax.legend(fontsize=8, loc="best")
        if roll:
            _roll_panel(axes[r, 3], sid, sd, h, x_st)
    for ax in axes[-1]:
        ax.set_xlabel("x (m, downrange)")
    fig.suptitle(_title(result, "measured and fitted angles vs distance"), fontsize=11)
    return fig


def _roll_panel(ax, sid: str, sd: ShotData, h: pd.DataFrame, x_st: np.ndarray) -> None:
    """The roll φ (deg) measured and fitted vs x: the fitted history unwrapped along the
    shot, each measurement moved by whole turns to the fitted branch (the channel is
    periodic: channels.residual)."""
    j = CHANNELS.index("phi")
    fitted = np.unwrap(np.radians(h["phi_deg"].to_numpy(float)))
    ax.plot(h["x_m"], np.degrees(fitted), "-", color="C0", lw=1.3, label="fitted")
    ok = np.isfinite(sd.meas[:, j])
    if ok.any():
        at = np.interp(sd.t_s[ok], h["t_s"], fitted)
        m = at + wrap_angle(sd.meas[ok, j] - at)
        ax.errorbar(x_st[ok], np.degrees(m), yerr=np.degrees(sd.sigma[ok, j]), fmt="o",
                    ms=4, color="k", ecolor="C3", capsize=2, label="measured (±1σ)")
    ax.set_ylabel("φ (deg, roll about the nose axis)")
    ax.set_title(f"{sid}: φ" + ("" if ok.any() else " (not measured)"), fontsize=9)
    ax.grid(alpha=0.3)


# --------------------------------------------------------------------------- residuals


def plot_residuals(result: FitResult, *, fig=None):
    """Normalized residuals (residual / sigma) per channel vs station, one marker colour per
    shot, with +-1 and +-3 lines; each panel's title gives the channel's rms (µm or deg).
    Returns the figure."""
    r = result.residuals
    chans = [c for c in CHANNELS if len(r) and (r["channel"] == c).any()]
    fig = _new_figure(fig, (11, 1.9 * max(len(chans), 1) + 0.8))
    if not chans:
        ax = fig.subplots()
        ax.text(0.5, 0.5, "no residuals", ha="center", va="center")
        return fig
    axes = fig.subplots(len(chans), 1, squeeze=False, sharex=True)[:, 0]
    ids = [sf.shot_id for sf in result.shots]
    nshots = len(ids)
    rms = result.rms()
    markers = "osD^v<>ph*"
    for ax, ch in zip(axes, chans, strict=True):
        for k, sid in enumerate(ids):
            sel = r[(r["channel"] == ch) & (r["shot_id"] == sid)].sort_values("station")
            dx = (k - (nshots - 1) / 2) * min(0.08, 0.6 / max(nshots, 1))
            ax.plot(sel["station"] + dx, sel["normalized"], marker=markers[k % len(markers)],
                    ms=4, lw=0.6, color=f"C{k % 10}", label=sid)
        for y, ls in ((0, "-"), (1, "--"), (-1, "--"), (3, ":"), (-3, ":")):
            ax.axhline(y, color="0.5", lw=0.8, ls=ls)
        v = rms[ch]
        unit = (f"{v * 1e6:.3g} µm" if BY_NAME[ch].kind == "position"
                else f"{math.degrees(v):.3g} deg")
        sel = r[r["channel"] == ch]["normalized"]
        ax.set_title(f"{_CHANNEL_LABELS[ch]}: rms {unit}, normalized rms "
                     f"{np.sqrt(np.mean(sel**2)):.2f}", fontsize=9, loc="left")
        ax.set_ylabel(f"{_CHANNEL_LABELS[ch]} residual / σ")
        lim = max(3.5, 1.1 * float(np.nanmax(np.abs(sel))) if len(sel) else 3.5)
        ax.set_ylim(-lim, lim)
        ax.grid(alpha=0.3)
    from matplotlib.ticker import MaxNLocator

    axes[-1].xaxis.set_major_locator(MaxNLocator(integer=True))
    axes[-1].set_xlabel("station")
    if nshots > 1:
        axes[0].legend(fontsize=7, ncol=min(nshots, 7), loc="upper right")
    fig.suptitle(_title(result, "normalized residuals (measured − fitted) / σ"), fontsize=11)
    return fig


# --------------------------------------------------------------------------- bodies


def resolve_body(shot: ShotData, bodies: Mapping | None = None):
    """The body of ``shot`` and whether it is only a generic stand-in.

    Order: ``bodies[shot.shot_id]``; the body of the shot file named in
    ``shot.source["shot_file"]``; else a generic body of ``shot.body_kind`` with the shot's
    reference length (sphere; M2-preset capsule; 10-degree cone).
    """
    from cadra.body import body_from_spec, capsule, cone, sphere

    if bodies and shot.shot_id in bodies:
        return bodies[shot.shot_id], False
    path = (shot.source or {}).get("shot_file")
    if path and Path(path).exists():
        from cadra.io.shotfile import load_shot

        return body_from_spec(load_shot(path).model), False
    d = shot.rigid.d_m
    if shot.body_kind == "sphere":
        return sphere(d), True
    if shot.body_kind == "cone":
        return cone(d, math.radians(10.0)), True
    return capsule("M2", d_m=d), True


def body_surface(body, n_axial: int = 90, n_around: int = 48):
    """(n_axial, n_around + 1, 3) surface-of-revolution grid of ``body``: body axes (x nose,
    y starboard, z down) from its reference point, m; the last azimuth repeats the first.
    A finned body (:class:`cadra.body.FinnedBody`) is drawn as its body of revolution: its
    fins (a few pixels at the 3-D view's model scale) are not drawn."""
    from cadra.body import meridian

    revolution = getattr(body, "body", body)     # a finned body's cone-cylinder
    s, r = meridian(revolution.arcs, int(n_axial))
    phi = np.linspace(0.0, 2.0 * np.pi, int(n_around) + 1)
    P = np.empty((len(s), len(phi), 3))
    P[..., 0] = s[:, None]
    P[..., 1] = r[:, None] * np.cos(phi)[None, :]
    P[..., 2] = r[:, None] * np.sin(phi)[None, :]
    return P


def _nice(x: float) -> float:
    """The number of the form 1, 2 or 5 x 10^k nearest to ``x`` in ratio (at least 1)."""
    if not (x > 1.0 and math.isfinite(x)):
        return 1.0
    e = math.floor(math.log10(x))
    cands = [m * 10.0**k for k in (e, e + 1) for m in (1.0, 2.0, 5.0)]
    return min(cands, key=lambda c: abs(math.log(c / x)))


def _scene(result, shots, bodies, histories, lateral_scale, model_scale):
    """Displayed geometry shared by the pyvista and matplotlib 3-D views."""
    from cadra.conventions import body_to_facility_matrix

    hist = _histories(result, shots, histories)
    sm = _shot_map(shots)
    ids = [sf.shot_id for sf in result.shots]
    xspan = max(float(np.ptp(hist[i]["x_m"])) for i in ids)
    lat = max(max(float(np.ptp(hist[i]["y_m"])), float(np.ptp(hist[i]["z_m"]))) for i in ids)
    k = lateral_scale or min(_nice(0.08 * xspan / max(lat, 1e-9)), 1000.0)
    resolved = {i: resolve_body(sm[i], bodies) for i in ids}
    spacing = min(float(np.median(np.diff(np.sort(sm[i].t_s)))) * float(np.mean(
        np.linalg.norm(result.shots[j].state[3:6]))) for j, i in enumerate(ids))
    length = max(resolved[i][0].length_m for i in ids)
    m = model_scale or _nice(0.45 * spacing / length)
    # several shots are stacked vertically (the view is from the side)
    zspan = max(float(np.ptp(hist[i]["z_m"])) for i in ids)
    offset_step = 1.25 * k * zspan + 2.5 * m * max(resolved[i][0].diameter_m for i in ids)
    shots_out = []
    for j, sid in enumerate(ids):
        h, sd = hist[sid], sm[sid]
        body, generic = resolved[sid]
        zoff = -j * offset_step
        path = np.stack([h["x_m"], k * h["y_m"], k * h["z_m"] + zoff], axis=1)
        grid = body_surface(body)
        ts = sd.t_s
        st_states = np.stack([np.interp(ts, h["t_s"], h[f"state_{q}"]) for q in range(13)],
                             axis=1)
        ref = np.stack([np.interp(ts, h["t_s"], h[c]) for c in ("x_m", "y_m", "z_m")], axis=1)
        meshes = []
        for i in range(len(ts)):
            R = body_to_facility_matrix(st_states[i, 6:10])
            P = (grid @ R.T) * m
            P[..., 0] += ref[i, 0]
            P[..., 1] += k * ref[i, 1]
            P[..., 2] += k * ref[i, 2] + zoff
            meshes.append(P)
        meas = sd.meas[:, POSITION]
        ok = np.all(np.isfinite(meas), axis=1)
        measured = np.stack([meas[ok, 0], k * meas[ok, 1], k * meas[ok, 2] + zoff], axis=1)
        label_pts = np.stack([ref[:, 0], k * ref[:, 1],
                              k * ref[:, 2] + zoff + 0.9 * m * body.diameter_m], axis=1)
        shots_out.append({"shot_id": sid, "path": path, "bodies": meshes, "measured": measured,
                          "stations": sd.stations, "label_points": label_pts,
                          "generic": generic, "grid_s": grid[..., 0], "zoff": zoff})
    generic = [s["shot_id"] for s in shots_out if s["generic"]]
    caption = (f"lateral scale (y, z) x{k:g}, model drawn x{m:g}, x true scale"
               + (f"; generic body outline for {', '.join(generic)}" if generic else ""))
    return shots_out, k, m, caption


# --------------------------------------------------------------------------- 3-D (pyvista)


def _headless() -> bool:
    return sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                     or os.environ.get("WAYLAND_DISPLAY"))


_PROBE = """
import vtkmodules.vtkRenderingOpenGL2  # registers the OpenGL back end
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkFiltersSources import vtkSphereSource
from vtkmodules.vtkRenderingCore import (vtkActor, vtkPolyDataMapper, vtkRenderer,
                                         vtkRenderWindow, vtkWindowToImageFilter)
src = vtkSphereSource()
mapper = vtkPolyDataMapper()
mapper.SetInputConnection(src.GetOutputPort())
actor = vtkActor()
actor.SetMapper(mapper)
ren = vtkRenderer()
ren.AddActor(actor)
ren.SetBackground(1, 1, 1)
win = vtkRenderWindow()
win.SetOffScreenRendering(1)
win.AddRenderer(ren)
win.SetSize(64, 48)
win.Render()
grab = vtkWindowToImageFilter()
grab.SetInput(win)
grab.Update()
img = vtk_to_numpy(grab.GetOutput().GetPointData().GetScalars())
assert img.std() > 0, "blank image"
print(win.GetClassName())
"""


@functools.cache
def offscreen_rendering() -> tuple[bool, str]:
    """Whether VTK renders off-screen in this environment, and how (or why not).

    Probed once per process in a child process (a VTK that cannot open any OpenGL context may
    abort the process rather than raise). Without an X display on Linux, VTK 9.4+ is steered
    to its EGL window (``VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow``), which needs the
    system's EGL and Mesa drivers (Debian/Ubuntu: ``libegl1``, ``libegl-mesa0``,
    ``libgl1-mesa-dri``); pip cannot provide them.
    """
    try:
        import pyvista  # noqa: F401
    except ImportError as exc:
        return False, f"pyvista is not installed ({exc})"
    env = dict(os.environ)
    if _headless():
        env.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    try:
        proc = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True,
                              text=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return False, f"the off-screen rendering probe did not finish ({exc})"
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
        return False, ("VTK cannot render off-screen here (exit status "
                       f"{proc.returncode}: {' / '.join(tail)}); it needs an X display, or "
                       "EGL (system packages libegl1, libegl-mesa0, libgl1-mesa-dri) or an "
                       "OSMesa build of VTK (pip install vtk-osmesa)")
    return True, proc.stdout.strip()


def render_trajectory_3d(result: FitResult, shots: Sequence[ShotData], path, *,
                         bodies: Mapping | None = None,
                         histories: Mapping[str, pd.DataFrame] | None = None,
                         title: str | None = None, lateral_scale: float | None = None,
                         model_scale: float | None = None,
                         window_size: tuple[int, int] = (1800, 720)) -> Path:
    """Render the fitted flight in 3-D with pyvista, off-screen, to a PNG at ``path``.

    The fitted reference-point path (line), the measured positions (black points) and the
    model at every station in its fitted attitude (a surface of revolution of its meridian,
    coloured from base (blue) to nose (red)). The range is ~20 m long and the lateral motion
    millimetres to centimetres, so y and z are exaggerated by ``lateral_scale`` and the model
    is drawn enlarged by ``model_scale`` (uniformly, so its attitude is true; the path's
    slope is exaggerated); defaults are chosen from the data and printed in the title.
    Several shots are stacked one above the other (offset in z).

    Raises :class:`RenderingUnavailable` (a RuntimeError) when VTK cannot render here
    (:func:`offscreen_rendering`). Returns ``path``.
    """
    ok, how = offscreen_rendering()
    if not ok:
        raise RenderingUnavailable(how)
    if _headless():
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    scene, k, m, caption = _scene(result, shots, bodies, histories, lateral_scale,
                                  model_scale)
    path = Path(path)
    p = pv.Plotter(off_screen=True, window_size=list(window_size))
    try:
        p.set_background("white")
        all_pts = []
        for sh in scene:
            line = pv.lines_from_points(sh["path"])
            p.add_mesh(line, color="#1f77b4", line_width=3)
            all_pts.append(sh["path"])
            for P in sh["bodies"]:
                grid = pv.StructuredGrid(P[..., 0], P[..., 1], P[..., 2])
                grid.point_data["s"] = sh["grid_s"].ravel(order="F")
                p.add_mesh(grid, scalars="s", cmap="coolwarm", show_scalar_bar=False,
                           smooth_shading=True, specular=0.3)
            p.add_point_labels(sh["label_points"], [str(int(s)) for s in sh["stations"]],
                               font_size=11, point_size=0, shape=None, text_color="#333333",
                               show_points=False, always_visible=True)
            p.add_point_labels(sh["label_points"][-1:] + np.array([0.8, 0.0, 0.0]),
                               [sh["shot_id"]],
                               font_size=14, point_size=0, shape=None, text_color="black",
                               show_points=False, always_visible=True)
        pts = np.concatenate(all_pts)
        x0, x1 = float(pts[:, 0].min()), float(pts[:, 0].max())
        zfloor = float(pts[:, 2].min()) - 1.2 * m * max(
            resolve_body(_shot_map(shots)[sh["shot_id"]], bodies)[0].diameter_m
            for sh in scene)
        ticks = np.arange(math.floor(x0 / 5.0) * 5.0, x1 + 1e-9, 5.0)
        ticks = ticks[(ticks >= x0 - 1e-9)]
        axis = np.array([[x0, 0.0, zfloor], [x1, 0.0, zfloor]])
        p.add_mesh(pv.lines_from_points(axis), color="#808080", line_width=1)
        if len(ticks):
            p.add_point_labels(np.stack([ticks, np.zeros_like(ticks),
                                         np.full_like(ticks, zfloor)], axis=1),
                               [f"x = {t:g} m" for t in ticks], font_size=10, point_size=6,
                               shape=None, text_color="#595959", point_color="#808080",
                               always_visible=True)
        p.add_text(_title(result, "fitted trajectory", title) + "\n" + caption,
                   position="upper_left", font_size=11, color="black")
        p.add_text("model at each station in its fitted attitude, coloured base (blue) to "
                   "nose (red); station numbers above; residuals (um) are far below this "
                   "scale: see residuals.png", position="lower_left", font_size=9,
                   color="#4d4d4d")
        cx = 0.5 * (x0 + x1)
        span = x1 - x0
        cz = float(pts[:, 2].mean())
        cy = float(pts[:, 1].mean())
        view = np.array([-0.04, -0.97, 0.24])
        view /= np.linalg.norm(view)
        zext = float(np.ptp(pts[:, 2])) + 2.0 * m * 0.05
        tan_v = math.tan(math.radians(15.0))          # VTK's default 30-degree view angle
        tan_h = tan_v * window_size[0] / window_size[1]
        dist = 1.3 * max(0.5 * span / tan_h, 0.5 * zext / tan_v)
        p.camera_position = [tuple(np.array([cx, cy, cz]) + dist * view), (cx, cy, cz),
                             (0.0, 0.0, 1.0)]
        p.reset_camera_clipping_range()
        img = p.screenshot(str(path), return_img=True)
    finally:
        p.close()
    if img is None or float(np.std(img)) == 0.0:
        path.unlink(missing_ok=True)
        raise RenderingUnavailable("VTK rendered a blank image (no working OpenGL context)")
    return path


def trajectory_3d_matplotlib(result: FitResult, shots: Sequence[ShotData], *, fig=None,
                             bodies: Mapping | None = None,
                             histories: Mapping[str, pd.DataFrame] | None = None,
                             title: str | None = None, lateral_scale: float | None = None,
                             model_scale: float | None = None):
    """The 3-D view of :func:`render_trajectory_3d` drawn with matplotlib (the fallback when
    VTK cannot render off-screen): path, measured points and the model at each station as a
    coarse wire-frame surface. Returns the figure."""
    scene, k, m, caption = _scene(result, shots, bodies, histories, lateral_scale,
                                  model_scale)
    fig = _new_figure(fig, (15, 6))
    ax = fig.add_subplot(projection="3d")
    for sh in scene:
        P = sh["path"]
        ax.plot(P[:, 0], P[:, 1], P[:, 2], "-", color="C0", lw=1.5)
        for B in sh["bodies"]:
            ax.plot_surface(B[::6, ::4, 0], B[::6, ::4, 1], B[::6, ::4, 2], color="0.7",
                            edgecolor="0.3", lw=0.2, alpha=0.8)
        if len(sh["measured"]):
            M = sh["measured"]
            ax.scatter(M[:, 0], M[:, 1], M[:, 2], color="k", s=8)
        for (x, y, z), s in zip(sh["label_points"], sh["stations"], strict=True):
            ax.text(x, y, z, str(int(s)), fontsize=7)
    ax.set_xlabel("x (m)")
    ax.set_ylabel(f"y x{k:g} (m)")
    ax.set_zlabel(f"z x{k:g} (m)")
    pts = np.concatenate([np.concatenate([sh["path"]] + [B.reshape(-1, 3)
                                                          for B in sh["bodies"]])
                          for sh in scene])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ext = hi - lo
    # x and z to the same scale (the pitch plane true); y widened to stay visible
    ax.set_box_aspect((ext[0], max(ext[1], 0.15 * ext[0]), ext[2]), zoom=1.0)
    ax.view_init(elev=15, azim=-80)
    fig.suptitle(_title(result, "fitted trajectory", title) + "\n" + caption, fontsize=10)
    return fig


__all__ = ["COEFFICIENT_LABELS", "RenderingUnavailable", "body_surface", "coefficient_curves",
           "offscreen_rendering", "plot_angle_histories", "plot_coefficients", "plot_residuals",
           "render_trajectory_3d", "resolve_body", "trajectory_3d_matplotlib"]
