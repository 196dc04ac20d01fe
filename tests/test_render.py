"""Synthetic shadowgraph renderer (cadra.synthetic.render): truth, optics, files, config.

Truths used: the shoelace area/centroid of the drawn polygon (exact), the separable overlap
lengths of an axis-aligned rectangle with the pixel grid (exact), the pixel-integrated Gaussian
edge sigma [G(z+) - G(z-)] with G(z) = z Phi(z) + phi(z) (analytic), and an independent
point-sampling rasterizer (``coverage(..., supersample=s)``).
"""

import math
import os

import numpy as np
import pytest
from scipy.special import ndtr

from cadra.synthetic.render import (
    RenderConfig,
    Scene,
    coverage,
    illumination_field,
    polygon_area_centroid,
    quantize,
    read_image,
    reference_mark_polygon,
    render,
    render_clean,
    wire_polygon,
    write_image,
)
from cadra.synthetic.render_config import PsfShape, load_render_config, save_render_config

RNG = np.random.default_rng(20261123)

#: no clutter, no noise: what moment tests need
QUIET = RenderConfig(scratches=0, dust=0, bow_shock=False, wake=False)


def circle(uc, vc, radius, n=4096):
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.column_stack([uc + radius * np.cos(t), vc + radius * np.sin(t)])


def moments(weight):
    """Area (sum) and centroid (u, v) of a non-negative (H, W) weight map."""
    v, u = np.indices(weight.shape)
    area = weight.sum()
    return area, ((weight * u).sum() / area, (weight * v).sum() / area)


def shadow_opacity(image, config, width, height):
    """(1 - I/B) / (1 - shadow_level): the shadow's opacity from a clean image."""
    background = illumination_field(width, height, config)
    return (1.0 - image / background) / (1.0 - config.shadow_level)


def interval_overlap(lo, hi, n):
    """Length of [lo, hi] inside each pixel [k - 1/2, k + 1/2], k = 0..n-1."""
    k = np.arange(n)
    return np.clip(np.minimum(hi, k + 0.5) - np.maximum(lo, k - 0.5), 0.0, None)


# ----------------------------------------------------------------------------- exact coverage


def test_sphere_area_and_centroid_from_coverage_moments():
    """Acceptance: r = 140 px circle (4096 vertices) at 24 random subpixel positions, no blur
    and no noise: centroid within 0.01 px, area within 1e-4 relative of the polygon's."""
    worst_c, worst_a = 0.0, 0.0
    for _ in range(24):
        uc, vc = RNG.uniform(180.0, 220.0, 2)
        poly = circle(uc, vc, 140.0)
        area, (pu, pv) = polygon_area_centroid(poly)
        cov = coverage(poly, 400, 400)
        m_area, (mu, mv) = moments(cov)
        worst_c = max(worst_c, abs(mu - pu), abs(mv - pv))
        worst_a = max(worst_a, abs(m_area / area - 1.0))
    assert worst_c < 1e-3  # 100x margin on the 0.01 px requirement (achieved ~2e-5)
    assert worst_a < 1e-12  # exact area integration


def test_sphere_through_render_without_blur_or_noise():
    """The same acceptance through the image: render_clean, no blur, no noise, no clutter."""
    config = QUIET.replace(optics_blur_sigma_px=0.0, diffraction_fringe=0.0)
    for _ in range(20):
        uc, vc = RNG.uniform(180.0, 220.0, 2)
        poly = circle(uc, vc, 140.0)
        area, (pu, pv) = polygon_area_centroid(poly)
        opacity = shadow_opacity(render_clean(Scene(400, 400, (poly,)), config), config, 400, 400)
        m_area, (mu, mv) = moments(opacity)
        assert abs(mu - pu) < 1e-3 and abs(mv - pv) < 1e-3
        assert abs(m_area / area - 1.0) < 1e-6  # float32 background field


