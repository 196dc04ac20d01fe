"""Cramér–Rao bound of the pose (cadra.synthetic.crb) and the Otsu + moments baseline."""

import math

import numpy as np
import pytest

from cadra.body import capsule, silhouette
from cadra.synthetic.crb import (
    grain_correlation_kernel,
    model_image,
    noise_covariance_operator,
    pose_crb,
)
from cadra.synthetic.render import (
    RenderConfig,
    Scene,
    _film_grain,
    illumination_field,
    quantize,
    render,
    render_clean,
)
from cadra.validation.otsu import (
    otsu_moments,
    polygon_centroid_offset,
    reference_from_centroid,
)

SCALE_M_PER_PX = 1.27e-4
TOP_VIEW = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def ellipse(uc, vc, a, b, angle, n=512):
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    x, y = a * np.cos(t), b * np.sin(t)
    c, s = math.cos(angle), math.sin(angle)
    return np.column_stack([uc + c * x - s * y, vc + s * x + c * y])


def capsule_px(u0, v0, yaw=0.0):
    """M2 capsule silhouette in the top view, nose toward +u turned by ``yaw`` (nose to port)."""
    c, s = math.cos(yaw), math.sin(yaw)
    R_FB = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ np.diag([1.0, -1.0, -1.0])
    pm = silhouette(capsule("M2"), R_FB, np.zeros(3), TOP_VIEW)
    return np.column_stack([pm[:, 0] / SCALE_M_PER_PX + u0, -pm[:, 1] / SCALE_M_PER_PX + v0])


# ============================================================================ noise model


def test_grain_correlation_matches_renderer():
    cfg = RenderConfig()
    a = grain_correlation_kernel(cfg.film_grain_length_px)
    mid = len(a) // 2
    assert a[mid] == pytest.approx(1.0)
    g = _film_grain((600, 600), cfg, np.random.default_rng(7)).astype(np.float64)[20:-20, 20:-20]
    for lag in range(4):
        emp = 0.5 * ((g[:, : g.shape[1] - lag] * g[:, lag:]).mean()
                     + (g[: g.shape[0] - lag] * g[lag:]).mean())  # fmt: skip
        assert emp == pytest.approx(a[mid + lag], abs=0.03)


def test_cg_fisher_matches_dense_solve():
    cfg = RenderConfig()
    poly = ellipse(20.3, 15.6, 9.0, 5.0, 0.3, n=256)
    r = pose_crb(poly, (20.3, 15.6), cfg, roi_margin_px=6)
    h, w, n = r.jacobian.shape
    apply, _, _ = noise_covariance_operator(r.expected, cfg)
    eye = np.eye(h * w)
    C = np.stack([apply(eye[i].reshape(h, w)).ravel() for i in range(h * w)], axis=1)
    assert np.allclose(C, C.T, rtol=0, atol=1e-18)
    G = r.jacobian.reshape(-1, n)
    F = G.T @ np.linalg.solve(C, G)
    assert np.abs(F - r.fisher).max() < 1e-7 * np.abs(F).max()
    assert r.params == ("u", "v", "phi", "gain", "blur_sigma")


# ============================================================================ bound


