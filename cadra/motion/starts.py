"""Automatic starting values for the motion fits: the matrix-pencil (Prony-type) estimate of
the complex exponents of a sum of damped complex exponentials (Hua & Sarkar, IEEE Trans.
ASSP 38 (1990) 814), with an FFT peak pick as the fallback. A user never gives starts.

Non-uniformly sampled data (range stations) are linearly resampled onto a uniform grid of
the same number of points first; the estimate only seeds the differential corrections.
"""

from __future__ import annotations

import numpy as np


def _uniform(s: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ds = np.diff(s)
    if np.ptp(ds) <= 1e-9 * np.mean(ds):
        return s, y
    grid = np.linspace(s[0], s[-1], s.size)
    yr = np.interp(grid, s, y.real) + 1j * np.interp(grid, s, y.imag)
    return grid, yr


def pencil_exponents(s: np.ndarray, y: np.ndarray, n_exp: int) -> np.ndarray:
    """Complex exponents ``r_k`` (per unit of ``s``) of ``y ≈ Σ c_k exp(r_k s)``.

    Parameters
    ----------
    s : (N,) increasing independent variable (time or distance)
    y : (N,) complex (or real) samples
    n_exp : number of exponents sought

    Returns
    -------
    (n_exp,) complex exponents; the decay rate is the real part and the frequency (rad per unit
    of ``s``) the imaginary part. Falls back on FFT peaks when the pencil is degenerate.
    """
    s, y = _uniform(np.asarray(s, float), np.asarray(y, complex))
    n = y.size
    h = (s[-1] - s[0]) / (n - 1)
    L = int(min(max(n // 3, n_exp + 1), 40))
    rows = n - L
    idx = np.arange(rows)[:, None] + np.arange(L + 1)[None, :]
    Y = y[idx]
    try:
        # the right singular vectors from the small Gram matrix: einsum and a (L+1)² eigh
        # instead of the SVD of the Hankel matrix, whose threaded BLAS stalls on a busy machine
        _, U = np.linalg.eigh(np.einsum("ki,kj->ij", Y.conj(), Y))
        V = U[:, ::-1][:, :n_exp].conj()
        z = np.linalg.eigvals(np.linalg.pinv(V[:-1]) @ V[1:])
        z = z[np.abs(z) > 1e-12]
        if z.size == n_exp and np.all(np.isfinite(z)):
            return np.log(z) / h
    except np.linalg.LinAlgError:
        pass
    return fft_exponents(s, y, n_exp)


def fft_exponents(s: np.ndarray, y: np.ndarray, n_exp: int) -> np.ndarray:
    """The ``n_exp`` largest peaks of the zero-padded, Hann-windowed FFT (zero decay)."""
    s, y = _uniform(np.asarray(s, float), np.asarray(y, complex))
    n = y.size
    h = (s[-1] - s[0]) / (n - 1)
    m = 8 * int(2 ** np.ceil(np.log2(n)))
    spec = np.abs(np.fft.fft((y - y.mean()) * np.hanning(n), m))
    freq = 2 * np.pi * np.fft.fftfreq(m, h)
    out = []
    work = spec.copy()
    guard = max(1, int(round(m / n)))
    for _ in range(n_exp):
        k = int(np.argmax(work))
        out.append(1j * freq[k])
        work[max(0, k - 2 * guard):k + 2 * guard + 1] = 0.0
    return np.asarray(out)


def linear_amplitudes(s: np.ndarray, y: np.ndarray, exponents: np.ndarray,
                      s_ref: float) -> np.ndarray:
    """Least-squares complex amplitudes ``c_k`` of ``y ≈ Σ c_k exp(r_k (s - s_ref))``."""
    E = np.exp(np.outer(s - s_ref, exponents))
    c, *_ = np.linalg.lstsq(E, y, rcond=None)
    return c
