"""Real spherical harmonics: basis, projection, rotation, windowing and irradiance.

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
from ..world.hdri import equirect_azimuths, equirect_polar, equirect_row_solid_angles

__all__ = [
    "MAX_L_MAX",
    "apply_window",
    "basis",
    "basis_from_angles",
    "basis_nonnegative_m",
    "clamped_cosine_zh",
    "convolve_zonal",
    "evaluate",
    "irradiance_coefficients",
    "l_max_from_size",
    "num_coefficients",
    "project",
    "project_equirect",
    "rotate",
    "rotation",
    "rotation_bands",
    "rotation_z",
    "window",
    "zonal_rotation",
]

#: Largest supported band. The recurrences are stable well beyond this; the cap only stops
#: accidental huge allocations ((l_max+1)² coefficients per direction, (2l+1)² per rotation
#: block). Tested to 1e-12 against scipy up to l = 8 and for orthonormality up to l = 16.
MAX_L_MAX = 64

#: Directions shorter than this are rejected instead of normalised: a zero (or denormal)
#: vector has no direction, and dividing by it would return NaN or amplify noise by > 1e12.
MIN_DIRECTION_NORM = 1e-12

#: Orthogonality tolerance for rotation matrices: ‖RᵀR − I‖_max and |det R − 1| must be below
#: it. 1e-6 accepts matrices built in float32 (ε ≈ 6e-8 per entry, a few ulps after products)
#: while rejecting scalings, shears and reflections.
ROTATION_TOLERANCE = 1e-6

#: A rotation whose z-column and z-row are (0, 0, 1) to within this is treated as a pure turn
#: about z and takes the cos/sin fast path. At 1e-14 the neglected tilt changes a coefficient
#: by at most ~l·1e-14, far below the 1e-10 at which the paths are compared.
Z_ROTATION_EPS = 1e-14

_FOUR_PI = 4.0 * math.pi


# ----------------------------------------------------------------------------------------------
# Validation helpers
# ----------------------------------------------------------------------------------------------


def _check_l_max(l_max) -> int:
    return _checks.positive_int("l_max", l_max, minimum=0, maximum=MAX_L_MAX)


def num_coefficients(l_max: int) -> int:
    """Number of real SH coefficients up to band ``l_max``: (l_max + 1)²."""
    l_max = _check_l_max(l_max)
    return (l_max + 1) ** 2


def l_max_from_size(size: int, name: str = "coeffs") -> int:
    """Inverse of :func:`num_coefficients`; raise ``ValueError`` if ``size`` is not a square."""
    root = math.isqrt(int(size))
    if root * root != size or root == 0:
        raise ValueError(f"{name} must have (l_max+1)² entries on its first axis, got {size}")
    return root - 1


def _unit_directions(directions, name: str = "directions") -> np.ndarray:
    """Return ``directions`` (..., 3) normalised, raising on NaN/Inf, wrong shape or zero length."""
    d = _checks.finite_array(name, directions)
    if d.ndim == 0 or d.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., 3), got {d.shape}")
    norm = np.linalg.norm(d, axis=-1, keepdims=True)
    if np.any(norm < MIN_DIRECTION_NORM):
        raise ValueError(f"{name} contains {int(np.sum(norm < MIN_DIRECTION_NORM))} zero-length vectors")
    return d / norm


def _coeff_array(coeffs, name: str = "coeffs") -> tuple[np.ndarray, int]:
    c = _checks.finite_array(name, coeffs)
    if c.ndim == 0:
        raise ValueError(f"{name} must have (l_max+1)² entries on its first axis, got a scalar")
    return c, l_max_from_size(c.shape[0], name)


def _band_of_index(l_max: int) -> np.ndarray:
    """Band l of every flat index i = l(l+1) + m, shape ((l_max+1)²,)."""
    return np.repeat(np.arange(l_max + 1), 2 * np.arange(l_max + 1) + 1)


# ----------------------------------------------------------------------------------------------
# Basis
# ----------------------------------------------------------------------------------------------


def _legendre_sin_free_normalised(l_max: int, z: np.ndarray) -> np.ndarray:
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


def _assemble(l_max: int, legendre: np.ndarray, cos_part: np.ndarray, sin_part: np.ndarray) -> np.ndarray:
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
    l_max = _check_l_max(l_max)
    d = _unit_directions(directions)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    legendre = _legendre_sin_free_normalised(l_max, z)
    cos_part, sin_part = _azimuthal_harmonics(l_max, x, y)
    return _assemble(l_max, legendre, cos_part, sin_part)


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
    l_max = _check_l_max(l_max)
    d = _unit_directions(directions).reshape(-1, 3)
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
    c, l_max = _coeff_array(coeffs)
    return basis(l_max, directions) @ c


# ----------------------------------------------------------------------------------------------
# Projection
# ----------------------------------------------------------------------------------------------


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
    l_max = _check_l_max(l_max)
    d = _unit_directions(directions)
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
    l_max = _check_l_max(l_max)
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
    legendre = _legendre_sin_free_normalised(l_max, cos_t)  # (H, n_lm)
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
    rows = _assemble(l_max, legendre, row_part, row_part)  # (H, (l_max+1)²)
    l_idx = _band_of_index(l_max)
    m_idx = np.arange((l_max + 1) ** 2) - l_idx * (l_idx + 1)
    k_idx = np.where(m_idx >= 0, m_idx, l_max - m_idx)  # column of cos(mφ) or sin(|m|φ) in trig
    coeffs = np.einsum("hi,hic->ic", rows, col[:, k_idx])
    if squeeze:
        coeffs = coeffs[:, 0]
    if return_info:
        return coeffs, {"rejected_pixels": rejected}
    return coeffs


# ----------------------------------------------------------------------------------------------
# Rotation
# ----------------------------------------------------------------------------------------------


def _check_rotation(matrix) -> np.ndarray:
    r = _checks.finite_array("R", matrix)
    if r.shape != (3, 3):
        raise ValueError(f"R must be a 3×3 matrix, got shape {r.shape}")
    ortho = np.max(np.abs(r.T @ r - np.eye(3)))
    if ortho > ROTATION_TOLERANCE:
        raise ValueError(f"R must be orthogonal (max |RᵀR − I| = {ortho:.3g} > {ROTATION_TOLERANCE})")
    det = np.linalg.det(r)
    if abs(det - 1.0) > ROTATION_TOLERANCE:
        raise ValueError(f"R must be a proper rotation with det +1, got det = {det:.6g}")
    return r


def _band1_ivanic_ruedenberg(r: np.ndarray) -> np.ndarray:
    """Band-1 block R^1_{mn}, m, n ∈ {−1, 0, 1}: the 3×3 rotation in the (y, z, x) order [IR96]_.

    Since (Y_1^{−1}, Y_1^0, Y_1^1) ∝ (y, z, x), the coefficients of f∘R⁻¹ are P R Pᵀ c with P
    the permutation x, y, z → y, z, x.
    """
    perm = [1, 2, 0]
    return r[np.ix_(perm, perm)]


def _z_rotation_angle(r: np.ndarray) -> float | None:
    """Angle α if ``r`` is a pure rotation about +z (to :data:`Z_ROTATION_EPS`), else None."""
    off = max(abs(r[0, 2]), abs(r[1, 2]), abs(r[2, 0]), abs(r[2, 1]), abs(r[2, 2] - 1.0))
    if off > Z_ROTATION_EPS:
        return None
    return math.atan2(r[1, 0], r[0, 0])


def _z_band(l: int, angle: float) -> np.ndarray:
    """Band-l block of a rotation by ``angle`` about z.

    f∘R⁻¹ turns cos mφ, sin mφ into cos m(φ−α), sin m(φ−α), so the ±m coefficient pair
    (c_m, s_m) maps to (c cos mα − s sin mα, c sin mα + s cos mα).
    """
    block = np.zeros((2 * l + 1, 2 * l + 1))
    block[l, l] = 1.0
    for m in range(1, l + 1):
        c, s = math.cos(m * angle), math.sin(m * angle)
        pos, neg = l + m, l - m  # rows of the cos (m > 0) and sin (m < 0) coefficients
        block[pos, pos] = c
        block[pos, neg] = -s
        block[neg, pos] = s
        block[neg, neg] = c
    return block


def _ivanic_ruedenberg_uvw(l: int, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Coefficients u, v, w of [IR96]_ Table 1 (with the 1998 errata), vectors over n = −l … l."""
    n = np.arange(-l, l + 1)
    denom = np.where(np.abs(n) == l, 2.0 * l * (2 * l - 1), (l + n) * (l - n)).astype(float)
    am = abs(m)
    d0 = 1.0 if m == 0 else 0.0
    u = np.sqrt((l + m) * (l - m) / denom)
    v = 0.5 * np.sqrt((1.0 + d0) * (l + am - 1) * (l + am) / denom) * (1.0 - 2.0 * d0)
    w = -0.5 * np.sqrt(max(0, (l - am - 1) * (l - am)) / denom) * (1.0 - d0)
    return u, v, w


