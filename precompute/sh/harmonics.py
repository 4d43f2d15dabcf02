"""Real spherical harmonics: the basis, its convention and its indexing.

One convention, written once (binding, see ``docs/conventions.md``):

- real, orthonormal over the unit sphere, ∫ Y_i Y_j dω = δ_ij, flat index i = l(l+1) + m;
- **no Condon–Shortley phase**; with θ the polar angle from +z and φ = atan2(y, x),

  ==========  ===============================================
  m > 0       Y_l^m  = √2 K_l^m P_l^m(cos θ) cos(m φ)
  m = 0       Y_l^0  =    K_l^0 P_l(cos θ)
  m < 0       Y_l^m  = √2 K_l^|m| P_l^|m|(cos θ) sin(|m| φ)
  ==========  ===============================================

  with K_l^m = √((2l+1)/(4π) · (l−m)!/(l+m)!) and P_l^m(z) = (1−z²)^{m/2} d^m P_l(z)/dz^m,
  the associated Legendre function *without* the (−1)^m factor (so P_1^1 = +sin θ).

  Closed forms of the first bands (x, y, z a unit direction):

  - Y_0^0 = 1/(2√π) = √(1/4π) ≈ 0.282095;
  - (Y_1^{−1}, Y_1^0, Y_1^1) = √(3/4π) · (y, z, x), √(3/4π) ≈ 0.488603;
  - Y_2^{−2} = ½√(15/π) x y, Y_2^{−1} = ½√(15/π) y z, Y_2^0 = ¼√(5/π) (3z² − 1),
    Y_2^1 = ½√(15/π) x z, Y_2^2 = ¼√(15/π) (x² − y²).

- ``rotation(l_max, R) @ c`` gives the coefficients of f∘R⁻¹ (the function turned by R).

The basis is evaluated without any angle: the polar part is the "sin-free" normalised Legendre
function N_l^m(z) = K_l^m P_l^m(z) / sin^m θ (a polynomial in z), and the azimuthal part is
Re/Im (x + i y)^m = sin^m θ · (cos mφ, sin mφ), both from stable recurrences. The poles are
therefore exact and no ``atan2`` is needed.

References
----------
.. [RH01] R. Ramamoorthi and P. Hanrahan, "An Efficient Representation for Irradiance
   Environment Maps", SIGGRAPH 2001.
.. [IR96] J. Ivanic and K. Ruedenberg, "Rotation Matrices for Real Spherical Harmonics.
   Direct Determination by Recursion", J. Phys. Chem. 100 (1996) 6342–6347; Additions and
   Corrections, J. Phys. Chem. A 102 (1998) 9099–9100.
.. [Slo08] P.-P. Sloan, "Stupid Spherical Harmonics (SH) Tricks", GDC 2008.
.. [Hob31] E. W. Hobson, "The Theory of Spherical and Ellipsoidal Harmonics", 1931
   (three-term Legendre recurrences).
"""

from __future__ import annotations

import math

import numpy as np

from .. import _checks

__all__ = [
    "MAX_L_MAX",
    "assemble",
    "band_of_index",
    "basis",
    "basis_from_angles",
    "basis_nonnegative_m",
    "check_l_max",
    "coeff_array",
    "evaluate",
    "l_max_from_size",
    "legendre_sin_free_normalised",
    "num_coefficients",
    "unit_directions",
]

#: Largest supported band. The recurrences are stable well beyond this; the cap only stops
#: accidental huge allocations ((l_max+1)² coefficients per direction, (2l+1)² per rotation
#: block). Tested to 1e-12 against scipy up to l = 8 and for orthonormality up to l = 16.
MAX_L_MAX = 64

#: Directions shorter than this are rejected instead of normalised: a zero (or denormal)
#: vector has no direction, and dividing by it would return NaN or amplify noise by > 1e12.
MIN_DIRECTION_NORM = 1e-12

_FOUR_PI = 4.0 * math.pi


# ----------------------------------------------------------------------------------------------
# Validation helpers
# ----------------------------------------------------------------------------------------------


def check_l_max(l_max) -> int:
    """``l_max`` as an int in 0 … :data:`MAX_L_MAX`, else ``ValueError`` naming it."""
    return _checks.positive_int("l_max", l_max, minimum=0, maximum=MAX_L_MAX)


def num_coefficients(l_max: int) -> int:
    """Number of real SH coefficients up to band ``l_max``: (l_max + 1)²."""
    l_max = check_l_max(l_max)
    return (l_max + 1) ** 2


def l_max_from_size(size: int, name: str = "coeffs") -> int:
    """Inverse of :func:`num_coefficients`; raise ``ValueError`` if ``size`` is not a square."""
    root = math.isqrt(int(size))
    if root * root != size or root == 0:
        raise ValueError(f"{name} must have (l_max+1)² entries on its first axis, got {size}")
    return root - 1


