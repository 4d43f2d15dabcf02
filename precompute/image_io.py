"""Image output: Blender's "Standard" display transform, 8-bit PNG and float OpenEXR writers.

The PNG writer is self-contained (per-row filter, zlib, CRC); OpenEXR is imported only when an
EXR is written, so the rest works where that package is not installed (e.g. inside Blender).
"""

from __future__ import annotations

import struct
import zlib

import numpy as np


def srgb_encode(linear: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """Blender's "Standard" view: scale by 2^exposure, clamp to [0, 1], sRGB OETF (IEC 61966-2-1)."""
    x = np.clip(np.asarray(linear) * 2.0**exposure, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def _png_filtered_row(data: np.ndarray, r: int) -> bytes:
    """Row r with the PNG filter (None, Sub or Up) of least Σ|signed residual| (libpng's heuristic).

    Natural images compress to about half with Sub/Up instead of None.
    """
    row = data[r].astype(np.int16).ravel()
    left = np.concatenate([np.zeros(3, np.int16), row[:-3]])
    up = data[r - 1].astype(np.int16).ravel() if r > 0 else np.zeros_like(row)
    options = [(0, row), (1, (row - left) % 256), (2, (row - up) % 256)]

    def cost(residual):
        return int(np.abs(np.where(residual > 127, residual - 256, residual)).sum())

    kind, best = min(options, key=lambda o: cost(o[1]))
    return bytes([kind]) + best.astype(np.uint8).tobytes()


def write_png(path, rgb_display: np.ndarray) -> None:
    """8-bit RGB PNG from display-referred values in [0, 1] (minimal writer: per-row filter, zlib, CRC)."""
    data = np.clip(np.rint(np.asarray(rgb_display) * 255), 0, 255).astype(np.uint8)
    h, w = data.shape[:2]
    raw = b"".join(_png_filtered_row(data, r) for r in range(h))

    def chunk(tag, payload):
        return struct.pack(">I", len(payload)) + tag + payload + struct.pack(">I", zlib.crc32(tag + payload))

    png = (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(raw, 9))
        + chunk(b"IEND", b"")
    )
    with open(path, "wb") as fh:
        fh.write(png)


def write_exr(path, rgb_linear: np.ndarray, alpha: np.ndarray | None = None) -> None:
    """Scene-linear float32 RGB OpenEXR; with ``alpha`` (H, W) also an "A" channel (the colour
    premultiplied by it: a transparent film's coverage)."""
    import OpenEXR  # optional: only needed to write EXR files (absent inside Blender)

    rgb = np.ascontiguousarray(np.asarray(rgb_linear, dtype=np.float32))
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    channels = {"RGB": rgb}
    if alpha is not None:
        channels["A"] = np.ascontiguousarray(np.asarray(alpha, dtype=np.float32).reshape(rgb.shape[:2]))
    OpenEXR.File(header, channels).write(str(path))