def test_crb_disk_matches_analytic_edge_formula():
    """Centre of a disk, white noise: sigma = s_n / sqrt(C^2 pi R / (2 sqrt(pi) s_e))."""
    R, s, sn = 60.0, 0.7, 0.01
    cfg = RenderConfig(illumination_variation=0.0, illumination_mottle=0.0,
                       diffraction_fringe=0.0, read_noise_sigma=sn, shot_noise_sigma=0.0,
                       film_grain_sigma=0.0, bit_depth=16, optics_blur_sigma_px=s)  # fmt: skip
    t = np.linspace(0.0, 2.0 * np.pi, 2048, endpoint=False)
    ref = (100.3, 90.7)
    poly = np.column_stack([ref[0] + R * np.cos(t), ref[1] + R * np.sin(t)])
    r = pose_crb(poly, ref, cfg, include_nuisance=False, fit_angle=False)
    contrast = cfg.background_level * (1.0 - cfg.shadow_level)
    s_e = math.sqrt(s * s + 1.0 / 12.0)
    expect = sn / math.sqrt(contrast**2 * math.pi * R / (2.0 * math.sqrt(math.pi) * s_e))
    assert r.sigma_u_px == pytest.approx(expect, rel=0.10)
    assert r.sigma_v_px == pytest.approx(expect, rel=0.10)
    assert math.isnan(r.sigma_phi_rad)
    # no grain: the correlated and white bounds coincide
    assert r.sigma_white_u_px == pytest.approx(r.sigma_u_px, rel=1e-9)


def test_roi_model_reproduces_full_frame_render_clean():
    cfg = RenderConfig(scratches=0, dust=0)
    W, H = 400, 300
    ref = (200.37, 150.61)
    poly = np.array(ref) + 0.5 * (capsule_px(*ref, yaw=0.1) - np.array(ref))  # a small capsule
    full = render_clean(Scene(W, H, bodies=(poly,), motion_blur_px=(0.8, 0.0)), cfg)
    r = pose_crb(poly, ref, cfg, motion_blur_px=(0.8, 0.0), width_px=W, height_px=H)
    u0, v0, w, h = r.roi
    assert np.abs(r.expected - full[v0 : v0 + h, u0 : u0 + w]).max() < 1e-6
    # the flat-beam model is the same transmission times background_level
    flat = model_image(poly, ref, cfg, r.roi, motion_blur_px=(0.8, 0.0))
    beam = illumination_field(W, H, cfg)[v0 : v0 + h, u0 : u0 + w]
    assert np.allclose(flat * beam / cfg.background_level, r.expected, rtol=1e-6, atol=1e-9)


def _monte_carlo(cfg, correlated, n_draws, seed):
    """Chord Gauss–Newton (Jacobian at truth, residual re-rendered) on render() draws."""
    ref = (40.3, 30.6)
    poly = ellipse(*ref, 18.0, 9.0, math.radians(20.0), n=256)
    r = pose_crb(poly, ref, cfg, include_nuisance=False, roi_margin_px=8)
    if correlated:
        X, Finv = r.cinv_jacobian, r.cov
    else:
        X, Finv = r.jacobian / r.pixel_variance[..., None], r.cov_white
    u0, v0, w, h = r.roi
    scene = Scene(w, h, bodies=(poly - (u0, v0),))
    rng = np.random.default_rng(seed)
    full = float((1 << cfg.bit_depth) - 1)
    est = np.empty((n_draws, 3))
    for k in range(n_draws):
        y = render(scene, cfg, rng) / full
        p = np.zeros(3)
        for _ in range(3):
            res = y - model_image(poly, ref, cfg, r.roi, pose=p)
            p = p + Finv @ np.einsum("ijk,ij->k", X, res)
        est[k] = p
    return r, est


def test_crb_monte_carlo_white_noise():
    cfg = RenderConfig(illumination_variation=0.0, illumination_mottle=0.0, scratches=0, dust=0,
                       film_grain_sigma=0.0)  # fmt: skip
    r, est = _monte_carlo(cfg, correlated=False, n_draws=300, seed=123)
    bound = np.sqrt(np.diag(r.cov_white))
    std = est.std(axis=0, ddof=1)
    assert np.all(np.abs(std / bound - 1.0) < 0.15), std / bound
    assert np.all(np.abs(est.mean(axis=0)) < 4.0 * bound / math.sqrt(len(est)))


