"""One pixel of thin-film SH shading (numpy twin of glsl/tf_shade.glsl, and of the generated
band-by-band sum, codegen.banded_source).

Build the view-aligned frame, rotate the World's SH into it, look the table up at θo (and
thickness) and sum M_i · L_i over the kept (m ≥ 0) coefficients; negative sums clamp to 0.
"""

from __future__ import annotations

import numpy as np

from ..bakes import bake, kernel
from .frame import view_aligned_frame
from .sh_rotation import local_coefficients
from .table import lookup, thickness_position


def shade_sh(result: bake.BakeResult, world_coeffs, normals, views, thickness_nm=None) -> np.ndarray:
    """Scene-linear RGB per pixel (…, 3) from a baked table and world-space radiance SH (≥ K, 3)."""
    l_max = result.sh_order
    frames = view_aligned_frame(normals, views)
    local = local_coefficients(np.asarray(world_coeffs, dtype=float), frames, l_max)
    kept = local[..., kernel.coefficient_indices(l_max), :]  # (…, K, 3)
    cos_o = np.sum(frames[..., 2, :] * np.asarray(views), axis=-1)
    m = lookup(result.data, cos_o, thickness_position(result, thickness_nm))
    if m.ndim == kept.ndim + 1:  # spectral: 3×3 per coefficient
        out = np.einsum("...ikc,...ic->...k", m, kept)
    else:  # per channel
        out = np.einsum("...ik,...ik->...k", m, kept)
    return np.maximum(out, 0.0)
