"""Rotation of real SH coefficients: block-diagonal band matrices, applied band by band.

``rotation(l_max, R) @ c`` gives the coefficients of f∘R⁻¹ (the function turned by R); the
convention is :mod:`.harmonics`'. The bands come from the Ivanic–Ruedenberg recursion [IR96]_,
with a cos/sin fast path for turns about z.

References
----------
.. [IR96] J. Ivanic and K. Ruedenberg, "Rotation Matrices for Real Spherical Harmonics.
   Direct Determination by Recursion", J. Phys. Chem. 100 (1996) 6342–6347; Additions and
   Corrections, J. Phys. Chem. A 102 (1998) 9099–9100.
"""

from __future__ import annotations

import math

import numpy as np

from .. import _checks
from .harmonics import check_l_max, coeff_array

__all__ = ["rotate", "rotation", "rotation_bands", "rotation_z"]

#: Orthogonality tolerance for rotation matrices: ‖RᵀR − I‖_max and |det R − 1| must be below
#: it. 1e-6 accepts matrices built in float32 (ε ≈ 6e-8 per entry, a few ulps after products)
#: while rejecting scalings, shears and reflections.
ROTATION_TOLERANCE = 1e-6

#: A rotation whose z-column and z-row are (0, 0, 1) to within this is treated as a pure turn
#: about z and takes the cos/sin fast path. At 1e-14 the neglected tilt changes a coefficient
#: by at most ~l·1e-14, far below the 1e-10 at which the paths are compared.
Z_ROTATION_EPS = 1e-14


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
    l_max = check_l_max(l_max)
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
    l_max = check_l_max(l_max)
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
    c, l_max = coeff_array(coeffs)
    out = np.empty_like(c)
    for l, block in enumerate(rotation_bands(l_max, matrix)):
        sl = slice(l * l, (l + 1) ** 2)
        out[sl] = np.tensordot(block, c[sl], axes=(1, 0))
    return out