def _ivanic_ruedenberg_band(l: int, r1: np.ndarray, prev: np.ndarray) -> np.ndarray:
    """Band-l block from the band-1 block ``r1`` and the band-(l−1) block ``prev`` [IR96]_.

    R^l_{mn} = u_{mn} U_{mn} + v_{mn} V_{mn} + w_{mn} W_{mn} with the helper
    P_i(a, b) = R^1_{i0} R^{l−1}_{ab} (|b| < l),
    P_i(a, l) = R^1_{i1} R^{l−1}_{a,l−1} − R^1_{i,−1} R^{l−1}_{a,−l+1},
    P_i(a, −l) = R^1_{i1} R^{l−1}_{a,−l+1} + R^1_{i,−1} R^{l−1}_{a,l−1},
    evaluated here for all n at once. Our basis (no Condon–Shortley phase, sin for m < 0)
    is the one [IR96]_ use, so the published recurrence applies unchanged; tests confirm
    project(f∘R⁻¹) = R @ project(f) to 1e-10.
    """

    def p_row(i: int, a: int) -> np.ndarray:
        row = prev[a + l - 1]  # R^{l−1}_{a, ·}, length 2l − 1
        out = np.empty(2 * l + 1)
        out[1:-1] = r1[i + 1, 1] * row
        out[-1] = r1[i + 1, 2] * row[-1] - r1[i + 1, 0] * row[0]
        out[0] = r1[i + 1, 2] * row[0] + r1[i + 1, 0] * row[-1]
        return out

    block = np.empty((2 * l + 1, 2 * l + 1))
    sqrt2 = math.sqrt(2.0)
    for m in range(-l, l + 1):
        u, v, w = _ivanic_ruedenberg_uvw(l, m)
        row = np.zeros(2 * l + 1)
        if abs(m) < l:
            row += u * p_row(0, m)
        if m == 0:
            big_v = p_row(1, 1) + p_row(-1, -1)
        elif m > 0:
            big_v = p_row(1, m - 1) * (sqrt2 if m == 1 else 1.0)
            if m != 1:
                big_v = big_v - p_row(-1, -m + 1)
        else:
            big_v = p_row(-1, -m - 1) * (sqrt2 if m == -1 else 1.0)
            if m != -1:
                big_v = big_v + p_row(1, m + 1)
        row += v * big_v
        if m != 0 and abs(m) < l - 1:
            if m > 0:
                big_w = p_row(1, m + 1) + p_row(-1, -m - 1)
            else:
                big_w = p_row(1, m - 1) - p_row(-1, -m + 1)
            row += w * big_w
        block[m + l] = row
    return block


