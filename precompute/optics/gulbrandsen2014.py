"""Blender's metallic Principled BSDF as a complex index: Gulbrandsen (2014) per channel.

Blender's metal is the F82-tint model: F0 = Base Color, and the reflectance at cos θ = 1/7
(:data:`F82_COS`) is Specular Tint × Schlick(F0, 1/7). :func:`conductor_from_rgb` turns that
into a tabulated complex index (Gulbrandsen's fit per channel, placed at
:data:`RGB_WAVELENGTHS_NM`): how the spectral colour mode sees such a metal. (The
Cycles-matching mode evaluates the F82-tint model itself: precompute/colour/film_channels.py.)
``precompute.materials.conductors`` re-exports everything here.

References
----------
O. Gulbrandsen (2014), "Artist Friendly Metallic Fresnel", Journal of Computer Graphics
Techniques 3(4), 64–72.
C. Schlick (1994), "An Inexpensive BRDF Model for Physically-based Rendering", Computer
Graphics Forum 13(3), 233–246.
"""

from __future__ import annotations

import numpy as np

from ..constants import WAVELENGTH_MAX_NM, WAVELENGTH_MIN_NM

__all__ = [
    "F82_COS",
    "RGB_WAVELENGTHS_NM",
    "conductor_from_rgb",
    "fresnel_conductor",
    "gulbrandsen_nk",
    "schlick",
]

#: Wavelengths (nm) standing for the R, G and B channels when an RGB conductor fit becomes a
#: spectral table (roughly the dominant wavelengths of the Rec.709 primaries).
RGB_WAVELENGTHS_NM = (465.0, 550.0, 610.0)
#: cos θ of the F82 edge-tint angle (θ ≈ 81.8°, cos θ = 1/7) of Blender's metallic Fresnel.
F82_COS = 1.0 / 7.0


def gulbrandsen_nk(reflectivity, edge_tint) -> tuple[np.ndarray, np.ndarray]:
    """Complex index (n, k) from normal-incidence reflectivity r and edge tint g, per channel.

    O. Gulbrandsen (2014), "Artist Friendly Metallic Fresnel", Journal of Computer Graphics
    Techniques 3(4), 64–72: with n_min = (1 − r)/(1 + r) and n_max = (1 + √r)/(1 − √r),

        n = g·n_min + (1 − g)·n_max,   k = √[(r(n + 1)² − (n − 1)²) / (1 − r)],

    which reproduces F(0°) = ((n − 1)² + k²)/((n + 1)² + k²) = r exactly for any g in [0, 1].
    r is clamped to [0, 0.99] (the formula diverges at 1) and g to [0, 1].
    """
    r = np.clip(np.asarray(reflectivity, dtype=float), 0.0, 0.99)
    g = np.clip(np.asarray(edge_tint, dtype=float), 0.0, 1.0)
    root = np.sqrt(r)
    n_min = (1.0 - r) / (1.0 + r)
    n_max = (1.0 + root) / (1.0 - root)
    n = g * n_min + (1.0 - g) * n_max
    k = np.sqrt(np.maximum(0.0, (r * (n + 1.0) ** 2 - (n - 1.0) ** 2) / (1.0 - r)))
    return n, k


def fresnel_conductor(n, k, cos_i) -> np.ndarray:
    """Unpolarised Fresnel reflectance from air into N = n + ik at incidence cosine ``cos_i``.

    R = ½(|r_s|² + |r_p|²) with q = √(N² − sin²θ), r_s = (cos θ − q)/(cos θ + q) and
    r_p = (N² cos θ − q)/(N² cos θ + q); broadcasting.
    """
    eta = np.asarray(n, dtype=complex) + 1j * np.asarray(k, dtype=float)
    cos_i = np.asarray(cos_i, dtype=float)
    eta2 = eta * eta
    q = np.sqrt(eta2 - (1.0 - cos_i * cos_i))
    rs = (cos_i - q) / (cos_i + q)
    rp = (eta2 * cos_i - q) / (eta2 * cos_i + q)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


def schlick(f0, cos_i):
    """Schlick's (1994) approximation F0 + (1 − F0)(1 − cos θ)⁵."""
    return f0 + (1.0 - f0) * (1.0 - cos_i) ** 5


def conductor_from_rgb(base_color, specular_tint=(1.0, 1.0, 1.0)) -> dict:
    """A tabulated-index spec approximating Principled's metal for ``base_color`` (per channel).

    Blender's metallic Fresnel is the F82-tint model: F0 = Base Color, and the reflectance at
    cos θ = 1/7 is Specular Tint × Schlick(F0, 1/7). Gulbrandsen's formula fixes F0; the edge
    tint g of each channel is chosen (grid search on [0, 1]) so that the conductor's Fresnel at
    cos θ = 1/7 is as close as it gets to that F82 value. The three (n, k) pairs are placed at
    :data:`RGB_WAVELENGTHS_NM` and held flat beyond them (360–830 nm).
    """
    r = np.clip(np.asarray(base_color, dtype=float)[:3], 0.0, 0.99)
    tint = np.clip(np.asarray(specular_tint, dtype=float)[:3], 0.0, 1.0)
    target = tint * schlick(r, F82_COS)
    grid = np.linspace(0.0, 1.0, 401)
    n, k = gulbrandsen_nk(r[None, :], grid[:, None])  # (G, 3)
    f82 = fresnel_conductor(n, k, F82_COS)
    best = np.argmin(np.abs(f82 - target[None, :]), axis=0)
    n_rgb, k_rgb = n[best, [0, 1, 2]], k[best, [0, 1, 2]]
    # Channels ordered R, G, B; the table runs from blue to red.
    n_bgr = [round(float(v), 6) for v in n_rgb[::-1]]
    k_bgr = [round(float(v), 6) for v in k_rgb[::-1]]
    wl = [WAVELENGTH_MIN_NM, *RGB_WAVELENGTHS_NM, WAVELENGTH_MAX_NM]
    return {
        "table": {
            "wavelengths_nm": [float(w) for w in wl],
            "n": [n_bgr[0], *n_bgr, n_bgr[-1]],
            "k": [k_bgr[0], *k_bgr, k_bgr[-1]],
        }
    }
