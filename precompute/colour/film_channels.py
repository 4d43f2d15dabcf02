"""The film's reflectance per colour channel: the Cycles-matching colour mode (``"per_channel"``).

Cycles computes a Principled thin film per RGB channel: the Airy series of one film, truncated
after three orders, integrated in Fourier space against the channel's sensitivity (the CIE
1931 colour-matching functions taken to the working space by Blender's XYZ → scene-linear
matrix, no chromatic adaptation, each channel normalised so that white reflects 1), the
polarisations averaged and clamped to [0, 1] (:mod:`.optics.belcour2017`). The light is then
multiplied channel by channel. This module decides how a material is evaluated in that mode:

- :func:`cycles_stack`: the film as Cycles' model expresses it — one layer of constant real
  index over a constant substrate (real: a dielectric; complex: a conductor;
  ``{"f82_tint": …}``: Blender's metallic Principled BSDF), the exact model, illuminant E —
  evaluated by :func:`fourier_reflectance` exactly as Cycles does;
- any other material (multilayers, dispersion, measured metals, absorbing films, Glassner's
  model, a coloured illuminant): the exact spectral reflectance integrated against the same
  channel sensitivities (:func:`precompute.colour.rgb_spaces.channel_weights`, in
  ``bake.spectral_quadrature``) and clamped — Cycles' colour pipeline with exact optics.

The spectral mode (a 3×3 matrix per coefficient, ``bake.spectral_quadrature``) is separate and
keeps the conventions of docs/conventions.md; docs/colour-modes.md lists where the two differ.
"""

from __future__ import annotations

import functools

import numpy as np

from ..materials.material import Material
from ..optics import belcour2017
from ..optics.dispersion import ConstantIndex
from .rgb_spaces import channel_sensitivities

__all__ = [
    "F82_MAX_REFLECTIVITY",
    "cycles_stack",
    "f82_tint_stack_substrate",
    "fourier_reflectance",
    "sensitivity",
]

#: Normal-incidence reflectivity is clamped below this before Gulbrandsen's (n, k) fit of an F82
#: metal (the fit diverges at 1), as Cycles does.
F82_MAX_REFLECTIVITY = 0.999


@functools.cache
def sensitivity(space: str) -> belcour2017.FourierSensitivity:
    """The Fourier table of ``space``'s channel sensitivities (built once per space)."""
    return belcour2017.FourierSensitivity.from_sensitivities(*channel_sensitivities(space))


def f82_tint_stack_substrate(f0, tint) -> tuple[np.ndarray, np.ndarray]:
    """(N₃ per channel, F82 per channel) of Blender's metal from Base Color F₀ and Specular Tint.

    The F82-tint model's reflectance at cos θ = 1/7 is g = clamp(Schlick(F₀, 1/7) · tint); the
    complex index is Gulbrandsen's (2014) fit with r = min(F₀, :data:`F82_MAX_REFLECTIVITY`) and
    edge tint g: n = (1 − g)(1 + √r)/(1 − √r) + g (1 − r)/(1 + r),
    k = √[(r (n + 1)² − (n − 1)²) / (1 − r)].
    """
    f0 = np.clip(np.asarray(f0, dtype=float), 0.0, 1.0)
    tint = np.clip(np.asarray(tint, dtype=float), 0.0, 1.0)
    g = np.clip((f0 + (1.0 - f0) * (1.0 - belcour2017.F82_COS) ** 5) * tint, 0.0, 1.0)
    r = np.minimum(f0, F82_MAX_REFLECTIVITY)
    root = np.sqrt(r)
    n = (1.0 - g) * (1.0 + root) / (1.0 - root) + g * (1.0 - r) / (1.0 + r)
    k = np.sqrt(np.maximum(0.0, (r * (n + 1.0) ** 2 - (n - 1.0) ** 2) / (1.0 - r)))
    return n + 1j * k, g


def cycles_stack(material: Material) -> belcour2017.FilmStack | None:
    """The material as Cycles' single-film model, or None when that model cannot express it."""
    if material.model != "exact" or material.illuminant != "E" or len(material.layers) > 1:
        return None
    if material.layers:
        film = material.indices()[1]
        if not isinstance(film, ConstantIndex) or film.k != 0.0:
            return None
        film_n = float(film.n)
    else:
        film_n = float(material.ambient)  # no film: the bare substrate
    spec = material.substrate
    if isinstance(spec, dict) and "f82_tint" in spec:
        n3, f82 = f82_tint_stack_substrate(spec["f82_tint"]["f0"], spec["f82_tint"]["tint"])
        return belcour2017.FilmStack(float(material.ambient), film_n, n3, f82)
    substrate = material.indices()[-1]
    if not isinstance(substrate, ConstantIndex):
        return None
    n3 = np.full(3, complex(substrate.n, substrate.k))
    return belcour2017.FilmStack(float(material.ambient), film_n, n3)


def fourier_reflectance(material: Material, stack, thickness_nm, cos_theta) -> np.ndarray:
    """Cycles' per-channel film reflectance (…, 3) at broadcast thicknesses (nm) and cosines."""
    return belcour2017.film_reflectance(stack, cos_theta, thickness_nm, sensitivity(material.colour_space))
