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


#: OpenEXR ``chromaticities`` (red, green, blue, white xy) of Blender's working spaces: ITU-R
#: BT.709 and BT.2020 with the D65 white; ACEScg (AP1) with the ACES white (Academy S-2014-004).
CHROMATICITIES = {
    "Linear Rec.709": (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290),
    "Linear Rec.2020": (0.708, 0.292, 0.170, 0.797, 0.131, 0.046, 0.3127, 0.3290),
    "ACEScg": (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767),
}


def write_exr(path, linear: np.ndarray, chromaticities=None) -> None:
    """Scene-linear float32 OpenEXR of an (H, W, 3) RGB or (H, W, 4) RGBA image (ZIP).

    ``chromaticities``: the 8 floats of the header attribute (:data:`CHROMATICITIES`), or None.
    Written with the ``OpenEXR`` package where it is installed, else with OpenImageIO (what
    Blender bundles: ``bpy.utils.expose_bundled_modules()`` must have run).
    """
    img = np.ascontiguousarray(np.asarray(linear, dtype=np.float32))
    if img.ndim != 3 or img.shape[2] not in (3, 4):
        raise ValueError(f"EXR image must be (H, W, 3|4), got {img.shape}")
    try:
        import OpenEXR  # the venv's package; absent inside Blender
    except ImportError:
        OpenEXR = None
    if OpenEXR is not None:
        header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
        if chromaticities is not None:
            header["chromaticities"] = tuple(float(c) for c in chromaticities)
        OpenEXR.File(header, {"RGBA" if img.shape[2] == 4 else "RGB": img}).write(str(path))
        return
    import OpenImageIO as oiio

    h, w, c = img.shape
    spec = oiio.ImageSpec(w, h, c, "float")
    spec.attribute("compression", "zip")
    if chromaticities is not None:
        spec.attribute("chromaticities", oiio.TypeDesc("float[8]"), tuple(float(v) for v in chromaticities))
    out = oiio.ImageOutput.create(str(path))
    if out is None or not out.open(str(path), spec) or not out.write_image(img) or not out.close():
        raise OSError(f"{path}: EXR not written ({oiio.geterror()})")
