"""CIEDE2000 between two scene-linear renders, at a common exposure: the project's one ΔE2000.

The benchmarks, the tests and ``scripts/make_reference_images.py`` compare renders with
:func:`delta_e_2000`. CIELAB is meaningless for HDR values unless both images are scaled alike,
so both are multiplied by the one factor that puts the *reference's* 95th-percentile luminance
at :data:`EXPOSURE_P95_TARGET` (a well-exposed object), then converted to XYZ, to CIELAB (D65
white) and compared with CIEDE2000.

Two routes from scene-linear Rec.709 to XYZ are kept, because the published figures were
computed with them (``xyz``):

- ``"D65"``: colour-science's ITU-R BT.709 matrix (XYZ relative to D65, no adaptation); the
  exposure from the Rec.709 luminance weights :data:`LUMINANCE_REC709`. RGB (1, 1, 1) is the D65
  white of Lab, so a flat (E) spectrum is neutral. Used by ``benchmarks.accuracy_vs_time``.
- ``"E"``: the extension's own matrix, ``spectra.rgb_to_xyz_matrix("Linear Rec.709")`` (XYZ with an
  equal-energy white, docs/conventions.md), the exposure from its Y. Lab's white stays D65, so
  RGB (1, 1, 1) is not Lab-neutral on this route. Used for every comparison with Cycles
  (``benchmarks.cycles_compare``, tests/parity/test_cycles_parity.py, scripts/make_reference_images.py).

References
----------
G. Sharma, W. Wu, E. N. Dalal, "The CIEDE2000 color-difference formula: implementation notes,
supplementary test data, and mathematical observations", Color Res. Appl. 30(1), 21–30 (2005);
computed by colour-science's ``delta_E(..., method="CIE 2000")``.
"""

from __future__ import annotations

from typing import Literal

import colour
import numpy as np

from . import rgb_spaces

#: Rec.709 / sRGB relative luminance weights (Blender's default scene-linear space).
LUMINANCE_REC709 = np.array([0.2126, 0.7152, 0.0722])

#: The reference's 95th-percentile luminance after the common exposure: a well-exposed object.
EXPOSURE_P95_TARGET = 0.8

#: The CIELAB white of both routes.
WHITE_D65 = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]

XYZ = Literal["D65", "E"]


def _check_route(xyz: str) -> None:
    if xyz not in ("D65", "E"):
        raise ValueError(f"xyz must be 'D65' or 'E', not {xyz!r}")


def luminance(rgb: np.ndarray, xyz: XYZ = "D65") -> np.ndarray:
    """Relative luminance Y of scene-linear Rec.709 RGB (…, 3) on the route ``xyz``."""
    _check_route(xyz)
    if xyz == "E":
        return (rgb @ rgb_spaces.rgb_to_xyz_matrix("Linear Rec.709").T)[..., 1]
    return np.asarray(rgb, dtype=float) @ LUMINANCE_REC709


def exposure_scale(reference_rgb: np.ndarray, target: float = EXPOSURE_P95_TARGET, xyz: XYZ = "D65") -> float:
    """Factor that maps the reference's 95th-percentile luminance to ``target`` (1 for a reference
    whose 95th percentile is black)."""
    p95 = float(np.percentile(luminance(reference_rgb, xyz), 95))
    return target / p95 if p95 > 0 else 1.0


def rgb_to_lab(rgb: np.ndarray, xyz: XYZ = "D65") -> np.ndarray:
    """Scene-linear Rec.709 RGB (…, 3) → XYZ on the route ``xyz`` → CIELAB (D65 white)."""
    _check_route(xyz)
    if xyz == "E":
        return colour.XYZ_to_Lab(rgb @ rgb_spaces.rgb_to_xyz_matrix("Linear Rec.709").T, WHITE_D65)
    space = colour.RGB_COLOURSPACES["ITU-R BT.709"]
    return colour.XYZ_to_Lab(
        colour.RGB_to_XYZ(np.asarray(rgb, dtype=float), space, apply_cctf_decoding=False), WHITE_D65
    )


def delta_e_2000(
    test_rgb: np.ndarray, reference_rgb: np.ndarray, *, scale: float | None = None, xyz: XYZ = "D65"
) -> np.ndarray:
    """Per-pixel CIEDE2000 between two scene-linear Rec.709 images (…, 3).

    Parameters
    ----------
    test_rgb, reference_rgb
        The images; negative values are clamped to 0.
    scale
        Exposure applied to both before Lab; default :func:`exposure_scale` of the reference
        (its 95th-percentile luminance becomes :data:`EXPOSURE_P95_TARGET`).
    xyz
        The route to XYZ, ``"D65"`` or ``"E"`` (module docstring).

    Returns
    -------
    ndarray
        ΔE2000 per pixel, shape ``test_rgb.shape[:-1]``.
    """
    s = exposure_scale(reference_rgb, xyz=xyz) if scale is None else scale
    lab_t = rgb_to_lab(np.maximum(test_rgb, 0.0) * s, xyz)
    lab_r = rgb_to_lab(np.maximum(reference_rgb, 0.0) * s, xyz)
    return np.asarray(colour.delta_E(lab_t, lab_r, method="CIE 2000"))
