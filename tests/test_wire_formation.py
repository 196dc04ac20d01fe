"""The wires' image formation fitted once per view of a shot (cadra.imaging.wires.formation)
against the renderer's truth: the default render forms a wire by its exact coverage of each
pixel, then a discrete Gaussian of 0.7 px (blur after the pixel), with a fringe 0.5 px wide;
each film placement's true affine gives every wire's true line."""

import dataclasses

import numpy as np
import pytest

from cadra.imaging.wires.fit import measure_wires, wire_profiles
from cadra.imaging.wires.formation import SHARED_P, _Problem, fit_formation, fit_widths
from cadra.synthetic.render import RenderConfig
from cadra.validation.wire_images import FAC, make_image, true_affine, true_offset_px

VIEW = FAC.view(1, "top")
BLUR_PX, FRINGE_PX = 0.7, 0.5


def _render(seed, config=None):
    M = true_affine(VIEW, 500 + seed)
    return make_image(VIEW, M, config, seed=seed), M


@pytest.fixture(scope="module")
def renders():
    return [_render(s) for s in range(4)]


@pytest.fixture(scope="module")
def shared(renders):
    f, _ = fit_formation([w for img, _ in renders[:3] for w in wire_profiles(img, VIEW)])
    return dataclasses.replace(f, n_images=3)


def test_a_view_s_formation_is_the_render_s_and_surer_than_one_image_s(renders, shared):
    """Three images pooled give the render's formation; its reported sigma is about 1/sqrt(3)
    of one image's (measured: sigma_d 0.695 +- 0.016, fringe 0.506 +- 0.036; one image's
    sigma_d scatters 0.60-0.75)."""
    assert shared.sigma_c < 0.1
    sd = np.sqrt(np.diag(shared.cov)[:3])
    assert abs(shared.sigma_d ** 2 - BLUR_PX ** 2) < 3.0 * sd[1]
    assert abs(shared.fringe_w - FRINGE_PX) < 3.0 * sd[2]
    one, _ = fit_formation(wire_profiles(renders[0][0], VIEW))
    ratio = np.sqrt(np.diag(one.cov)[1:3]) / sd[1:3]
    assert np.all(ratio > 1.3), ratio          # sqrt(3) = 1.73 for equal images


@pytest.mark.parametrize("k", [0, 3], ids=["pooled_image", "other_image"])
def test_an_image_measured_with_the_view_s_formation(renders, shared, k):
    """Only the widths are fitted; the lines are as true as with the image's own formation
    (err / sigma of each line's offset: measured within 1.7 both ways)."""
    img, M = renders[k]
    f, hs, score, p = fit_widths(wire_profiles(img, VIEW), shared)
    assert p > SHARED_P and f.shared and f.n_images == 3
    nominal = [0.5 * w.diameter_m / VIEW.scale_m_per_px for w in VIEW.wires]
    np.testing.assert_allclose(hs, nominal, rtol=0.05)      # the render's wires
    res = measure_wires(img, VIEW, formation=shared)
    assert res.ok and res.formation.shared and res.reason == ""
    own = measure_wires(img, VIEW)
    for r in (res, own):
        z = true_offset_px(VIEW, r, M) / [w.sigma_offset_px for w in r.wires]
        assert np.all(np.abs(z) < 4.0), z
    # the covariance carries the view's formation block and this image's widths
    assert res.formation.cov.shape == (3 + len(hs), 3 + len(hs))
    np.testing.assert_array_equal(res.formation.cov[:3, :3], shared.cov[:3, :3])


def test_an_image_formed_otherwise_fits_its_own(shared):
    """An image blurred 1.1 px (a station whose optics differ) rejects the view's formation
    (measured: score ~270, p ~ 1e-58; 0.8 px: score ~90-150) and is fitted alone."""
    img, M = _render(7, dataclasses.replace(RenderConfig(), optics_blur_sigma_px=1.1))
    res = measure_wires(img, VIEW, formation=shared)
    assert res.ok and not res.formation.shared
    assert "disagree with the view's shared image formation" in res.reason
    assert res.formation.sigma_d == pytest.approx(1.1, abs=0.1)
    z = true_offset_px(VIEW, res, M) / [w.sigma_offset_px for w in res.wires]
    assert np.all(np.abs(z) < 4.0), z


def test_the_widths_derivatives_in_one_pass_are_column_by_column_ones(renders):
    """A profile's residuals depend on its own wire's half-width only, so moving every wire's
    at once gives each wire's column (the fit's shortcut against the plain definition)."""
    pb = _Problem(wire_profiles(renders[1][0], VIEW))
    q = np.array([0.01, BLUR_PX ** 2, FRINGE_PX, *pb.h0])
    c = pb.centres(q)
    r0 = pb.resid(q, c)
    J = pb.jacobian(q, c, r0)
    assert J.shape == (len(r0), 3 + pb.m)
    for j in range(3 + pb.m):
        dq = q.copy()
        dq[j] += 1e-4
        col = (pb.resid(dq, c) - r0) / 1e-4
        assert np.max(np.abs(col)) > 0
        np.testing.assert_allclose(J[:, j], col, rtol=0, atol=1e-9 * np.max(np.abs(col)))


def test_a_parameter_the_profiles_do_not_determine_keeps_its_bounds_variance():
    """The formation's covariance gives no parameter more variance than a uniform spread over
    its bounds: an undetermined fringe width (sigma 212 px seen, bounds 0.05-4 px) is held to
    (4 - 0.05) / sqrt(12) px, its correlations kept; a determined one is left alone."""
    from cadra.imaging.wires.formation import _within_bounds

    cov = np.array([[4e-6, 1e-4, 0.0], [1e-4, 4.5e4, 2e-3], [0.0, 2e-3, 1e-4]])
    lo, hi = np.array([0.0, 0.05, 0.5]), np.array([16.0, 4.0, 2.0])
    out = _within_bounds(cov, lo, hi)
    assert out[1, 1] == pytest.approx((4.0 - 0.05) ** 2 / 12.0)
    assert out[0, 0] == cov[0, 0] and out[2, 2] == cov[2, 2]
    corr = lambda c: c[0, 1] / np.sqrt(c[0, 0] * c[1, 1])   # noqa: E731
    assert corr(out) == pytest.approx(corr(cov))
