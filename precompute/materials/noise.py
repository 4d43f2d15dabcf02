"""Deterministic procedural noise: fractal 3-D value noise on an integer hash lattice.

Used for the "Noise" thickness source of a film (the add-on evaluates it at the object-space
vertex positions). Pure numpy, the same numbers on every platform.

References
----------
A. Appleby (2011), MurmurHash3, ``fmix32`` finaliser.
K. Perlin (2002), "Improving Noise", ACM Transactions on Graphics 21(3), 681–682 (quintic fade).
"""

from __future__ import annotations

import numpy as np

__all__ = ["value_noise"]


def _hash01(ix, iy, iz, seed: int) -> np.ndarray:
    """Integer lattice point → uniform value in [0, 1), deterministic on every platform.

    Coordinates are mixed with large odd constants and finished with MurmurHash3's fmix32
    (Appleby 2011), all in wrapping uint32 arithmetic.
    """

    def u32(a):
        return (np.asarray(a, dtype=np.int64) & 0xFFFFFFFF).astype(np.uint32)

    h = u32(ix) * np.uint32(0x8DA6B343)
    h ^= u32(iy) * np.uint32(0xD8163841)
    h ^= u32(iz) * np.uint32(0xCB1AB31F)
    h ^= np.uint32((int(seed) * 0x9E3779B9) & 0xFFFFFFFF)
    h ^= h >> np.uint32(16)
    h *= np.uint32(0x85EBCA6B)
    h ^= h >> np.uint32(13)
    h *= np.uint32(0xC2B2AE35)
    h ^= h >> np.uint32(16)
    return h.astype(np.float64) / 4294967296.0


def value_noise(points, scale: float = 1.0, seed: int = 0, octaves: int = 3) -> np.ndarray:
    """Fractal 3-D value noise in [0, 1] at ``points`` (N, 3).

    Each octave hashes the integer lattice around p·scale·2^o, blends the eight corner values
    with the quintic fade 6t⁵ − 15t⁴ + 10t³ (Perlin 2002) and is weighted 2^−o; the sum is
    divided by the total weight, so the result stays in [0, 1].
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3) * float(scale)
    total = np.zeros(p.shape[0])
    weight = 0.0
    with np.errstate(over="ignore"):
        for octave in range(octaves):
            q = p * (2.0**octave) + 17.0 * octave
            cell = np.floor(q)
            f = q - cell
            w = f * f * f * (f * (f * 6.0 - 15.0) + 10.0)
            cell = cell.astype(np.int64)
            value = np.zeros(p.shape[0])
            for dx in (0, 1):
                for dy in (0, 1):
                    for dz in (0, 1):
                        corner = _hash01(cell[:, 0] + dx, cell[:, 1] + dy, cell[:, 2] + dz, seed + octave)
                        wx = w[:, 0] if dx else 1.0 - w[:, 0]
                        wy = w[:, 1] if dy else 1.0 - w[:, 1]
                        wz = w[:, 2] if dz else 1.0 - w[:, 2]
                        value += wx * wy * wz * corner
            amplitude = 0.5**octave
            total += amplitude * value
            weight += amplitude
    return np.clip(total / weight, 0.0, 1.0)
