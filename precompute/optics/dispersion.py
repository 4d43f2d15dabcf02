"""Wavelength-dependent refractive indices: constant, Cauchy, Sellmeier, tabulated.

Every model is a small frozen dataclass with ``index(wavelengths_nm) -> complex array``.
:func:`resolve_index` turns whatever a caller passed for one medium (a scalar, an array over
the wavelengths, or a model) into a complex array over the wavelengths and checks it.

References
----------
- Cauchy, A.-L. (1836). *Mémoire sur la dispersion de la lumière.*
- Sellmeier, W. (1871). Ann. Phys. 219, 272–282.
- Malitson, I. H. (1965). Interspecimen comparison of the refractive index of fused silica.
  JOSA 55, 1205 (the Sellmeier coefficients used in ``FUSED_SILICA``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import _checks


@dataclass(frozen=True)
class ConstantIndex:
    """A non-dispersive medium, N = n + i·k."""

    n: float
    k: float = 0.0

    def index(self, wavelengths_nm) -> np.ndarray:
        """The constant complex index n + ik at each wavelength."""
        wl = np.asarray(wavelengths_nm, dtype=float)
        return np.full(wl.shape, complex(self.n, self.k))

    @property
    def dispersive(self) -> bool:
        """False: the index does not depend on wavelength."""
        return False


@dataclass(frozen=True)
class CauchyIndex:
    """Cauchy's law n(λ) = A + B/λ² + C/λ⁴ with λ in micrometres; k = 0."""

    A: float
    B: float = 0.0
    C: float = 0.0

    def index(self, wavelengths_nm) -> np.ndarray:
        """Cauchy index A + B/λ² + C/λ⁴ (λ in µm) at each wavelength."""
        lam_um = np.asarray(wavelengths_nm, dtype=float) * 1e-3
        return (self.A + self.B / lam_um**2 + self.C / lam_um**4).astype(complex)

    @property
    def dispersive(self) -> bool:
        """True when B or C is non-zero."""
        return self.B != 0.0 or self.C != 0.0


@dataclass(frozen=True)
class SellmeierIndex:
    """Sellmeier equation n² = 1 + Σ B_i λ² / (λ² − C_i), λ in µm, C_i in µm²; k = 0."""

    B: tuple[float, ...]
    C: tuple[float, ...]

    def __post_init__(self):
        if len(self.B) != len(self.C) or not self.B:
            raise ValueError("SellmeierIndex needs equally many B and C coefficients (at least one)")

    def index(self, wavelengths_nm) -> np.ndarray:
        """Sellmeier index at each wavelength; refuses wavelengths where n² ≤ 0."""
        lam2 = (np.asarray(wavelengths_nm, dtype=float) * 1e-3) ** 2
        n2 = 1.0 + sum(b * lam2 / (lam2 - c) for b, c in zip(self.B, self.C, strict=False))
        if np.any(n2 <= 0):
            raise ValueError("SellmeierIndex gives n² ≤ 0 at some wavelength: a resonance lies in range")
        return np.sqrt(n2).astype(complex)

    @property
    def dispersive(self) -> bool:
        """True."""
        return True


@dataclass(frozen=True)
class TabulatedIndex:
    """Measured n and k at given wavelengths, interpolated linearly in wavelength."""

    wavelengths_nm: tuple[float, ...]
    n: tuple[float, ...]
    k: tuple[float, ...]
    name: str = "tabulated"

    def __post_init__(self):
        wl = np.asarray(self.wavelengths_nm, dtype=float)
        if not (len(wl) == len(self.n) == len(self.k)) or len(wl) < 2:
            raise ValueError(f"{self.name}: wavelengths_nm, n and k need equal lengths ≥ 2")
        if np.any(np.diff(wl) <= 0):
            raise ValueError(f"{self.name}: wavelengths_nm must increase strictly")

    def index(self, wavelengths_nm) -> np.ndarray:
        """Tabulated n + ik interpolated at each wavelength; refuses extrapolation."""
        wl = np.asarray(wavelengths_nm, dtype=float)
        lo, hi = self.wavelengths_nm[0], self.wavelengths_nm[-1]
        if np.any(wl < lo) or np.any(wl > hi):
            raise ValueError(f"wavelengths_nm outside {self.name}'s tabulated range {lo}–{hi} nm")
        return np.interp(wl, self.wavelengths_nm, self.n) + 1j * np.interp(wl, self.wavelengths_nm, self.k)

    @property
    def dispersive(self) -> bool:
        """True."""
        return True


#: Fused silica, Malitson (1965), valid 0.21–3.71 µm.
FUSED_SILICA = SellmeierIndex(
    B=(0.6961663, 0.4079426, 0.8974794), C=(0.0684043**2, 0.1162414**2, 9.896161**2)
)


def is_model(value) -> bool:
    """True when ``value`` is a dispersion model (has an ``index`` method)."""
    return hasattr(value, "index") and callable(value.index)


def is_dispersive(value) -> bool:
    """True unless ``value`` is a scalar or a non-dispersive model (arrays count as dispersive)."""
    if is_model(value):
        return bool(getattr(value, "dispersive", True))
    return np.ndim(value) > 0


def resolve_index(name: str, value, wavelengths_nm: np.ndarray) -> np.ndarray:
    """Return the complex index of one medium over ``wavelengths_nm`` (shape (W,)), checked.

    ``value`` may be a real or complex scalar, an array over the wavelengths, or a model.
    Raises ``ValueError`` naming ``name`` for NaN/Inf, n ≤ 0, k < 0 or a length mismatch.
    """
    if is_model(value):
        arr = value.index(wavelengths_nm)
    else:
        arr = _checks.finite_array(name, value, allow_complex=True)
        if arr.ndim > 1:
            raise ValueError(
                f"{name} must be a scalar or a 1-D array over wavelengths_nm, got shape {arr.shape}"
            )
        if arr.ndim == 1 and arr.shape[0] != wavelengths_nm.shape[0]:
            raise ValueError(
                f"{name} has {arr.shape[0]} values but wavelengths_nm has {wavelengths_nm.shape[0]}"
            )
    arr = np.broadcast_to(np.asarray(arr, dtype=complex), wavelengths_nm.shape)
    _checks.finite_array(name, arr, allow_complex=True)
    if np.any(arr.real <= 0):
        raise ValueError(f"{name} must have a real part n > 0, got {arr.real.min()!r}")
    if np.any(arr.imag < 0):
        raise ValueError(
            f"{name} has a negative extinction coefficient k = {arr.imag.min()!r} "
            "(absorbing media need k ≥ 0)"
        )
    return np.array(arr)