def test_fine_grid_binning_reproduces_exact_coverage():
    """Two paths, one truth: the body's supersampled patch (s = 8, binned) with no blur equals
    the exact pixel-grid coverage."""
    config = QUIET.replace(
        optics_blur_sigma_px=0.0,
        diffraction_fringe=0.0,
        illumination_variation=0.0,
        illumination_mottle=0.0,
    )
    poly = circle(61.37, 48.81, 30.2, n=77)
    image = render_clean(Scene(120, 100, (poly,)), config)
    opacity = shadow_opacity(image, config, 120, 100)
    assert np.abs(opacity - coverage(poly, 120, 100)).max() < 1e-12


def test_axis_aligned_square_exact_coverage():
    # edges on pixel boundaries: exactly 1 inside, 0 outside
    square = np.array([[9.5, 9.5], [20.5, 9.5], [20.5, 15.5], [9.5, 15.5]])
    cov = coverage(square, 40, 30)
    expected = np.zeros((30, 40))
    expected[10:16, 10:21] = 1.0
    assert np.array_equal(cov, expected)
    # fractional edges: coverage = product of the overlap lengths (exact)
    for _ in range(10):
        u0, v0 = RNG.uniform(3.0, 8.0, 2)
        u1, v1 = u0 + RNG.uniform(2.0, 20.0), v0 + RNG.uniform(0.3, 15.0)
        rect = np.array([[u0, v0], [u0, v1], [u1, v1], [u1, v0]])  # either orientation
        expected = np.outer(interval_overlap(v0, v1, 30), interval_overlap(u0, u1, 40))
        assert np.abs(coverage(rect, 40, 30) - expected).max() < 1e-13
        assert np.abs(coverage(rect[::-1], 40, 30) - expected).max() < 1e-13


def test_coverage_matches_point_sampling_reference():
    """Exact rasterizer vs an independent point-in-polygon sampler (error O(1/s))."""
    s = 32
    for _ in range(5):
        t = np.sort(RNG.uniform(0.0, 2 * np.pi, 11))
        r = RNG.uniform(5.0, 14.0, 11)
        star = np.column_stack([20.3 + r * np.cos(t), 15.7 + r * np.sin(t)])
        exact = coverage(star, 40, 32)
        sampled = coverage(star, 40, 32, supersample=s)
        assert np.abs(exact - sampled).max() < 3.0 / s
        assert exact.sum() == pytest.approx(polygon_area_centroid(star)[0], rel=1e-12)


def test_polygon_clipped_by_image_border_is_exact():
    """A polygon running off the image: the same pixels as on a larger canvas."""
    poly = circle(5.3, 36.1, 22.4, n=301)
    big = coverage(poly + [30.0, 30.0], 100, 100)
    small = coverage(poly, 50, 40)
    assert np.abs(small - big[30:70, 30:80]).max() < 1e-13


def test_wire_and_mark_polygons():
    area, (uc, vc) = polygon_area_centroid(wire_polygon((1.0, 2.0), (11.0, 2.0), 2.0))
    assert area == pytest.approx(20.0) and (uc, vc) == pytest.approx((6.0, 2.0))
    area, (uc, vc) = polygon_area_centroid(reference_mark_polygon(50.0, 60.0, 10.0, 3.0))
    assert area == pytest.approx(2 * 20.0 * 3.0 - 9.0) and (uc, vc) == pytest.approx((50, 60))


# ----------------------------------------------------------------------------- optics


@pytest.mark.parametrize("motion", [(0.0, 0.0), (0.3, -0.2), (4.0, 1.5)])
def test_blur_keeps_sphere_area_and_centroid(motion):
    """Default optics (Gaussian PSF 0.7 px on the fine grid, fringe, uneven background) plus
    motion blur: the shadow's moments still give the polygon's area and centroid."""
    config = QUIET
    for _ in range(4):
        uc, vc = RNG.uniform(180.0, 220.0, 2)
        poly = circle(uc, vc, 140.0)
        area, (pu, pv) = polygon_area_centroid(poly)
        scene = Scene(400, 400, (poly,), motion_blur_px=motion)
        opacity = shadow_opacity(render_clean(scene, config), config, 400, 400)
        m_area, (mu, mv) = moments(opacity)
        assert abs(mu - pu) < 1e-3 and abs(mv - pv) < 1e-3
        assert abs(m_area / area - 1.0) < 1e-5