def unit_directions(directions, name: str = "directions") -> np.ndarray:
    """Return ``directions`` (..., 3) normalised, raising on NaN/Inf, wrong shape or zero length."""
    d = _checks.finite_array(name, directions)
    if d.ndim == 0 or d.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., 3), got {d.shape}")
    norm = np.linalg.norm(d, axis=-1, keepdims=True)
    if np.any(norm < MIN_DIRECTION_NORM):
        raise ValueError(f"{name} contains {int(np.sum(norm < MIN_DIRECTION_NORM))} zero-length vectors")
    return d / norm


def coeff_array(coeffs, name: str = "coeffs") -> tuple[np.ndarray, int]:
    """(``coeffs`` as a finite float array, its l_max from the first axis), else ``ValueError``."""
    c = _checks.finite_array(name, coeffs)
    if c.ndim == 0:
        raise ValueError(f"{name} must have (l_max+1)² entries on its first axis, got a scalar")
    return c, l_max_from_size(c.shape[0], name)


def band_of_index(l_max: int) -> np.ndarray:
    """Band l of every flat index i = l(l+1) + m, shape ((l_max+1)²,)."""
    return np.repeat(np.arange(l_max + 1), 2 * np.arange(l_max + 1) + 1)


# ----------------------------------------------------------------------------------------------
# Basis
# ----------------------------------------------------------------------------------------------


