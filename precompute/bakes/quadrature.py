"""The bake's quadratures: Gauss–Legendre nodes, and wavelength nodes and weights λ → (output
RGB k, light RGB c).

:func:`gauss_legendre` and :func:`unit_gauss_legendre` are the Gauss–Legendre rules every
integral of the bake uses (half-vector elevations, view cosines, the GGX albedo), computed once
per order and shared read-only: numpy's ``leggauss`` solves an eigenproblem per call (≈ 25 ms
at 96 nodes, ≈ 0.3 s at 256), which was 37 % of a cold bake when each view rebuilt it.
:func:`spectral_quadrature` turns a film's spectral reflectance into the bake's 3×3 (spectral
mode) or per-channel (Cycles-matching mode) colour weights; fluorescent illuminants add one node
per emission line (the Composite Model). Pure numpy over :mod:`.spectra` and :mod:`.composite`.
"""

from __future__ import annotations

import functools

import numpy as np

from ..colour import composite, rgb_spaces, spectra

__all__ = ["gauss_legendre", "is_line_spectrum", "spectral_quadrature", "unit_gauss_legendre"]


@functools.cache
def gauss_legendre(order: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre nodes x_j and weights w_j on (−1, 1), ``order`` of each, read-only.

    Σ_j w_j f(x_j) = ∫₋₁¹ f(x) dx exactly for polynomials of degree < 2·order (numpy's
    ``leggauss``, Golub–Welsch). Cached by order: the arrays are shared, so they are returned
    with writing switched off.
    """
    if int(order) != order or order < 1:
        raise ValueError(f"Gauss–Legendre order must be a positive integer, got {order!r}")
    x, w = np.polynomial.legendre.leggauss(int(order))
    x.setflags(write=False)
    w.setflags(write=False)
    return x, w


@functools.cache
def unit_gauss_legendre(order: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`gauss_legendre` mapped to (0, 1): nodes (x + 1)/2, weights w/2 (they sum to 1), read-only."""
    x, w = gauss_legendre(order)
    s, ws = 0.5 * (x + 1.0), 0.5 * w
    s.setflags(write=False)
    ws.setflags(write=False)
    return s, ws


def is_line_spectrum(illuminant: str) -> bool:
    """Fluorescent lamps (FL1–FL12 / F1–F12) have emission lines: the Composite Model applies."""
    return illuminant.upper().startswith("F")


@functools.lru_cache(maxsize=16)
def _illuminant_composite(illuminant: str):
    wl, values = spectra.illuminant_table(illuminant)
    return composite.fit_composite(wl, values)


@functools.lru_cache(maxsize=32)
def spectral_quadrature(count: int, colour_space: str, illuminant: str, colour_mode: str):
    """Wavelength nodes (W′,) and weights G (W′, 3, 3) with M[k, c] = Σ_λ F(λ) G[λ, k, c].
    Cached (a bake and its film table each ask for it: 1.3 ms a call); both arrays read-only.

    spectral: G[λ, k, c] = Σ_j M_xyz→rgb[k, j] · X_j(λ) · S(λ) · B_c(λ) — lighting channel c
    upsampled with the linear basis B (Mallett & Yuksel 2019), times the illuminant S, integrated
    against the CMFs (X includes dλ and the E normalisation) and taken to the working space.
    per_channel (Cycles): the film's reflectance in channel k, R_k = Σ_λ F(λ) w_k(λ) S(λ),
    multiplies light channel k: G[λ, k, c] = δ_kc w_k(λ) S(λ), with w_k Cycles' channel
    sensitivity (spectra.channel_weights: the CMFs through Blender's XYZ → scene-linear matrix,
    no chromatic adaptation, each channel normalised to 1 for a flat spectrum). Used for the
    materials Cycles' own Fourier-space film cannot express (film_channels).

    Line illuminants follow the Composite Model (Sun, Drew & Fracchia 1999): the smooth part is
    integrated on the grid, and each emission line becomes one more node at its exact wavelength
    with weight P_j c̄(λ_j) / ∫c̄, so the film is evaluated exactly where the lamp emits.
    """
    wl = spectra.wavelength_grid(count)
    per_channel = colour_mode == "per_channel"
    if per_channel:
        m = rgb_spaces.scene_linear_matrix(colour_space)
        totals = spectra.cmf_integrals() @ m.T  # each channel's ∫ s_k dλ
        grid_w = rgb_spaces.channel_weights(wl, colour_space)
    else:
        m = rgb_spaces.xyz_to_rgb_matrix(colour_space)
        totals = None
        grid_w = spectra.xyz_weights(wl) @ m.T
    basis = rgb_spaces.rgb_basis(wl, colour_space)  # (3, W)
    if is_line_spectrum(illuminant):
        comp = _illuminant_composite(illuminant)
        scale = 1.0 / comp.to_xyz()[1]  # Y = 1, as illuminant_spd
        smooth = comp.evaluate_smooth(wl) * scale
        lines = np.asarray(comp.spike_wavelengths_nm, dtype=float)
        powers = np.asarray(comp.spike_powers) * scale
        if per_channel:
            line_w = (spectra.cmfs(lines) @ m.T) * powers[:, None] / totals
        else:
            line_w = (spectra.cmfs(lines) * powers[:, None] / spectra.cmf_integrals()) @ m.T
        rgb_w = np.concatenate([grid_w * smooth[:, None], line_w])
        line_basis = np.stack([np.interp(lines, wl, b) for b in basis])
        basis = np.concatenate([basis, line_basis], axis=1)
        wl = np.concatenate([wl, lines])
    else:
        rgb_w = grid_w * spectra.illuminant_spd(illuminant, wl)[:, None]
    g = rgb_w[:, :, None] * (np.eye(3)[None, :, :] if per_channel else basis.T[:, None, :])
    wl.flags.writeable = False
    g.flags.writeable = False
    return wl, g
