"""Lookup of a baked table at (θo, thickness) (numpy twin of glsl/tf_table.glsl).

Linear interpolation on the table's uniform θo axis (0…90° inclusive) and, for a 2-D table, its
thickness rows, in full precision (the shader does the same with ``texelFetch`` in float32).
"""

from __future__ import annotations

import numpy as np


def lerp_index(value, count: int):
    """Lower index and weight for linear interpolation of a sample position in [0, count − 1]."""
    pos = np.clip(value, 0.0, count - 1.0)
    i0 = np.minimum(np.floor(pos).astype(int), max(count - 2, 0))
    return i0, pos - i0


def thickness_position(result, thickness_nm):
    """Fractional thickness row in [0, T − 1] of ``thickness_nm`` in a bake result's table, or
    None (no thickness given, or a table of one row)."""
    if thickness_nm is None or result.thicknesses_nm.size < 2:
        return None
    lo, hi = result.thicknesses_nm[0], result.thicknesses_nm[-1]
    return (np.asarray(thickness_nm, dtype=float) - lo) / (hi - lo) * (result.thicknesses_nm.size - 1)


def lookup(table: np.ndarray, cos_o, thickness_position=None) -> np.ndarray:
    """Interpolate a table (T, A, K, 3[, 3]) at per-pixel θo and thickness position, → (…, K, 3[, 3]).

    θo = acos(n·v) is mapped to the uniform 0…90° axis; ``thickness_position`` is the
    fractional row in [0, T − 1] (0 when the table has one row).
    """
    t_count, a_count = table.shape[:2]
    theta = np.arccos(np.clip(cos_o, 0.0, 1.0))
    a0, wa = lerp_index(theta / (0.5 * np.pi) * (a_count - 1), a_count)
    if t_count == 1 or thickness_position is None:
        t0, wt = np.zeros_like(a0), np.zeros_like(wa)
        t_count = max(t_count, 2)
        table = np.concatenate([table, table]) if table.shape[0] == 1 else table
    else:
        t0, wt = lerp_index(np.broadcast_to(thickness_position, a0.shape), t_count)
    a1, t1 = np.minimum(a0 + 1, a_count - 1), np.minimum(t0 + 1, table.shape[0] - 1)
    extra = (None,) * (table.ndim - 2)
    wa, wt = wa[(...,) + extra], wt[(...,) + extra]
    return (1 - wt) * ((1 - wa) * table[t0, a0] + wa * table[t0, a1]) + wt * (
        (1 - wa) * table[t1, a0] + wa * table[t1, a1]
    )
