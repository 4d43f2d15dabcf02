"""Blender's Color Ramp as Cycles evaluates it, in numpy: a table of 257 entries.

Cycles does not evaluate a Color Ramp's stops per shading point. When it compiles the node it
samples the ramp (Blender's own evaluation: any interpolation, RGB, HSV or HSL) at
:data:`TABLE_SIZE` evenly spaced factors 0, 1/256, …, 1, and each shading point reads that table
(:func:`lookup`): the factor clamped to [0, 1] and scaled by 256, the entry at its integer part
and, unless the ramp's interpolation is *Constant*, a linear blend with the next entry by the
fraction. (Measured in Blender 5.2: a Constant ramp whose stop sits at 0.45 steps, in Cycles'
bake, between Fac 0.45295 and 0.45321, about 116/256 = 0.453125, the first table position past
the stop; a table of 256 at i/255 would step at 115/255 = 0.45098.) The add-on samples the
ramp through ``ColorRamp.evaluate`` (addon/thickness/linked_nodes.py), so this module needs
only the table; ``glsl/tf_perlin.glsl`` (``tf_ramp``, ``TF_THICKNESS_RAMP``) reads the same
table per pixel.

A ramp that feeds a float input (a film's thickness) reaches it through Blender's implicit colour
to float conversion, the luminance: a weighted sum of the channels, which commutes with the
table's blend, so a table of luminances read by :func:`lookup` is the luminance of the colour
Cycles looks up.

Reference: Blender manual, *Color Ramp* node; Cycles' ``rgb_ramp_lookup`` (its behaviour, as
described above).
"""

from __future__ import annotations

import numpy as np

__all__ = ["TABLE_SIZE", "lookup", "table_positions"]

#: Entries of the table Cycles samples a Color Ramp into (its ``RAMP_TABLE_SIZE`` + 1: both ends).
TABLE_SIZE = 257


def table_positions(size: int = TABLE_SIZE) -> np.ndarray:
    """The factors a ramp is sampled at: 0, 1/(size − 1), …, 1 (float64 (size,))."""
    return np.arange(int(size), dtype=np.float64) / (int(size) - 1)


def lookup(table, fac, interpolate: bool = True) -> np.ndarray:
    """The ramp at ``fac`` from its ``table`` ((size,) or (size, C) entries at
    :func:`table_positions`): ``fac`` clamped to [0, 1] (NaN reads entry 0), the entry at
    ⌊fac · (size − 1)⌋, blended linearly with the next by the fraction when ``interpolate``.
    Returns (N,) or (N, C) float64 for (N,) factors."""
    table = np.asarray(table, dtype=np.float64)
    size = table.shape[0]
    f = np.clip(np.nan_to_num(np.asarray(fac, dtype=np.float64), nan=0.0), 0.0, 1.0) * (size - 1)
    i = np.clip(np.floor(f).astype(np.int64), 0, size - 1)
    value = table[i]
    if interpolate:
        t = f - i
        if table.ndim == 2:
            t = t[:, None]
        value = value + t * (table[np.minimum(i + 1, size - 1)] - value)
    return value
