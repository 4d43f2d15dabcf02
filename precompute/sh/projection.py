"""Projection onto real SH: quadrature samples, and an equirectangular panorama pixel by pixel.

The convention and the basis are :mod:`.harmonics`'.
"""

from __future__ import annotations

import numpy as np

from .. import _checks
from ..world.hdri import equirect_azimuths, equirect_polar, equirect_row_solid_angles
from .harmonics import (
    assemble,
    band_of_index,
    basis,
    check_l_max,
    legendre_sin_free_normalised,
    unit_directions,
)

__all__ = ["project", "project_equirect"]


def project(l_max: int, directions, values, weights) -> np.ndarray:
    """Quadrature projection c_i = Σ_k w_k f(ω_k) Y_i(ω_k).

    Parameters
    ----------
    l_max : int
    directions : array_like, shape (N, 3)
        Sample directions (normalised here).
    values : array_like, shape (N,) or (N, C)
        Samples f(ω_k) (e.g. radiance, W m⁻² sr⁻¹).
    weights : array_like, shape (N,)
        Quadrature weights w_k in sr (they should sum to ≈ 4π for a full-sphere rule).

    Returns
    -------
    ndarray, shape ((l_max+1)²,) for 1-D ``values`` or ((l_max+1)², C) for 2-D ``values``
        Coefficients in units of f·sr^½.
    """
    l_max = check_l_max(l_max)
    d = unit_directions(directions)
    if d.ndim != 2:
        raise ValueError(f"directions must have shape (N, 3), got {d.shape}")
    v = _checks.finite_array("values", values)
    if v.ndim not in (1, 2) or v.shape[0] != d.shape[0]:
        raise ValueError(f"values must have shape ({d.shape[0]},) or ({d.shape[0]}, C), got {v.shape}")
    w = _checks.finite_array("weights", weights)
    if w.shape != (d.shape[0],):
        raise ValueError(f"weights must have shape ({d.shape[0]},), got {w.shape}")
    y = basis(l_max, d)
    wv = w[:, None] * v if v.ndim == 2 else w * v
    return y.T @ wv


def project_equirect(image, l_max: int, *, return_info: bool = False):
    """Project an equirectangular environment (Blender's convention) onto real SH.

    Each pixel contributes its radiance times its exact solid angle
    dω = (2π/W)(cos θ_top − cos θ_bottom), with the basis evaluated at the pixel centre.
    The sum is separable: per row the Legendre part N_l^m(cos θ) sin^m θ · dω, per column the
    (cos mφ, sin mφ) part, contracted with two matrix products (O(H W (2 l_max + 1) C)).

    Parameters
    ----------
    image : array_like, shape (H, W, C) or (H, W)
        Radiance, top row first (as stored in OpenEXR); column c ↔ φ = 2π(½ − (c+½)/W),
        row r ↔ θ = π (r + ½)/H (see ``docs/conventions.md``).
    l_max : int
    return_info : bool, optional
        If True, also return ``{"rejected_pixels": n}``.

    Returns
    -------
    coeffs : ndarray, shape ((l_max+1)², C), or ((l_max+1)²,) for a 2-D ``image``
    info : dict, only if ``return_info``
        ``rejected_pixels``: number of pixels with a NaN or ±Inf in any channel; they get
        weight 0 (the projection then slightly underestimates the environment there).
    """
    l_max = check_l_max(l_max)
    img = np.asarray(image)
    if img.ndim not in (2, 3) or img.shape[0] < 1 or img.shape[1] < 1:
        raise ValueError(f"image must have shape (H, W, C) or (H, W), got {img.shape}")
    try:
        img = img.astype(np.float64, copy=False)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"image must be numeric, got dtype {img.dtype}") from exc
    squeeze = img.ndim == 2
    if squeeze:
        img = img[..., None]
    height, width, _ = img.shape

    # Row part: N_l^m(cos θ_r) · sin^m θ_r · dω_r (dω_r includes the 2π/W column width).
    cos_t, sin_t = equirect_polar(height)
    legendre = legendre_sin_free_normalised(l_max, cos_t)  # (H, n_lm)
    sin_pow = sin_t[:, None] ** np.arange(l_max + 1)  # (H, l_max+1)
    row_weight = equirect_row_solid_angles(height, width)  # (H,)
    # Column part: cos(mφ_c), sin(mφ_c) (unit-circle version of C_m, S_m).
    phi = equirect_azimuths(width)
    m = np.arange(l_max + 1)
    trig = np.concatenate([np.cos(phi[:, None] * m), np.sin(phi[:, None] * m[1:])], axis=1)  # (W, 2l+1)
    # A[r, k, ch] = Σ_c trig[c, k] L[r, c, ch]  (batched matmul, the only O(H W) step).
    with np.errstate(invalid="ignore", over="ignore"):  # NaN/Inf pixels are handled just below
        col = np.matmul(trig.T, img)  # (H, 2l+1, C)
    # Any NaN/Inf pixel makes its row's m = 0 sum (trig = 1) non-finite, so a finite result
    # proves the image clean without a separate O(H W C) scan; otherwise mask and redo.
    rejected = 0
    if not np.all(np.isfinite(col[:, 0])):
        good = np.isfinite(img).all(axis=-1)
        rejected = int(good.size - np.count_nonzero(good))
        col = np.matmul(trig.T, np.where(good[..., None], img, 0.0))
    # Row factors B[r, i] = (√2 or 1) N_l^m(cos θ_r) sin^|m| θ_r dω_r, assembled exactly like
    # the basis (same ±m bookkeeping), then contracted with the matching column sum.
    row_part = row_weight[:, None] * sin_pow
    rows = assemble(l_max, legendre, row_part, row_part)  # (H, (l_max+1)²)
    l_idx = band_of_index(l_max)
    m_idx = np.arange((l_max + 1) ** 2) - l_idx * (l_idx + 1)
    k_idx = np.where(m_idx >= 0, m_idx, l_max - m_idx)  # column of cos(mφ) or sin(|m|φ) in trig
    coeffs = np.einsum("hi,hic->ic", rows, col[:, k_idx])
    if squeeze:
        coeffs = coeffs[:, 0]
    if return_info:
        return coeffs, {"rejected_pixels": rejected}
    return coeffs