def legendre_sin_free_normalised(l_max: int, z: np.ndarray) -> np.ndarray:
    """N_l^m(z) = K_l^m P_l^m(z) / sin^m θ for 0 ≤ m ≤ l ≤ l_max, stacked on a new last axis.

    Parameters
    ----------
    l_max : int
    z : ndarray
        cos θ, any shape, in [−1, 1].

    Returns
    -------
    ndarray, shape z.shape + ((l_max+1)(l_max+2)/2,)
        Entry l(l+1)/2 + m holds N_l^m(z) (a polynomial of degree l − m in z).

    Notes
    -----
    Fully normalised recurrences (no overflow of (2m−1)!! or (l+m)!) [Hob31]_:

    - N_0^0 = 1/√(4π);  N_m^m = √((2m+1)/(2m)) N_{m−1}^{m−1}  (diagonal; sin θ factored out);
    - N_{m+1}^m = √(2m+3) z N_m^m;
    - N_l^m = a_l^m (z N_{l−1}^m − b_l^m N_{l−2}^m),
      a_l^m = √((4l²−1)/(l²−m²)), b_l^m = √(((l−1)²−m²)/(4(l−1)²−1)).
    """
    out = np.empty(z.shape + ((l_max + 1) * (l_max + 2) // 2,))

    def idx(l, m):
        return l * (l + 1) // 2 + m

    diag = 1.0 / math.sqrt(_FOUR_PI)
    for m in range(l_max + 1):
        if m > 0:
            diag *= math.sqrt((2 * m + 1) / (2 * m))
        out[..., idx(m, m)] = diag
        if m + 1 <= l_max:
            out[..., idx(m + 1, m)] = math.sqrt(2 * m + 3) * z * diag
        for l in range(m + 2, l_max + 1):
            a = math.sqrt((4 * l * l - 1) / (l * l - m * m))
            b = math.sqrt(((l - 1) ** 2 - m * m) / (4 * (l - 1) ** 2 - 1))
            out[..., idx(l, m)] = a * (z * out[..., idx(l - 1, m)] - b * out[..., idx(l - 2, m)])
    return out


def _azimuthal_harmonics(l_max: int, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """C_m = Re (x + i y)^m and S_m = Im (x + i y)^m for m = 0 … l_max (last axis).

    For a unit direction, (x + i y)^m = sin^m θ · e^{i m φ}, so C_m = sin^m θ cos mφ and
    S_m = sin^m θ sin mφ. Recurrence (complex multiplication by x + i y):
    C_m = x C_{m−1} − y S_{m−1},  S_m = x S_{m−1} + y C_{m−1}.
    """
    c = np.empty(x.shape + (l_max + 1,))
    s = np.empty(x.shape + (l_max + 1,))
    c[..., 0] = 1.0
    s[..., 0] = 0.0
    for m in range(1, l_max + 1):
        c[..., m] = x * c[..., m - 1] - y * s[..., m - 1]
        s[..., m] = x * s[..., m - 1] + y * c[..., m - 1]
    return c, s


def assemble(l_max: int, legendre: np.ndarray, cos_part: np.ndarray, sin_part: np.ndarray) -> np.ndarray:
    """Combine N_l^m, cos-part and sin-part into Y at flat index l(l+1)+m (see module docstring)."""
    shape = np.broadcast_shapes(legendre.shape[:-1], cos_part.shape[:-1])
    out = np.empty(shape + ((l_max + 1) ** 2,))
    sqrt2 = math.sqrt(2.0)
    for l in range(l_max + 1):
        centre = l * (l + 1)
        base = l * (l + 1) // 2
        out[..., centre] = legendre[..., base] * cos_part[..., 0]
        for m in range(1, l + 1):
            n_lm = sqrt2 * legendre[..., base + m]
            out[..., centre + m] = n_lm * cos_part[..., m]
            out[..., centre - m] = n_lm * sin_part[..., m]
    return out


def basis(l_max: int, directions) -> np.ndarray:
    """Real orthonormal SH (no Condon–Shortley phase) evaluated at ``directions``.

    Parameters
    ----------
    l_max : int
        Highest band, 0 ≤ l_max ≤ :data:`MAX_L_MAX`.
    directions : array_like, shape (..., 3)
        Direction vectors (normalised here; zero-length, NaN or Inf raise ``ValueError``).

    Returns
    -------
    ndarray, shape (..., (l_max+1)²)
        Y_i(ω) at flat index i = l(l+1) + m (unit: sr^−½, so that ∫ Y_i² dω = 1).

    Examples
    --------
    Band 1 is √(3/4π)·(y, z, x): ``basis(1, [1, 0, 0])[3] == sqrt(3/(4π))``.
    """
    l_max = check_l_max(l_max)
    d = unit_directions(directions)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    legendre = legendre_sin_free_normalised(l_max, z)
    cos_part, sin_part = _azimuthal_harmonics(l_max, x, y)
    return assemble(l_max, legendre, cos_part, sin_part)


def basis_from_angles(l_max: int, cos_theta, phi) -> np.ndarray:
    """:func:`basis` at spherical angles: θ polar from +z (given as cos θ ∈ [−1, 1]), φ = atan2(y, x).

    Parameters
    ----------
    l_max : int
    cos_theta : array_like
        cos θ in [−1, 1]; broadcasts against ``phi``.
    phi : array_like
        Azimuth in radians.

    Returns
    -------
    ndarray, shape broadcast(cos_theta, phi).shape + ((l_max+1)²,)
    """
    cos_theta = _checks.in_range("cos_theta", _checks.finite_array("cos_theta", cos_theta), -1.0, 1.0)
    phi = _checks.finite_array("phi", phi)
    cos_theta, phi = np.broadcast_arrays(cos_theta, phi)
    sin_theta = np.sqrt(np.maximum(0.0, 1.0 - cos_theta * cos_theta))
    d = np.stack([sin_theta * np.cos(phi), sin_theta * np.sin(phi), cos_theta], axis=-1)
    return basis(l_max, d)


def basis_nonnegative_m(l_max: int, directions, weights=None) -> np.ndarray:
    """The m ≥ 0 rows of :func:`basis`, one row per function: shape ((L+1)(L+2)/2, N).

    Row l(l+1)/2 + m holds w_n Y_l^m(ω_n) at the N ``directions`` (N, 3) (l then m, as the bake
    keeps them; ``weights`` w (N,) default 1), equal to ``basis(l_max, directions)[:, [l(l+1)+m
    …]].T * w``. The same recurrences, but each written as a contiguous row (the bake's kernel
    multiplies rows against its nodes), so no strided column writes and no m < 0 half; the
    recurrence in l is linear in its seed, so w multiplies the seeds only.
    """
    l_max = check_l_max(l_max)
    d = unit_directions(directions).reshape(-1, 3)
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    out = np.empty(((l_max + 1) * (l_max + 2) // 2, z.size))
    # w Re (x + i y)^m and w Im (x + i y)^m
    cos_m = np.ones_like(z) if weights is None else np.array(weights, dtype=float).reshape(-1)
    sin_m = np.zeros_like(z)
    diag = 1.0 / math.sqrt(_FOUR_PI)
    for m in range(l_max + 1):
        if m > 0:
            diag *= math.sqrt((2 * m + 1) / (2 * m))
            cos_m, sin_m = x * cos_m - y * sin_m, x * sin_m + y * cos_m
        row = cos_m * (diag if m == 0 else math.sqrt(2.0) * diag)  # N_m^m (√2 cos mφ) sin^m θ
        out[m * (m + 1) // 2 + m] = row
        prev2, prev1 = None, row
        for l in range(m + 1, l_max + 1):
            if l == m + 1:
                cur = math.sqrt(2 * m + 3) * z * prev1
            else:
                a = math.sqrt((4 * l * l - 1) / (l * l - m * m))
                b = math.sqrt(((l - 1) ** 2 - m * m) / (4 * (l - 1) ** 2 - 1))
                cur = a * (z * prev1 - b * prev2)
            out[l * (l + 1) // 2 + m] = cur
            prev2, prev1 = prev1, cur
    return out


def evaluate(coeffs, directions) -> np.ndarray:
    """Reconstruct f(ω) = Σ_i c_i Y_i(ω).

    Parameters
    ----------
    coeffs : array_like, shape ((l_max+1)²,) or ((l_max+1)², C)
    directions : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (...,) or (..., C)
    """
    c, l_max = coeff_array(coeffs)
    return basis(l_max, directions) @ c
