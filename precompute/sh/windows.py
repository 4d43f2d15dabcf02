"""Windows that suppress the ringing (Gibbs) of a truncated SH expansion, band by band [Slo08]_.

References
----------
.. [Slo08] P.-P. Sloan, "Stupid Spherical Harmonics (SH) Tricks", GDC 2008.
"""

from __future__ import annotations

import numpy as np

from .. import _checks
from .harmonics import band_of_index, check_l_max, coeff_array

__all__ = ["apply_window", "window"]


def _hanning_sloan(l: np.ndarray, width: float) -> np.ndarray:
    """Hanning window [Slo08]_: h_l = (1 + cos(π l / w)) / 2 for l < w, else 0."""
    return np.where(l < width, 0.5 * (1.0 + np.cos(np.pi * l / width)), 0.0)


def _lanczos_sloan(l: np.ndarray, width: float) -> np.ndarray:
    """Lanczos (sinc) window [Slo08]_: σ_l = sin(π l / w) / (π l / w), σ_0 = 1."""
    return np.sinc(l / width)


def window(l_max: int, kind: str = "hanning", width=None) -> np.ndarray:
    """Per-coefficient windowing factors that suppress ringing (Gibbs) of a truncated expansion.

    Parameters
    ----------
    l_max : int
    kind : {"hanning", "lanczos", "none"}
    width : float, optional
        Window width w > 0 in bands; default l_max + 1, so band l_max is attenuated but kept.

    Returns
    -------
    ndarray, shape ((l_max+1)²,)
        Factor of each coefficient (constant within a band, 1 for l = 0).

    References
    ----------
    [Slo08]_, section "Windowing".
    """
    l_max = check_l_max(l_max)
    kind = _checks.choice("kind", kind, {"hanning", "lanczos", "none"})
    if width is None:
        width = l_max + 1.0
    width = float(_checks.in_range("width", _checks.finite_array("width", width), 0.0, lo_open=True))
    l = np.arange(l_max + 1, dtype=float)
    if kind == "hanning":
        per_band = _hanning_sloan(l, width)
    elif kind == "lanczos":
        per_band = _lanczos_sloan(l, width)
    else:
        per_band = np.ones_like(l)
    return per_band[band_of_index(l_max)]


def apply_window(coeffs, kind: str = "hanning", width=None) -> np.ndarray:
    """``coeffs`` ((l_max+1)², ...) multiplied band by band by :func:`window`."""
    c, l_max = coeff_array(coeffs)
    factors = window(l_max, kind, width)
    return c * factors.reshape((-1,) + (1,) * (c.ndim - 1))
