"""Zonal kernels: the clamped cosine (irradiance [RH01]_), convolution (Funk–Hecke) and a zonal
function turned to a direction [Slo08]_.

References
----------
.. [RH01] R. Ramamoorthi and P. Hanrahan, "An Efficient Representation for Irradiance
   Environment Maps", SIGGRAPH 2001.
.. [Slo08] P.-P. Sloan, "Stupid Spherical Harmonics (SH) Tricks", GDC 2008.
"""

from __future__ import annotations

import math

import numpy as np

from .. import _checks
from .harmonics import band_of_index, basis, check_l_max, coeff_array, unit_directions

__all__ = ["clamped_cosine_zh", "convolve_zonal", "irradiance_coefficients", "zonal_rotation"]

_FOUR_PI = 4.0 * math.pi


def clamped_cosine_zh(l_max: int) -> np.ndarray:
    """Â_l, the clamped-cosine convolution factors of Ramamoorthi & Hanrahan [RH01]_ (eq. 8–9).

    E_lm = Â_l L_lm turns radiance coefficients into irradiance coefficients.

    - Â_0 = π, Â_1 = 2π/3;
    - odd l > 1: Â_l = 0;
    - even l: Â_l = 2π (−1)^{l/2−1} / ((l+2)(l−1)) · l! / (2^l ((l/2)!)²)  (Â_2 = π/4, Â_4 = −π/24).

    Returns
    -------
    ndarray, shape (l_max+1,), dimensionless (sr).
    """
    l_max = check_l_max(l_max)
    out = np.zeros(l_max + 1)
    for l in range(l_max + 1):
        if l == 1:
            out[l] = 2.0 * math.pi / 3.0
        elif l % 2 == 0:
            sign = -1.0 if (l // 2 - 1) % 2 else 1.0
            # l!/(2^l ((l/2)!)²) = C(l, l/2)/2^l, exact in integers before the division.
            central = math.comb(l, l // 2) / 2.0**l
            out[l] = 2.0 * math.pi * sign / ((l + 2) * (l - 1)) * central
    return out


def irradiance_coefficients(radiance_coeffs) -> np.ndarray:
    """Irradiance E_lm = Â_l L_lm from radiance coefficients L_lm [RH01]_.

    Parameters
    ----------
    radiance_coeffs : array_like, shape ((l_max+1)², ...)
        Radiance L (W m⁻² sr⁻¹ or any linear unit) in SH.

    Returns
    -------
    ndarray, same shape: irradiance coefficients; :func:`evaluate` gives E(n) in W m⁻².
    """
    c, l_max = coeff_array(radiance_coeffs, "radiance_coeffs")
    a_hat = clamped_cosine_zh(l_max)[band_of_index(l_max)]
    return c * a_hat.reshape((-1,) + (1,) * (c.ndim - 1))


def _funk_hecke_factor(l_max: int) -> np.ndarray:
    """√(4π/(2l+1)) for l = 0 … l_max (Funk–Hecke: convolution with a zonal kernel)."""
    l = np.arange(l_max + 1)
    return np.sqrt(_FOUR_PI / (2 * l + 1))


def _check_zonal(zonal, l_max: int | None = None) -> np.ndarray:
    z = _checks.finite_array("zonal", zonal)
    if z.ndim != 1:
        raise ValueError(f"zonal must be 1-D (one coefficient per band), got shape {z.shape}")
    if l_max is not None and z.shape[0] < l_max + 1:
        raise ValueError(f"zonal must have ≥ {l_max + 1} entries (one per band), got {z.shape[0]}")
    return z


def convolve_zonal(coeffs, zonal) -> np.ndarray:
    """Convolve f with a zonal (rotationally symmetric about +z) kernel k (Funk–Hecke).

    (k ⋆ f)_lm = √(4π/(2l+1)) z_l f_lm, with z_l = ∫ k Y_l^0 dω the kernel's zonal
    coefficients. With z_l the clamped cosine's ZH this equals :func:`irradiance_coefficients`.

    Parameters
    ----------
    coeffs : array_like, shape ((l_max+1)², ...)
    zonal : array_like, shape (≥ l_max+1,)
        Zonal coefficients z_l (extra entries ignored).
    """
    c, l_max = coeff_array(coeffs)
    z = _check_zonal(zonal, l_max)[: l_max + 1]
    factor = (_funk_hecke_factor(l_max) * z)[band_of_index(l_max)]
    return c * factor.reshape((-1,) + (1,) * (c.ndim - 1))


def zonal_rotation(zonal, direction) -> np.ndarray:
    """Full coefficients of a zonal function whose axis is turned from +z to ``direction``.

    c_lm = √(4π/(2l+1)) z_l Y_lm(d) [Slo08]_ (the addition theorem).

    Parameters
    ----------
    zonal : array_like, shape (l_max+1,)
    direction : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., (l_max+1)²)
    """
    z = _check_zonal(zonal)
    l_max = z.shape[0] - 1
    check_l_max(l_max)
    factor = (_funk_hecke_factor(l_max) * z)[band_of_index(l_max)]
    return basis(l_max, unit_directions(direction, "direction")) * factor
