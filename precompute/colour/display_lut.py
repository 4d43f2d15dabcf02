"""The display transform as a 3-D lookup table: the numpy mirror of ``glsl/tf_display.glsl``.

The scene's colour management (display device, view transform, look, gamma; OCIO, evaluated by
addon/drawing/display.py) is baked on the CPU into a cube of ``N``³ display-referred RGB values over a
logarithmic *shaper* of the scene-linear input, and sampled per pixel with trilinear
interpolation. Exposure stays outside the table: the caller scales the scene-linear input by
2^exposure first, as Blender does. A 3 × 3 matrix then takes the working space into the table's
input space: the display's own linear gamut for views that clip to it (Standard, Filmic, PBR
Neutral: the clip then falls on the cube's faces instead of inside its cells), the working
space itself for views that map wide gamuts (AgX); addon/drawing/display.py picks the one that follows
OCIO best.

Shaper (each channel, x scene-linear in the working space after exposure, clamped to ≥ 0):

    s(x) = clamp((log2(x + a) − log2 a) / (log2(x_max + a) − log2 a), 0, 1)

with a = :data:`.shading.policy.DISPLAY_LUT_FLOOR` and x_max = :data:`.shading.policy.DISPLAY_LUT_MAX`;
the lattice's point ``i`` along an axis lies at s = i / (N − 1). Both the GLSL and this module
fetch the eight corners of the cell and interpolate (no hardware filtering), so they agree to
float32 rounding.
"""

from __future__ import annotations

import numpy as np

from ..shading import policy


def shaper(x: np.ndarray, floor: float | None = None, top: float | None = None) -> np.ndarray:
    """Position in [0, 1] along a LUT axis of scene-linear values ``x`` (see the module)."""
    a = policy.DISPLAY_LUT_FLOOR if floor is None else float(floor)
    top = policy.DISPLAY_LUT_MAX if top is None else float(top)
    lo, hi = np.log2(a), np.log2(top + a)
    x = np.maximum(np.asarray(x, dtype=np.float64), 0.0)
    return np.clip((np.log2(x + a) - lo) / (hi - lo), 0.0, 1.0)


def lattice_values(size: int, floor: float | None = None, top: float | None = None) -> np.ndarray:
    """Scene-linear value at each of the ``size`` lattice points of an axis (the shaper's inverse)."""
    a = policy.DISPLAY_LUT_FLOOR if floor is None else float(floor)
    top = policy.DISPLAY_LUT_MAX if top is None else float(top)
    lo, hi = np.log2(a), np.log2(top + a)
    s = np.linspace(0.0, 1.0, int(size))
    return np.maximum(np.exp2(lo + s * (hi - lo)) - a, 0.0)


def lattice(size: int, floor: float | None = None, top: float | None = None) -> np.ndarray:
    """Every lattice point's scene-linear RGB, shape (size, size, size, 3) indexed [b, g, r]
    (red varies fastest: the texture's layout, :func:`texture_layout`)."""
    v = lattice_values(size, floor, top)
    b, g, r = np.meshgrid(v, v, v, indexing="ij")
    return np.stack([r, g, b], axis=-1)


def texture_layout(table: np.ndarray, matrix=None) -> np.ndarray:
    """A (N, N, N, 3) table indexed [b, g, r] as the RGBA texture the shader reads: width N · N
    (texel x = r + N · g), height N + 1 (y = b; the last row's first three texels hold the rows
    of the input ``matrix``, identity when None), alpha 1."""
    table = np.asarray(table, dtype=np.float32)
    n = table.shape[0]
    if table.shape != (n, n, n, 3):
        raise ValueError(f"display LUT must be (N, N, N, 3), got {table.shape}")
    rgba = np.ones((n + 1, n * n, 4), dtype=np.float32)
    rgba[:n, :, :3] = table.reshape(n, n * n, 3)
    rgba[n] = 0.0
    rgba[n, :3, :3] = np.eye(3) if matrix is None else np.asarray(matrix, dtype=np.float32)
    return rgba


def apply(table: np.ndarray, rgb: np.ndarray, exposure: float = 0.0, matrix=None) -> np.ndarray:
    """Display-referred RGB of scene-linear ``rgb`` (…, 3): × 2^exposure, into the LUT's input
    space (``matrix`` M: x ↦ M x; None: identity), shaper, trilinear lookup."""
    table = np.asarray(table, dtype=np.float64)
    n = table.shape[0]
    x = np.asarray(rgb, dtype=np.float64) * 2.0 ** float(exposure)
    if matrix is not None:
        x = x @ np.asarray(matrix, dtype=np.float64).T
    s = shaper(x) * (n - 1)
    i0 = np.minimum(np.floor(s).astype(np.int64), n - 2)
    f = s - i0
    r0, g0, b0 = i0[..., 0], i0[..., 1], i0[..., 2]
    fr, fg, fb = f[..., 0:1], f[..., 1:2], f[..., 2:3]

    def at(db, dg, dr):
        return table[b0 + db, g0 + dg, r0 + dr]

    c00 = at(0, 0, 0) * (1 - fr) + at(0, 0, 1) * fr
    c01 = at(0, 1, 0) * (1 - fr) + at(0, 1, 1) * fr
    c10 = at(1, 0, 0) * (1 - fr) + at(1, 0, 1) * fr
    c11 = at(1, 1, 0) * (1 - fr) + at(1, 1, 1) * fr
    c0 = c00 * (1 - fg) + c01 * fg
    c1 = c10 * (1 - fg) + c11 * fg
    return c0 * (1 - fb) + c1 * fb