@pytest.mark.parametrize("shape", [PsfShape.AIRY_LIKE, PsfShape.DISK])
def test_other_psf_shapes_keep_centroid(shape):
    config = QUIET.replace(psf_shape=shape.value, optics_blur_sigma_px=0.9, diffraction_fringe=0)
    for _ in range(2):
        uc, vc = RNG.uniform(55.0, 65.0, 2)
        poly = circle(uc, vc, 30.0, n=1024)
        area, (pu, pv) = polygon_area_centroid(poly)
        opacity = shadow_opacity(render_clean(Scene(120, 120, (poly,)), config), config, 120, 120)
        m_area, (mu, mv) = moments(opacity)
        assert abs(mu - pu) < 1e-3 and abs(mv - pv) < 1e-3
        assert abs(m_area / area - 1.0) < 1e-5


@pytest.mark.parametrize("shape", list(PsfShape))
def test_blur_keeps_wire_position(shape):
    """A vertical wire at u = 50.3: the centroid of each row's shadow stays at 50.3."""
    config = QUIET.replace(psf_shape=shape.value, diffraction_fringe=0.0)
    scene = Scene(100, 40, wires=(((50.3, -10.0), (50.3, 50.0), 2.0),))
    opacity = shadow_opacity(render_clean(scene, config), config, 100, 40)[20]
    u = np.arange(100)
    assert (opacity * u).sum() / opacity.sum() == pytest.approx(50.3, abs=1e-9)
    assert opacity.sum() == pytest.approx(2.0, abs=1e-9)


def test_gaussian_edge_profile_is_the_pixel_integrated_error_function():
    """What measurement code may assume: a straight edge blurred by the Gaussian PSF and
    integrated over the pixel, sigma [G(z+) - G(z-)] with G(z) = z Phi(z) + phi(z)."""
    sigma, edge = 0.7, 40.3
    config = QUIET.replace(
        optics_blur_sigma_px=sigma,
        diffraction_fringe=0.0,
        illumination_variation=0.0,
        illumination_mottle=0.0,
    )
    body = np.array([[-50.0, -50.0], [edge, -50.0], [edge, 150.0], [-50.0, 150.0]])
    image = render_clean(Scene(80, 100, (body,)), config)
    opacity = shadow_opacity(image, config, 80, 100)[50]

    def G(z):
        return z * ndtr(z) + np.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi)

    u = np.arange(80)
    expected = sigma * (G((edge - u + 0.5) / sigma) - G((edge - u - 0.5) / sigma))
    assert np.abs(opacity - expected).max() < 2e-3  # fine-grid sampling of the PSF (s = 8)


def test_motion_blur_is_a_centred_ramp():
    """A vertical edge swept by 4 px along u: opacity ramps linearly over 4 px centred on
    the mid-exposure edge."""
    edge, m = 40.5, 4.0
    config = QUIET.replace(
        optics_blur_sigma_px=0.0,
        diffraction_fringe=0.0,
        illumination_variation=0.0,
        illumination_mottle=0.0,
    )
    body = np.array([[-50.0, -50.0], [edge, -50.0], [edge, 150.0], [-50.0, 150.0]])
    image = render_clean(Scene(80, 100, (body,), motion_blur_px=(m, 0.0)), config)
    opacity = shadow_opacity(image, config, 80, 100)[50]
    # pixel k covers [k - 1/2, k + 1/2]; the swept edge profile is clip((edge + m/2 - x)/m)
    x = np.linspace(-0.5, 0.5, 2001)
    expected = [np.clip((edge + m / 2 - (k + x)) / m, 0, 1).mean() for k in range(80)]
    assert np.abs(opacity - np.array(expected)).max() < 2e-3