def test_crb_monte_carlo_correlated_grain():
    """With grain the efficient (GLS) estimator reaches the correlated bound, not the white."""
    cfg = RenderConfig(illumination_variation=0.0, illumination_mottle=0.0, scratches=0, dust=0)
    r, est = _monte_carlo(cfg, correlated=True, n_draws=300, seed=321)
    std = est.std(axis=0, ddof=1)
    assert np.all(np.abs(std / np.sqrt(np.diag(r.cov)) - 1.0) < 0.15)
    assert np.all(std / np.sqrt(np.diag(r.cov_white)) > 1.05)


def test_crb_capsule_default_realism():
    ref = (1000.37, 500.61)
    r = pose_crb(capsule_px(*ref), ref, RenderConfig(), motion_blur_px=(0.8, 0.0),
                 width_px=2048, height_px=1024)  # fmt: skip
    assert r.params == ("u", "v", "phi", "gain", "blur_sigma")
    assert 1e-4 < r.sigma_u_px < 1e-2 and 1e-4 < r.sigma_v_px < 1e-2
    assert 1e-6 < r.sigma_phi_rad < 1e-3
    # grain correlation costs information; marginalizing nuisances never helps
    assert r.sigma_u_px > r.sigma_white_u_px
    known = r.pose_sigmas(marginalize_nuisance=False)
    assert known["u"] <= r.sigma_u_px * (1.0 + 1e-9)
    assert r.cg_residual < 1e-8


# ============================================================================ baseline


def test_otsu_sphere_centroid():
    uc, vc = 320.37, 240.61
    t = np.linspace(0.0, 2.0 * np.pi, 2048, endpoint=False)
    poly = np.column_stack([uc + 140.0 * np.cos(t), vc + 140.0 * np.sin(t)])
    scene = Scene(640, 480, bodies=(poly,), wires=(((-5.0, 100.3), (700.0, 110.2), 2.0),),
                  motion_blur_px=(0.8, 0.0))  # fmt: skip
    image = quantize(render_clean(scene, RenderConfig()), 8)
    b = otsu_moments(image)
    assert abs(b.u_px - uc) < 0.3 and abs(b.v_px - vc) < 0.3
    assert b.area_px == pytest.approx(math.pi * 140.0**2, rel=0.005)
    assert 0.1 < b.threshold < 0.8
    # float input and a ROI give the same answer
    b2 = otsu_moments(render_clean(scene, RenderConfig()), roi=(150, 70, 340, 340))
    assert abs(b2.u_px - uc) < 0.3 and abs(b2.v_px - vc) < 0.3


@pytest.mark.parametrize("deg", [25.0, -60.0, 90.0, 0.0])
def test_otsu_ellipse_angle(deg):
    e = ellipse(200.2, 150.7, 90.0, 30.0, math.radians(deg))
    image = render_clean(Scene(400, 300, bodies=(e,)), RenderConfig())
    b = otsu_moments(image)
    err = (math.degrees(b.angle_rad) - deg + 90.0) % 180.0 - 90.0
    assert abs(err) < 0.5
    assert -0.5 * math.pi < b.angle_rad <= 0.5 * math.pi


def test_capsule_reference_from_centroid():
    ref = (320.37, 240.61)
    yaw = math.radians(10.0)
    poly = capsule_px(*ref, yaw=yaw)
    phi = -yaw  # nose to port = up in the top view = -v
    offset = polygon_centroid_offset(poly, ref, phi)
    assert offset[0] < -30.0 and abs(offset[1]) < 1e-9  # centroid behind the reference point
    image = render(Scene(640, 480, bodies=(poly,), motion_blur_px=(0.8, 0.0)), RenderConfig())
    b = otsu_moments(image)
    axis = b.angle_rad + 0.5 * math.pi  # wider than long: the major axis is across
    if math.cos(axis) < 0.0:
        axis -= math.pi
    assert math.degrees(axis - phi) == pytest.approx(0.0, abs=0.5)
    u, v = reference_from_centroid(b.u_px, b.v_px, axis, offset)
    assert abs(u - ref[0]) < 0.3 and abs(v - ref[1]) < 0.3
