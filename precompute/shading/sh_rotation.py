"""Rotation of the World's SH into each pixel's frame (numpy twin of glsl/tf_sh_rotate.glsl).

rotation(Rz(a) Ry(b) Rz(c)) = Z(a) · X(−90°) · Z(b) · X(+90°) · Z(c), applied right to left,
because Ry(b) = Rx(−90°) Rz(b) Rx(90°) (Kautz, Sloan & Snyder 2002, §4). The X(±90°) band
blocks are constants (the shader keeps them in its uniform buffer, codegen.x_rotation_scalars).

References
----------
- Kautz, J., Sloan, P.-P. & Snyder, J. (2002). Fast, arbitrary BRDF shading for low-frequency
  lighting using spherical harmonics. EGWR.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ..sh import rotations
from .frame import zyz_from_frame


def rotate_z_batch(coeffs, cos_t, sin_t, l_max: int) -> np.ndarray:
    """Turn per-pixel SH coefficients (…, K, C) by Rz(θ).

    Each pair (c_m, s_m) → (c cos mθ − s sin mθ, c sin mθ + s cos mθ), as ``sh.rotation_z``.
    """
    out = np.array(coeffs, copy=True)
    cm, sm = np.ones_like(cos_t), np.zeros_like(cos_t)
    for m in range(1, l_max + 1):
        cm, sm = cm * cos_t - sm * sin_t, sm * cos_t + cm * sin_t  # cos mθ, sin mθ by recurrence
        for l in range(m, l_max + 1):
            pos, neg = l * (l + 1) + m, l * (l + 1) - m
            c, s = coeffs[..., pos, :], coeffs[..., neg, :]
            out[..., pos, :] = c * cm[..., None] - s * sm[..., None]
            out[..., neg, :] = c * sm[..., None] + s * cm[..., None]
    return out


@functools.lru_cache(maxsize=16)
def x_rotation_bands(l_max: int, sign: int) -> tuple[np.ndarray, ...]:
    """Band blocks of the SH rotation for Rx(sign · 90°): constants the shader keeps in its UBO."""
    t = sign * 0.5 * np.pi
    rx = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(t), -math.sin(t)], [0.0, math.sin(t), math.cos(t)]])
    return tuple(rotations.rotation_bands(l_max, rx))


def apply_bands(bands, coeffs) -> np.ndarray:
    """Apply block-diagonal band matrices to (…, K, C) coefficients."""
    out = np.empty_like(coeffs)
    for l, block in enumerate(bands):
        sl = slice(l * l, (l + 1) * (l + 1))
        out[..., sl, :] = np.einsum("ij,...jc->...ic", block, coeffs[..., sl, :])
    return out


def local_coefficients(world_coeffs, frames, l_max: int) -> np.ndarray:
    """Radiance SH in each pixel's frame, (…, K, C): rotation(frame) @ world, the z-y-z way.

    rotation(Rz(a) Ry(b) Rz(c)) = Z(a) · X(−90°) · Z(b) · X(+90°) · Z(c), applied right to left,
    because Ry(b) = Rx(−90°) Rz(b) Rx(90°).
    """
    ca, sa, cb, sb, cc, sc = zyz_from_frame(frames)
    k = (l_max + 1) ** 2
    c = np.broadcast_to(np.asarray(world_coeffs)[:k], ca.shape + (k, np.shape(world_coeffs)[-1]))
    c = rotate_z_batch(c, cc, sc, l_max)
    c = apply_bands(x_rotation_bands(l_max, +1), c)
    c = rotate_z_batch(c, cb, sb, l_max)
    c = apply_bands(x_rotation_bands(l_max, -1), c)
    return rotate_z_batch(c, ca, sa, l_max)