def test_fringe_is_bright_outside_and_dark_inside():
    config = QUIET.replace(illumination_variation=0.0, illumination_mottle=0.0)
    body = np.array([[-50.0, -50.0], [40.0, -50.0], [40.0, 150.0], [-50.0, 150.0]])
    row = render_clean(Scene(80, 100, (body,)), config)[50] / config.background_level
    assert row[41:45].max() > 1.03  # bright band just outside (u > 40)
    assert row[35:40].min() < config.shadow_level - 0.03  # dark band just inside


def test_wires_and_mark_are_drawn_opaque():
    config = QUIET.replace(diffraction_fringe=0.0, illumination_mottle=0.0)
    scene = Scene(200, 150, wires=(((50.0, -10.0), (50.0, 160.0), 6.0),),
                  reference_mark=(150.0, 100.0, 10.0, 6.0))  # fmt: skip
    image = render_clean(scene, config) / illumination_field(200, 150, config)
    assert image[75, 50] == pytest.approx(config.shadow_level, abs=1e-3)
    assert image[100, 150] == pytest.approx(config.shadow_level, abs=1e-3)
    assert image[75, 80] == pytest.approx(1.0, abs=1e-9)


# ----------------------------------------------------------------------------- clutter


def test_clutter_never_touches_the_body():
    uc, vc, r = 200.3, 150.7, 60.0
    poly = circle(uc, vc, r, n=1024)
    scene = Scene(400, 300, (poly,), body_hint=(uc, vc, 1.0, 0.2, r))
    config = RenderConfig(scratches=40, dust=400)  # lots of defects: some fall on the body
    with_clutter = render_clean(scene, config)
    without = render_clean(scene, config.replace(scratches=0, dust=0, bow_shock=False,
                                                 wake=False))  # fmt: skip
    near_body = coverage(circle(uc, vc, r + config.clutter_clearance_px), 400, 300) > 0.0
    assert np.array_equal(with_clutter[near_body], without[near_body])
    assert np.abs(with_clutter - without).max() > 0.01  # but clutter is there


def test_bow_shock_ahead_and_wake_behind():
    uc, vc, r = 200.0, 150.0, 40.0
    scene = Scene(400, 300, (circle(uc, vc, r, n=512),), body_hint=(uc, vc, 1.0, 0.0, r))
    base = QUIET.replace(illumination_variation=0.0, illumination_mottle=0.0)
    plain = render_clean(scene, base)
    shock = np.abs(render_clean(scene, base.replace(bow_shock=True)) - plain)
    wake = np.abs(render_clean(scene, base.replace(wake=True)) - plain)
    v = int(vc)
    assert shock[v, int(uc + r) + 3 :].max() > 0.02  # ahead (flight is +u)
    assert shock[:, : int(uc - r)].max() < 1e-12  # nothing behind the body
    assert wake[:, : int(uc - r)].max() > 0.005
    assert wake[:, int(uc + r) :].max() < 1e-12


# ----------------------------------------------------------------------------- noise, determinism


def small_scene():
    return Scene(160, 120, (circle(80.2, 60.4, 25.0, n=512),),
                 wires=(((20.0, -5.0), (22.0, 125.0), 2.0),),
                 reference_mark=(140.0, 100.0, 8.0, 2.0),
                 body_hint=(80.2, 60.4, 1.0, 0.0, 25.0))  # fmt: skip


def test_same_seed_same_image_different_seed_different_noise():
    scene, config = small_scene(), RenderConfig(seed=7)
    a = render(scene, config)
    b = render(scene, config)
    c = render(scene, config, rng=np.random.default_rng(8))
    d = render(scene, config.replace(seed=8))
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    assert not np.array_equal(a, d)
    # the clean image (fixed pattern) depends on config.seed only, not on the noise stream
    assert np.array_equal(render_clean(scene, config), render_clean(scene, config))


def test_noise_level_matches_the_model():
    config = RenderConfig(bit_depth=16, illumination_variation=0.0, illumination_mottle=0.0,
                          film_grain_sigma=0.0, scratches=0, dust=0)  # fmt: skip
    scene = Scene(300, 300)
    image = render(scene, config).astype(float) / 65535.0
    level = config.background_level
    expected = math.sqrt(config.read_noise_sigma**2 + config.shot_noise_sigma**2 * level)
    assert image.mean() == pytest.approx(level, abs=2e-4)
    assert image.std() == pytest.approx(expected, rel=0.02)