def rotation_bands(l_max: int, matrix) -> list[np.ndarray]:
    """Per-band SH rotation blocks for a 3×3 rotation ``matrix`` R.

    Parameters
    ----------
    l_max : int
    matrix : array_like, shape (3, 3)
        Proper rotation (orthogonal, det +1 to :data:`ROTATION_TOLERANCE`), acting on
        column vectors in world space.

    Returns
    -------
    list of ndarray
        Block l has shape (2l+1, 2l+1) and maps band-l coefficients of f to those of f∘R⁻¹.
        Pure z rotations use the cos/sin fast path (:func:`rotation_z`), others the
        Ivanic–Ruedenberg recurrence [IR96]_.
    """
    l_max = _check_l_max(l_max)
    r = _check_rotation(matrix)
    angle = _z_rotation_angle(r)
    if angle is not None:
        return [_z_band(l, angle) for l in range(l_max + 1)]
    bands = [np.ones((1, 1))]
    if l_max == 0:
        return bands
    r1 = _band1_ivanic_ruedenberg(r)
    bands.append(r1.copy())
    for l in range(2, l_max + 1):
        bands.append(_ivanic_ruedenberg_band(l, r1, bands[-1]))
    return bands


def _block_diagonal(bands: list[np.ndarray]) -> np.ndarray:
    size = sum(b.shape[0] for b in bands)
    out = np.zeros((size, size))
    start = 0
    for b in bands:
        stop = start + b.shape[0]
        out[start:stop, start:stop] = b
        start = stop
    return out


