"""The film's colour matrices per u = cos θ: what one light direction's reflection looks like.

:func:`film_rgb_matrices` gives RG(u) = Σ_λ R(u, λ) G[λ], the 3×3 matrix that turns a light's
RGB into the reflected RGB at the half-vector cosine u (spectral: row = output RGB, column =
light RGB), on a fine uniform u grid; the brute-force ground truth (render.shade_reference) uses
it per sample. :func:`film_table` tabulates it at a bake's thickness rows with the bake's
multiple-scattering factor: the film table the World's lamps are shaded with
(shading.lamps.shade, glsl/tf_lamps.glsl).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .. import brdf, constants
from ..bakes import bake, planner
from ..bakes.chunks import chunked_sweep
from ..bakes.kernel import u_interpolation_matrix, uniform_interpolation_matrix
from ..bakes.progress import checkpoint
from ..optics import reflectance
from . import film_channels

#: Samples of the film table in u = cos θ (uniform 0…1 inclusive).
FILM_SAMPLES = 128


def film_rgb_matrices(material, thickness_nm=None, samples: int = 4097):
    """RG(u): Σ_λ R(u, λ) G[λ] as (samples, 3, 3) on a uniform u grid, for the ground truth.

    Returns (u, RG, R, λ, G): the grid, the matrices, the reflectance (samples, W), the
    wavelength nodes and the spectral quadrature weights of the bake's plan. In the per-channel
    mode RG is diagonal, the film per channel (bake.channel_film: Cycles' film where it applies),
    and R is None when that film does not go through a spectrum.
    """
    p = planner.plan(material)
    wl, g = bake.spectral_quadrature(
        p.wavelength_count, material.colour_space, material.illuminant, material.colour_mode
    )
    d = material.thicknesses()
    if thickness_nm is not None and d:
        d = [float(thickness_nm)] + d[1:]
    method = "glassner2000" if material.model == "glassner2000" else "exact"
    u = np.linspace(0.0, 1.0, samples)
    if material.colour_mode == "per_channel":
        row = np.array([d], dtype=float).reshape(1, len(d))
        rgb = bake.channel_film(material, material.indices(), row, wl, g, u, method)[0]
        r = (
            None
            if film_channels.cycles_stack(material) is not None
            else reflectance(material.indices(), d, wl, u, method=method)
        )
        return u, rgb[..., None] * np.eye(3), r, wl, g
    r = reflectance(material.indices(), d, wl, u, method=method)
    rg = bake.clamp_film_rgb(np.einsum("uw,wkc->ukc", r, g), material.colour_mode)
    return u, rg, r, wl, g


def white_reflectance(material, thickness_nm, cos_theta) -> np.ndarray:
    """The film's RGB reflectance of white light (1, 1, 1), (…, 3), at broadcast thicknesses of
    the top layer (nm) and incidence cosines: each pixel of a white furnace at roughness 0.

    per_channel: the film per channel (Cycles' pipeline, bake.channel_film); spectral: the row
    sums of the 3×3 matrices (E white, docs/conventions.md).
    """
    d, cos = np.broadcast_arrays(np.asarray(thickness_nm, dtype=float), np.asarray(cos_theta, dtype=float))
    stack = film_channels.cycles_stack(material) if material.colour_mode == "per_channel" else None
    if stack is not None:
        return film_channels.fourier_reflectance(material, stack, d, cos)
    p = planner.plan(material)
    wl, g = bake.spectral_quadrature(
        p.wavelength_count, material.colour_space, material.illuminant, material.colour_mode
    )
    method = "glassner2000" if material.model == "glassner2000" else "exact"
    out = np.zeros(d.shape + (3,))
    rest = material.thicknesses()[1:]
    for value in np.unique(d):
        sel = d == value
        layers = [float(value), *rest] if material.layers else []
        r = reflectance(material.indices(), layers, wl, cos[sel], method=method)
        out[sel] = bake.clamp_film_rgb(r @ g.sum(axis=2), material.colour_mode)
    return out


@dataclass(frozen=True)
class FilmTable:
    """The film's specular reflectance against u = cos θ (uniform 0…1, ``FILM_SAMPLES``).

    ``reflectance``: (T, U, 3, 3) spectral (row = output RGB, column = light RGB) or (T, U, 3)
    per channel, T = the bake's thickness rows. ``multiscatter``: (T, U, 3) the factor the
    bake applied at view cosine u (1 without multiple scattering), so lamps match the table.
    ``diffuse``: (T, U, 3), the diffuse base's BRDF at view cosine u as the light objects light it
    (:func:`diffuse_view`), or None without a diffuse base.
    """

    reflectance: np.ndarray
    multiscatter: np.ndarray
    thicknesses_nm: np.ndarray
    diffuse: np.ndarray | None = None

    @property
    def spectral(self) -> bool:
        """True for a spectral (3×3 per coefficient) table, False for per-channel RGB."""
        return self.reflectance.ndim == 4


def film_table(result, samples: int = FILM_SAMPLES) -> FilmTable:
    """The film reflectance of a :class:`bake.BakeResult` 's material at its thickness rows.

    A fresh spectral bake keeps its reflectance at its u nodes (``node_reflectance``): the table
    is then interpolated from it (:func:`_interpolated_rows`, the bake's own piecewise-Chebyshev
    interpolation, within its tolerance of 1e-6 relative above u = 0.0125), with no second
    sweep: half the warm work of a thickness or IOR edit. Otherwise one reflectance sweep for
    every thickness (:func:`_film_rows`). Either way one albedo integral's geometry is shared
    by every row's multiple-scattering factor (:func:`_multiscatter`). Equal to the per-row
    :func:`film_rgb_matrices` and :func:`brdf.directional_albedo` to float rounding (swept) or
    the interpolation's tolerance (tests/viewport/test_live.py). The viewport computes it on the bake's
    worker (:func:`addon.bakes.tables.get_film`), never in a draw.
    """
    spectral = np.asarray(result.data).ndim == 5
    nodes = getattr(result, "node_reflectance", None)
    if nodes is None or not spectral:
        return _film_table(result.material, result.thicknesses_nm, spectral, samples)
    u = np.linspace(0.0, 1.0, int(samples))
    rg = _interpolated_rows(result.material, nodes, result.u_nodes, u)
    thicknesses = np.atleast_1d(np.asarray(result.thicknesses_nm, dtype=float))
    ms = _multiscatter(result.material, u, rg)
    return FilmTable(
        np.ascontiguousarray(rg), np.ascontiguousarray(ms), thicknesses, diffuse_view(result.material, u, rg)
    )


def _interpolated_rows(material, nodes: np.ndarray, degree: int, u: np.ndarray) -> np.ndarray:
    """RG(u) (T, U, 3, 3) from the spectral reflectance at a bake's u nodes (T, N, W), read at
    ``u`` with the bake's piecewise-Chebyshev interpolation of ``degree`` nodes per interval."""
    p = planner.plan(material)
    _wl, g = bake.spectral_quadrature(
        p.wavelength_count, material.colour_space, material.illuminant, material.colour_mode
    )
    t, n, w = nodes.shape
    uniform = u.size > 1 and np.array_equal(u, np.linspace(0.0, 1.0, u.size))
    degree = int(degree)  # (U, N) weights below: one product for every row; the film grid's cached
    weights = uniform_interpolation_matrix(degree, u.size) if uniform else u_interpolation_matrix(degree, u)
    r = weights @ nodes.transpose(1, 0, 2).reshape(n, t * w)  # (U, T·W), u-major
    rgb = (r.reshape(-1, w) @ g.reshape(w, -1)).reshape((u.size, t) + g.shape[1:])  # (U, T, 3, 3)
    return bake.clamp_film_rgb(np.ascontiguousarray(rgb.transpose(1, 0, 2, 3)), material.colour_mode)


def film_table_of(material, samples: int = FILM_SAMPLES) -> FilmTable:
    """The :func:`film_table` that :func:`bake.bake` of ``material`` will have, computed without
    the bake: its thickness rows are the bake's plan's (:func:`bake.active_stack`), so the
    viewport computes it on a second thread beside the bake (equal to the result's to float
    rounding: tests/viewport/test_live.py)."""
    m = planner.table_material(material)
    _indices, _sets, axis = planner.active_stack(m, planner.plan(m).thickness_samples)
    return _film_table(m, axis, m.colour_mode != "per_channel", samples)


def _film_table(material, thicknesses_nm, spectral: bool, samples: int) -> FilmTable:
    thicknesses = np.atleast_1d(np.asarray(thicknesses_nm, dtype=float))
    u = np.linspace(0.0, 1.0, int(samples))
    rg = _film_rows(material, thicknesses, u)  # (T, U, 3, 3)
    reflectance = rg if spectral else np.einsum("tukk->tuk", rg)
    ms = _multiscatter(material, u, rg)
    return FilmTable(
        np.ascontiguousarray(reflectance),
        np.ascontiguousarray(ms),
        thicknesses,
        diffuse_view(material, u, rg),
    )


def diffuse_view(material, u: np.ndarray, rg: np.ndarray) -> np.ndarray | None:
    """(T, U, 3): the diffuse base's BRDF at view cosine u, for the light objects
    (shading.lights.shade); None without a diffuse base. The World lights the base through the
    table (bake._channel_diffuse_term, bake._diffuse_term); a light object's sample adds this
    times its irradiance E cos θi.

    Per channel, as Cycles' Principled BSDF layers it: Base Color / π × the specular layer's
    :func:`bake.layering_weight` at the view angle (no film on the light's way in). Spectral:
    Base Color / π × (1 − R(u)) per channel, R the film's reflectance of white light (the
    light's way in, 1 − R(cos θi), is applied per sample): the spectral product of
    brdf.diffuse_under_film taken per colour channel.
    """
    if material.base_color is None:
        return None
    base = np.asarray(material.base_color, dtype=float) / np.pi
    if material.colour_mode == "per_channel":
        film_o = np.einsum("tukk->tuk", rg)
        weight = bake.layering_weight(material, film_o, np.asarray(u, dtype=float))
        return np.ascontiguousarray(weight[..., None] * base)
    return np.ascontiguousarray(np.clip(1.0 - rg.sum(axis=-1), 0.0, 1.0) * base)


def _film_rows(material, thicknesses: np.ndarray, u: np.ndarray) -> np.ndarray:
    """RG(u) (T, U, 3, 3) of :func:`film_rgb_matrices` at each top-layer thickness (nm) of
    ``thicknesses``, every row in one sweep; a material without layers has one row, repeated."""
    p = planner.plan(material)
    wl, g = bake.spectral_quadrature(
        p.wavelength_count, material.colour_space, material.illuminant, material.colour_mode
    )
    base = material.thicknesses()
    sets = np.array([[float(t), *base[1:]] for t in thicknesses]) if base else np.zeros((1, 0))
    method = "glassner2000" if material.model == "glassner2000" else "exact"
    if material.colour_mode == "per_channel":
        rg = bake.channel_film(material, material.indices(), sets, wl, g, u, method)[..., None] * np.eye(3)
    else:
        r = _sweep(material.indices(), sets, wl, u, method)
        rgb = (r.reshape(-1, r.shape[-1]) @ g.reshape(g.shape[0], -1)).reshape(r.shape[:2] + g.shape[1:])
        rg = bake.clamp_film_rgb(rgb, material.colour_mode)
    return rg if base else np.broadcast_to(rg, (thicknesses.size,) + rg.shape[1:])


def _sweep(indices, sets: np.ndarray, wl: np.ndarray, u: np.ndarray, method: str) -> np.ndarray:
    """R (T, U, W) of every thickness set in one sweep; a set with a layer of thickness exactly 0
    goes through :func:`reflectance`, which removes that layer ("exact": the bare interface,
    finite at grazing incidence where the Airy form of an air film in air is 0/0)."""
    if sets.shape[1] == 0:
        return reflectance(indices, [], wl, u, method=method)[None]
    with np.errstate(invalid="ignore", divide="ignore"):  # the 0 nm rows, replaced below
        r = chunked_sweep(indices, sets, wl, u, method)
    if method == "exact":
        for row in np.flatnonzero((sets == 0.0).any(axis=1)):
            r[row] = reflectance(indices, list(sets[row]), wl, u, method=method)
    return r


def _albedo_weights(roughness: float, mu: np.ndarray, u: np.ndarray) -> np.ndarray:
    """(M, U) weights W with Σ_j W[m, j] R(u_j) = :func:`brdf.directional_albedo` at view cosine
    ``mu[m]`` of a reflectance R tabulated on the uniform grid ``u`` and read with linear
    interpolation (as ``np.interp``): the integral's geometry, shared by every row."""
    alpha = float(brdf.alpha_from_roughness(roughness))
    cos_o = np.clip(mu, constants.MIN_COS, 1.0)
    h, wgt = brdf.ggx_importance_grid(alpha, 128, 64)
    last = u.size - 1
    out = np.empty((cos_o.size, u.size))
    for m, co in enumerate(cos_o):
        wo = np.array([np.sqrt(max(0.0, 1.0 - co * co)), 0.0, co])
        cos_h = h @ wo
        wi = brdf.reflect(wo[None, :], h)
        ok = (cos_h > 0) & (wi[:, 2] > 0)
        g2 = brdf.G2_smith_height_correlated(np.maximum(wi[:, 2], constants.MIN_COS), co, alpha)
        scalar = np.where(ok, g2 * cos_h / (co * h[:, 2]), 0.0) * wgt
        x = np.clip(cos_h, 0.0, 1.0) * last  # position on the uniform u grid
        left = np.minimum(np.floor(x).astype(np.int64), last - 1)
        frac = x - left
        out[m] = np.bincount(left, scalar * (1.0 - frac), u.size)
        out[m] += np.bincount(left + 1, scalar * frac, u.size)
        checkpoint()  # one view cosine (a bake's progress and cancellation point)
    return out


@functools.lru_cache(maxsize=1)
def _albedo_nodes() -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre nodes and weights on [0, 1] (32) of the film's F_avg integral over μ.
    Cached, read-only."""
    mu, wmu = np.polynomial.legendre.leggauss(32)
    nodes, weights = 0.5 * (mu + 1.0), 0.5 * wmu
    nodes.flags.writeable = False
    weights.flags.writeable = False
    return nodes, weights


@functools.lru_cache(maxsize=16)
def _uniform_albedo_weights(roughness: float, samples: int) -> np.ndarray:
    """:func:`_albedo_weights` on :func:`_albedo_nodes` and a uniform u grid of ``samples``: it
    depends on the roughness alone (29 ms a call), so a thickness or IOR edit reuses it.
    Read-only."""
    weights = _albedo_weights(roughness, _albedo_nodes()[0], np.linspace(0.0, 1.0, samples))
    weights.flags.writeable = False
    return weights


def _multiscatter(material, u: np.ndarray, rg: np.ndarray) -> np.ndarray:
    """(T, U, 3): the factor :func:`bake.apply_multiscatter` applies at view cosine u, per row.

    "cycles": the film-free substrate's F_avg (bake.cycles_fresnel_average), as the bake, the
    same for every row. "film": F_avg per row and channel from the film's single-scattering
    white-light albedo over E (the bake takes the same ratio on its own view samples, so the two
    agree to the quadrature: a few 1e-3 of the factor).
    """
    rows = rg.shape[0]
    if material.multiscatter == "none" or material.roughness <= 0.0:
        return np.ones((rows, u.size, 3))
    if material.multiscatter == "cycles":  # the bake's own factor, per output row of a unit table
        one = bake.apply_multiscatter(np.ones((1, u.size, 1, 3, 1)), material, u)[0, :, 0, :, 0]
        return np.broadcast_to(one, (rows, u.size, 3))
    white = rg.sum(axis=-1)  # (T, U, 3): the film's reflectance of white light per output channel
    mu, wmu = _albedo_nodes()
    if u.size >= 2 and np.array_equal(u, np.linspace(0.0, 1.0, u.size)):
        weights = _uniform_albedo_weights(float(material.roughness), u.size)
    else:
        weights = _albedo_weights(float(material.roughness), mu, u)
    rows, count = white.shape[0], white.shape[1]
    e_film = (weights @ white.transpose(1, 0, 2).reshape(count, -1)).reshape(-1, rows, 3).transpose(1, 0, 2)
    e = brdf.ggx_E(float(material.roughness), tuple(np.clip(mu, constants.MIN_COS, 1.0).tolist()))
    ratio = e_film / e[None, :, None] * (2.0 * mu * wmu)[None, :, None]
    f_avg = np.clip(np.sum(ratio, axis=1), 0.0, 1.0)  # (T, 3)
    return np.moveaxis(brdf.multiscatter_scale(u, material.roughness, f_avg), 0, 1)