def test_quantization_range_and_dtype():
    values = np.array([[-0.2, 0.0, 0.5, 1.0, 1.3]])
    assert quantize(values, 8).tolist() == [[0, 0, 128, 255, 255]]
    assert quantize(values, 16).tolist() == [[0, 0, 32768, 65535, 65535]]
    bright = RenderConfig(background_level=1.0, illumination_variation=0.2)
    for bits, dtype in ((8, np.uint8), (16, np.uint16)):
        image = render(small_scene(), bright.replace(bit_depth=bits))
        assert image.dtype == dtype and image.shape == (120, 160)
        assert image.max() == (1 << bits) - 1  # saturated, clipped not wrapped


# ----------------------------------------------------------------------------- files


@pytest.mark.parametrize("bits", [8, 16])
def test_png_round_trip_and_no_overwrite(tmp_path, bits):
    image = render(small_scene(), RenderConfig(bit_depth=bits))
    path = tmp_path / f"shot_{bits}.png"
    write_image(path, image)
    back = read_image(path)
    assert back.dtype == image.dtype and np.array_equal(back, image)
    with pytest.raises(FileExistsError):
        write_image(path, image)
    write_image(path, image[::-1].copy(), overwrite=True)
    assert np.array_equal(read_image(path), image[::-1])
    assert sorted(os.listdir(tmp_path)) == [path.name]  # no temporary files left


def test_write_image_rejects_bad_input(tmp_path):
    with pytest.raises(ValueError):
        write_image(tmp_path / "a.png", np.zeros((4, 4), dtype=np.float64))
    with pytest.raises(ValueError):
        write_image(tmp_path / "a.jpg", np.zeros((4, 4), dtype=np.uint8))
    with pytest.raises(FileNotFoundError):
        read_image(tmp_path / "missing.png")


# ----------------------------------------------------------------------------- config


def test_config_toml_round_trip(tmp_path):
    config = RenderConfig(seed=12, psf_shape="airy_like", bit_depth=16, scratches=5,
                          optics_blur_sigma_px=1.25)  # fmt: skip
    path = save_render_config(tmp_path / "render.toml", config)
    assert load_render_config(path) == config
    assert RenderConfig.from_dict(config.to_dict()) == config
    with pytest.raises(FileExistsError):
        save_render_config(path, config)
    # a [render] table inside a larger run file
    run = tmp_path / "run.toml"
    run.write_text("[render]\nseed = 3\ndust = 0\n[other]\nx = 1\n")
    assert load_render_config(run, table="render") == RenderConfig(seed=3, dust=0)


def test_config_unknown_key_is_named(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("seed = 1\noptics_blur_sigma = 0.7\n")
    with pytest.raises(ValueError, match="optics_blur_sigma"):
        load_render_config(path)
    with pytest.raises(ValueError, match="'bogus'"):
        RenderConfig.from_dict({"bogus": 1})


def test_config_bad_values_are_rejected():
    with pytest.raises(ValueError, match="bit_depth"):
        RenderConfig(bit_depth=12)
    with pytest.raises(ValueError, match="psf_shape"):
        RenderConfig(psf_shape="square")
    with pytest.raises(TypeError, match="supersample"):
        RenderConfig(supersample=8.0)
    with pytest.raises(ValueError, match="shadow_level"):
        RenderConfig(shadow_level=1.5)


def test_scene_validation():
    with pytest.raises(ValueError):
        Scene(100, 100, (np.zeros((2, 2)),))
    with pytest.raises(ValueError):
        Scene(100, 100, circle(50, 50, 10))  # a bare polygon, not a tuple of them
    with pytest.raises(ValueError):
        Scene(100, 100, wires=(((0, 0), (0, 0), 2.0),))
    hint = Scene(100, 100, body_hint=(50, 50, 3.0, 4.0, 10.0)).body_hint
    assert hint[2:4] == pytest.approx((0.6, 0.8))
