"""A bake's work in steps between two progress checkpoints (:mod:`.progress`).

Each slow loop of :mod:`.bake` is cut into blocks whose size is a named constant here, not the
material's, so the time between two checkpoints, which is how long a cancel waits, is bounded by
design: a block of a reflectance sweep (:func:`chunked_sweep`), one view angle of the kernel
(bounded by :data:`KERNEL_CHUNK`, :func:`precompute.bakes.kernel.view_kernel`), a block of thickness
rows (:func:`row_blocks`). A bigger table makes more
steps, never longer ones. benchmarks/bake_progress.py measures the gaps (docs/bake-progress.md).
"""

from __future__ import annotations

import math

import numpy as np

from ..optics import reflectance_sweep
from .progress import checkpoint

__all__ = [
    "CONTRACT_CHUNK",
    "ELEMENT_CHUNK",
    "KERNEL_CHUNK",
    "SWEEP_CHUNK",
    "chunked_sweep",
    "row_blocks",
    "sweep_checkpoints",
]

#: Film reflectances (thickness rows × u nodes × wavelengths × layers) evaluated between two
#: progress checkpoints of a reflectance sweep, and rows × coefficients × u nodes × 9 multiply-
#: adds between two of the contraction: each ≈ 0.05 s on a loaded two-core machine, so an Esc
#: waits ≪ 0.5 s (benchmarks/bake_progress.py measures the gaps; docs/bake-progress.md).
SWEEP_CHUNK = 250_000
CONTRACT_CHUNK = 50_000_000
#: Multiply-adds of one block of a view angle's kernel product (half-vector nodes × SH
#: coefficients × u nodes): l = 12 with 64 nodes per interval is 215 M, 0.3 s unloaded and up
#: to 1 s on a loaded two-core machine in one piece; blocks of 32 M keep each step ≲ 0.15 s.
KERNEL_CHUNK = 32_000_000
#: Array elements an elementwise pass (the multiple-scattering scale) handles between two.
ELEMENT_CHUNK = 2_000_000


def chunked_sweep(indices, thickness_sets, wavelengths_nm, cos_theta, method: str) -> np.ndarray:
    """:func:`~precompute.optics.reflectance_sweep` in blocks of ≤ :data:`SWEEP_CHUNK` film
    evaluations (thickness rows, then u nodes within a row), a progress :func:`checkpoint`
    after each; element by element the same result as one call, shape (T, U, W)."""
    sets = np.atleast_2d(np.asarray(thickness_sets, dtype=float))
    cos = np.asarray(cos_theta, dtype=float)
    per_node = max(1, np.size(wavelengths_nm) * max(1, sets.shape[1]))
    per_row = per_node * cos.size
    if sets.shape[0] * per_row <= SWEEP_CHUNK:
        out = reflectance_sweep(indices, sets, wavelengths_nm, cos, method=method)
        checkpoint()
        return out
    rows = max(1, SWEEP_CHUNK // per_row)
    cols = cos.size if rows > 1 else max(1, SWEEP_CHUNK // per_node)
    out = np.empty((sets.shape[0], cos.size, np.size(wavelengths_nm)))
    for r in range(0, sets.shape[0], rows):
        for c in range(0, cos.size, cols):
            out[r : r + rows, c : c + cols] = reflectance_sweep(
                indices, sets[r : r + rows], wavelengths_nm, cos[c : c + cols], method=method
            )
            checkpoint()
    return out


def row_blocks(t: int, per_row: int, budget: int = CONTRACT_CHUNK) -> list[slice]:
    """Slices of ``t`` thickness rows, each of ≤ ``budget`` units of work (at least one row)."""
    rows = max(1, budget // max(1, per_row))
    return [slice(lo, lo + rows) for lo in range(0, t, rows)]


def sweep_checkpoints(rows: int, layers: int, nodes: int, wavelengths: int) -> int:
    """How many checkpoints :func:`chunked_sweep` makes for a sweep of this size."""
    per_node = max(1, wavelengths * max(1, layers))
    per_row = per_node * nodes
    if rows * per_row <= SWEEP_CHUNK:
        return 1
    per_block = max(1, SWEEP_CHUNK // per_row)
    if per_block > 1:
        return math.ceil(rows / per_block)
    return rows * math.ceil(nodes / max(1, SWEEP_CHUNK // per_node))
