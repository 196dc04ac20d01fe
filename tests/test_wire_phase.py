"""The wire centroid's sub-pixel phase bias (cadra.imaging.wires.phase), against closed forms
and noise-free renders.

A noise-free render leaves only the deterministic error of each wire's line: on a wire that
stays at one pixel phase it is the centroid's phase bias, which the line's ``sigma_sys_px``
must cover; on one that sweeps the pixel grid it averages out, and ``sigma_sys_px`` must
too. Measured when written (12 placements, 48 lines, 8 of them within 1 px of grid-parallel):
error / sigma_sys_px of the grid-parallel lines rms 1.15 (errors rms 0.0029 px; the
single-gain model slightly under-sizes the bias near its jump); swept lines' sigma_sys_px
<= 4.4e-4 px.
"""

import numpy as np
import pytest

from cadra.imaging.wires.fit import measure_wires
from cadra.imaging.wires.phase import phase_gain, sampling_bias_px, systematic_cov
from cadra.validation.wire_images import (
    FAC,
    QUIET,
    VIEWS,
    drift_px,
    make_image,
    true_affine,
    true_offset_px,
)


@pytest.mark.parametrize("width", [1.0, 1.5, 1.97, 2.6, 3.3])
def test_sampling_bias_against_supersampled_coverage(width):
    """The closed form against the centroid of a 4000x supersampled band's pixel coverage."""
    phi = np.linspace(0.0, 1.0, 41)
    fine = (np.arange(-8000, 8000) + 0.5) / 1000.0  # sub-samples of pixels -8 .. 7
    k = np.floor(fine + 0.5)
    for p in phi:
        inside = np.abs(fine - p) <= 0.5 * width
        cov = np.bincount((k[inside] + 8).astype(int), minlength=17)
        ref = (cov * (np.arange(17) - 8)).sum() / cov.sum() - p
        assert sampling_bias_px(p, width) == pytest.approx(ref, abs=2e-5)
    b = sampling_bias_px(phi[:-1], width)
    assert abs(b.mean()) < 1e-12 + 1e-3 * np.abs(b).max()  # zero mean over a phase
    if abs(width - round(width)) > 0.05:
        assert np.abs(b).max() > 1e-3


def test_systematic_cov_one_phase_and_swept():
    """A line at one phase keeps the bias's full mean square; a line sweeping many pixels
    averages it out."""
    w, n = 1.97, 300
    s = np.linspace(-600.0, 600.0, n)
    rms2 = np.mean(sampling_bias_px(np.linspace(0.0, 1.0, 20000, endpoint=False), w) ** 2)
    one = systematic_cov(np.full(n, 0.3), s, 1.0, w, 1.0)
    assert one == pytest.approx(rms2 * np.ones((2, 2)), rel=0.02)  # 64 shifts of a sawtooth
    swept = systematic_cov((s / 120.0) % 1.0, s, 1.0, w, 1.0)  # 10 pixels across the grid
    assert np.max(np.abs(swept)) < 0.02 * rms2
    assert systematic_cov(np.full(n, 0.3), s, 1.0, w, 0.25) == pytest.approx(0.25 * one)


def test_phase_gain_recovers_a_known_gain():
    """Residuals made of 0.6 x the sharp band's bias plus noise, on swept lines: g_hat ~ 0.6
    within its own sigma; a line at one phase shows nothing."""
    rng = np.random.default_rng(5)
    w, lines = 1.97, []
    for drift in (7.0, 9.0, 0.0):
        s = np.linspace(-600.0, 600.0, 300)
        phi = (0.2 + drift * (s + 600.0) / 1200.0) % 1.0
        r = 0.6 * sampling_bias_px(phi, w) + rng.normal(0.0, 0.002, s.size)
        A = np.column_stack([np.ones_like(s), s])
        r = r - A @ np.linalg.lstsq(A, r, rcond=None)[0]
        lines.append((phi, s, r, 1.0, 0.002))
    g, sd, g2 = phase_gain(lines, [w] * 3)
    assert abs(g - 0.6) < 4.0 * sd and sd < 0.05
    assert g2 == pytest.approx(g * g + sd * sd, rel=0.05)
    _g, _sd, g2_none = phase_gain([lines[2], None, None], [w] * 3)
    assert g2_none == pytest.approx(1.0 / 3.0, rel=0.05)  # nothing shown: the prior's mean


@pytest.fixture(scope="module")
def quiet_lines():
    """Noise-free renders of tools/validate_wire_sigma.py's first 12 placements: per line
    (error of its offset (px), its sigma_sys_px, its drift across the grid (px))."""
    out = []
    for k in range(12):
        station, name = VIEWS[k % 2]
        view = FAC.view(station, name)
        M = true_affine(view, 100 * station + 1000 + k)
        res = measure_wires(make_image(view, M, QUIET, seed=1000 + k), view, profile_model=False)
        assert res.ok and res.n_found == 4
        out += zip(true_offset_px(view, res, M), [f.sigma_sys_px for f in res.wires],
                   drift_px(view, M), strict=True)
    return np.array(out)


def test_sigma_sys_covers_a_grid_parallel_lines_error(quiet_lines):
    err, sys_px, drift = quiet_lines.T
    parallel = drift < 1.0
    z = err[parallel] / sys_px[parallel]
    rms = float(np.sqrt(np.mean(z ** 2)))
    print(f"noise-free: {parallel.sum()} grid-parallel lines, error / sigma_sys rms {rms:.2f} "
          f"(errors rms {np.sqrt(np.mean(err[parallel] ** 2)):.4f} px); swept lines' "
          f"sigma_sys max {sys_px[drift > 4.0].max():.5f} px")
    assert parallel.sum() >= 5
    # ~8 lines: the rms of z has ~25 % sampling error; the bias's rms is ~0.003 px
    assert 0.6 < rms < 1.7
    assert np.all(np.abs(z) < 3.5)
    assert np.all(sys_px[drift > 4.0] < 1e-3)