def rotation(l_max: int, matrix) -> np.ndarray:
    """Full SH rotation matrix ((l_max+1)², (l_max+1)²), block-diagonal by band.

    ``rotation(l_max, R) @ project(f)`` equals ``project(f∘R⁻¹)``; see :func:`rotation_bands`.
    """
    return _block_diagonal(rotation_bands(l_max, matrix))


def rotation_z(l_max: int, angle) -> np.ndarray:
    """SH rotation matrix for a turn by ``angle`` (radians, right-handed) about +z.

    Each ±m pair mixes by cos/sin of mα (see :func:`_z_band`); equals
    ``rotation(l_max, Rz(angle))``.
    """
    l_max = _check_l_max(l_max)
    if np.ndim(angle) != 0:
        raise ValueError(f"angle must be a scalar, got shape {np.shape(angle)}")
    angle = float(_checks.finite_array("angle", angle))
    return _block_diagonal([_z_band(l, angle) for l in range(l_max + 1)])


def rotate(coeffs, matrix) -> np.ndarray:
    """Coefficients of f∘R⁻¹, applied band by band.

    Parameters
    ----------
    coeffs : array_like, shape ((l_max+1)², ...)
    matrix : array_like, shape (3, 3)

    Returns
    -------
    ndarray, same shape as ``coeffs``
    """
    c, l_max = _coeff_array(coeffs)
    out = np.empty_like(c)
    for l, block in enumerate(rotation_bands(l_max, matrix)):
        sl = slice(l * l, (l + 1) ** 2)
        out[sl] = np.tensordot(block, c[sl], axes=(1, 0))
    return out


# ----------------------------------------------------------------------------------------------
# Windowing
# ----------------------------------------------------------------------------------------------


def _hanning_sloan(l: np.ndarray, width: float) -> np.ndarray:
    """Hanning window [Slo08]_: h_l = (1 + cos(π l / w)) / 2 for l < w, else 0."""
    return np.where(l < width, 0.5 * (1.0 + np.cos(np.pi * l / width)), 0.0)


def _lanczos_sloan(l: np.ndarray, width: float) -> np.ndarray:
    """Lanczos (sinc) window [Slo08]_: σ_l = sin(π l / w) / (π l / w), σ_0 = 1."""
    return np.sinc(l / width)


def window(l_max: int, kind: str = "hanning", width=None) -> np.ndarray:
    """Per-coefficient windowing factors that suppress ringing (Gibbs) of a truncated expansion.

    Parameters
    ----------
    l_max : int
    kind : {"hanning", "lanczos", "none"}
    width : float, optional
        Window width w > 0 in bands; default l_max + 1, so band l_max is attenuated but kept.

    Returns
    -------
    ndarray, shape ((l_max+1)²,)
        Factor of each coefficient (constant within a band, 1 for l = 0).

    References
    ----------
    [Slo08]_, section "Windowing".
    """
    l_max = _check_l_max(l_max)
    kind = _checks.choice("kind", kind, {"hanning", "lanczos", "none"})
    if width is None:
        width = l_max + 1.0
    width = float(_checks.in_range("width", _checks.finite_array("width", width), 0.0, lo_open=True))
    l = np.arange(l_max + 1, dtype=float)
    if kind == "hanning":
        per_band = _hanning_sloan(l, width)
    elif kind == "lanczos":
        per_band = _lanczos_sloan(l, width)
    else:
        per_band = np.ones_like(l)
    return per_band[_band_of_index(l_max)]


def apply_window(coeffs, kind: str = "hanning", width=None) -> np.ndarray:
    """``coeffs`` ((l_max+1)², ...) multiplied band by band by :func:`window`."""
    c, l_max = _coeff_array(coeffs)
    factors = window(l_max, kind, width)
    return c * factors.reshape((-1,) + (1,) * (c.ndim - 1))


# ----------------------------------------------------------------------------------------------
# Convolution with zonal kernels
# ----------------------------------------------------------------------------------------------


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
    l_max = _check_l_max(l_max)
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
    c, l_max = _coeff_array(radiance_coeffs, "radiance_coeffs")
    a_hat = clamped_cosine_zh(l_max)[_band_of_index(l_max)]
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
    c, l_max = _coeff_array(coeffs)
    z = _check_zonal(zonal, l_max)[: l_max + 1]
    factor = (_funk_hecke_factor(l_max) * z)[_band_of_index(l_max)]
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
    _check_l_max(l_max)
    factor = (_funk_hecke_factor(l_max) * z)[_band_of_index(l_max)]
    return basis(l_max, _unit_directions(direction, "direction")) * factor
