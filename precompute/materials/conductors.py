"""Conductors from RGB and back: Blender's metallic Principled BSDF as a complex index.

From (Base Color, Specular Tint) to a tabulated complex index is
:mod:`precompute.optics.gulbrandsen2014` (its names are re-exported here:
:func:`conductor_from_rgb`, :data:`F82_COS`, …); :func:`metal_rgb` goes the other way, from any
index to (Base Color, Specular Tint) of Blender's F82-tint metal, and :func:`real_index` reads
an index at one wavelength (550 nm by default), as the Principled BSDF's single "IOR" needs.
"""

from __future__ import annotations

import numpy as np

from ..colour import rgb_spaces, spectra
from ..optics import reflectance
from ..optics.gulbrandsen2014 import (
    F82_COS,
    RGB_WAVELENGTHS_NM,
    conductor_from_rgb,
    fresnel_conductor,
    gulbrandsen_nk,
    schlick,
)
from .material import Material

__all__ = [
    "F82_COS",
    "REFERENCE_WAVELENGTH_NM",
    "RGB_WAVELENGTHS_NM",
    "conductor_from_rgb",
    "fresnel_conductor",
    "gulbrandsen_nk",
    "metal_rgb",
    "real_index",
    "schlick",
]

#: Where a film's dispersive index is read for Principled's single "Thin Film IOR".
REFERENCE_WAVELENGTH_NM = 550.0
#: Smallest Schlick(F0, 1/7) divided by in :func:`metal_rgb`: a black F0 gives a tint of 0,
#: not a division by zero.
_MIN_SCHLICK = 1e-6


def _spectrum_rgb(spectrum, wavelengths_nm, colour_space: str) -> np.ndarray:
    """A reflectance spectrum as working-space RGB (E white: a flat 1 gives (1, 1, 1))."""
    xyz = spectra.spectrum_to_xyz(spectrum, wavelengths_nm)
    return rgb_spaces.xyz_to_rgb_matrix(colour_space) @ xyz


def metal_rgb(index_spec, colour_space: str | None = None) -> tuple[tuple, tuple]:
    """(Base Color, Specular Tint) for Principled's metal model from a conductor's index.

    Base Color is the normal-incidence reflectance R(0°, λ) integrated to RGB; Specular Tint
    is R(cos θ = 1/7) in RGB divided by Schlick(F0, 1/7) (Blender's F82 tint), clamped to [0, 1].
    """
    space = colour_space or rgb_spaces.DEFAULT_SPACE
    medium = Material(layers=(), substrate=index_spec).indices()[-1]
    wl = spectra.wavelength_grid(95)
    spectra_r = reflectance([1.0, medium], [], wl, [1.0, F82_COS])  # (2, W)
    f0 = np.clip(_spectrum_rgb(spectra_r[0], wl, space), 0.0, 1.0)
    f82 = np.clip(_spectrum_rgb(spectra_r[1], wl, space), 0.0, 1.0)
    tint = np.clip(f82 / np.maximum(schlick(f0, F82_COS), _MIN_SCHLICK), 0.0, 1.0)
    return tuple(float(v) for v in f0), tuple(float(v) for v in tint)


def real_index(spec, wavelength_nm: float = REFERENCE_WAVELENGTH_NM) -> complex:
    """N = n + ik at one wavelength (nm) of any IndexSpec (constant, table, Cauchy, metal)."""
    medium = Material(layers=(), substrate=spec).indices()[-1]
    return complex(np.asarray(medium.index(np.array([wavelength_nm])))[0])
