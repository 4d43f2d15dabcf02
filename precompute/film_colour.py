"""The film's colour matrices per u = cos θ: what one light direction's reflection looks like.

:func:`film_rgb_matrices` gives RG(u) = Σ_λ R(u, λ) G[λ], the 3×3 matrix that turns a light's
RGB into the reflected RGB at the half-vector cosine u (spectral: row = output RGB, column =
light RGB), on a fine uniform u grid; the brute-force ground truth (render.shade_reference) uses
it per sample. :func:`film_table` tabulates it at a bake's thickness rows with the bake's
multiple-scattering factor: the film table the World's lamps are shaded with
(shading.lamps.shade, glsl/tf_lamps.glsl).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import bake, brdf, constants
from .optics import reflectance

#: Samples of the film table in u = cos θ (uniform 0…1 inclusive).
FILM_SAMPLES = 128


def film_rgb_matrices(material, thickness_nm=None, samples: int = 4097):
    """RG(u): Σ_λ R(u, λ) G[λ] as (samples, 3, 3) on a uniform u grid, for the ground truth.

    Returns (u, RG, R, λ, G): the grid, the matrices, the reflectance (samples, W), the
    wavelength nodes and the spectral quadrature weights of the bake's plan.
    """
    p = bake.plan(material)
    wl, g = bake.spectral_quadrature(
        p.wavelength_count, material.colour_space, material.illuminant, material.colour_mode
    )
    d = material.thicknesses()
    if thickness_nm is not None and d:
        d = [float(thickness_nm)] + d[1:]
    method = "glassner2000" if material.model == "glassner2000" else "exact"
    u = np.linspace(0.0, 1.0, samples)
    r = reflectance(material.indices(), d, wl, u, method=method)
    rg = bake.clamp_film_rgb(np.einsum("uw,wkc->ukc", r, g), material.colour_mode)
    return u, rg, r, wl, g


@dataclass(frozen=True)
class FilmTable:
    """The film's specular reflectance against u = cos θ (uniform 0…1, ``FILM_SAMPLES``).

    ``reflectance``: (T, U, 3, 3) spectral (row = output RGB, column = light RGB) or (T, U, 3)
    per channel, T = the bake's thickness rows. ``multiscatter``: (T, U, 3) the factor the
    bake applied at view cosine u (1 without multiple scattering), so lamps match the table.
    """

    reflectance: np.ndarray
    multiscatter: np.ndarray
    thicknesses_nm: np.ndarray

    @property
    def spectral(self) -> bool:
        """True for a spectral (3×3 per coefficient) table, False for per-channel RGB."""
        return self.reflectance.ndim == 4


def film_table(result, samples: int = FILM_SAMPLES) -> FilmTable:
    """The film reflectance of a :class:`bake.BakeResult` 's material at its thickness rows."""
    material = result.material
    thicknesses = np.atleast_1d(np.asarray(result.thicknesses_nm, dtype=float))
    u = np.linspace(0.0, 1.0, int(samples))
    rows = []
    for t in thicknesses:
        _, rg, _, _, _ = film_rgb_matrices(material, float(t) if material.thicknesses() else None, samples)
        rows.append(rg)
    rg = np.stack(rows)  # (T, U, 3, 3)
    spectral = np.asarray(result.data).ndim == 5
    reflectance = rg if spectral else np.einsum("tukk->tuk", rg)
    ms = np.stack([_multiscatter(material, u, rg_t) for rg_t in rg])
    return FilmTable(reflectance, np.ascontiguousarray(ms), thicknesses)


def _multiscatter(material, u: np.ndarray, rg: np.ndarray) -> np.ndarray:
    """(U, 3): the factor :func:`bake.apply_multiscatter` applies at view cosine u.

    "cycles": the bare dielectric's F_avg, as the bake. "film": F_avg per channel from the
    film's single-scattering white-light albedo over E (the bake takes the same ratio on its
    own view samples, so the two agree to the quadrature: a few 1e-3 of the factor).
    """
    if material.multiscatter == "none" or material.roughness <= 0.0:
        return np.ones((u.size, 3))
    if material.multiscatter == "cycles":  # the bake's own factor, per output row of a unit table
        return bake.apply_multiscatter(np.ones((1, u.size, 1, 3, 1)), material, u)[0, :, 0, :, 0]
    white = rg.sum(axis=-1)  # (U, 3): the film's reflectance of white light per output channel
    mu, wmu = np.polynomial.legendre.leggauss(32)
    mu, wmu = 0.5 * (mu + 1.0), 0.5 * wmu

    def film_reflectance(x):
        return np.stack([np.interp(x, u, white[:, c]) for c in range(3)], axis=-1)

    e_film = brdf.directional_albedo(mu, material.roughness, film_reflectance, 128, 64)  # (32, 3)
    e = brdf.ggx_E(float(material.roughness), tuple(np.clip(mu, constants.MIN_COS, 1.0).tolist()))
    f_avg = np.clip(np.sum(e_film / e[:, None] * (2.0 * mu * wmu)[:, None], axis=0), 0.0, 1.0)
    return np.stack([brdf.multiscatter_scale(u, material.roughness, f) for f in f_avg], axis=-1)
