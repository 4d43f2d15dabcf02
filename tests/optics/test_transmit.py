"""A transparent film's wall (precompute.shading.transmit): energy, transparency, bounds.

The wall's transmittance comes from the film's reflectance (T = 1 − R for a lossless film);
here it is checked against an independent transmittance (a characteristic-matrix computation
of the film's transmitted power, Born & Wolf §1.6, written out below), in a white furnace
(T + R = 1), at zero thickness (a film of the ambient's index vanishes) and against the largest
reflectance a single film can have (a bubble never darkens the background below 1 − R_max).
"""

import numpy as np
import pytest

from precompute.bakes import bake, planner
from precompute.colour import film_colour
from precompute.materials.material import Layer, Material, preset
from precompute.shading import transmit

N_FILM = 1.33
COS = np.array([1.0, 0.9, 0.7, 0.5, 0.3, 0.12])


def film_material(colour_mode: str, thickness: float = 450.0, substrate: float = 1.0) -> Material:
    return Material(
        layers=(Layer(N_FILM, thickness),), substrate=substrate, roughness=0.05, colour_mode=colour_mode
    )


def matrix_transmittance(n_film, d_nm, n_out, wl_nm, cos_i):
    """Transmitted power of ambient (1) | film | n_out by the characteristic matrix, per
    polarisation, averaged: (A, W). Independent of precompute.optics (no Airy sum)."""
    cos_i = np.asarray(cos_i, dtype=float)[:, None]
    wl = np.asarray(wl_nm, dtype=float)[None, :]
    s2 = 1.0 - cos_i**2
    cos_f = np.sqrt(1.0 - s2 / n_film**2 + 0j)
    cos_o = np.sqrt(1.0 - s2 / n_out**2 + 0j)
    delta = 2.0 * np.pi * n_film * d_nm * cos_f / wl
    out = 0.0
    for pol in ("s", "p"):
        if pol == "s":
            y0, y1, y2 = cos_i, n_film * cos_f, n_out * cos_o
        else:
            y0, y1, y2 = 1.0 / cos_i, n_film / cos_f, n_out / cos_o
        m11, m12 = np.cos(delta), 1j * np.sin(delta) / y1
        m21, m22 = 1j * y1 * np.sin(delta), np.cos(delta)
        b = m11 + m12 * y2
        c = m21 + m22 * y2
        t = 4.0 * y0 * np.real(y2) / np.abs(y0 * b + c) ** 2
        out = out + 0.5 * t
    return np.real(out)


@pytest.mark.parametrize("colour_mode", ["spectral", "per_channel"])
def test_lossless_free_standing_film_transmits_one_minus_r(colour_mode):
    """Per channel, T of the wall = the channel-weighted transmitted power of the film, and
    T + R = 1: a white furnace behind and around a smooth bubble stays white."""
    material = film_material(colour_mode)
    thickness = np.array([0.0, 120.0, 300.0, 450.0, 900.0])[:, None]
    r = film_colour.white_reflectance(material, thickness, COS[None, :])
    t, s = transmit.wall(r, COS[None, :], transmit.WALL_SHEET, 1.0)
    # A channel of a spectrum in [0, 1] may leave [0, 1] (Rec.709's matching functions have
    # negative lobes): the wall clamps r there; everywhere else T + R = 1 exactly.
    inside = (r >= 0.0) & (r <= 1.0)
    assert inside.mean() > 0.9
    assert np.allclose((t + s * r)[inside], 1.0, atol=1e-12)  # energy: T + R = 1
    assert np.allclose(t[inside], (1.0 - r)[inside], atol=1e-12)
    if colour_mode == "spectral":  # the same T from the film's own transmission, per wavelength
        p = planner.plan(material)
        wl, g = bake.spectral_quadrature(p.wavelength_count, material.colour_space, "E", "spectral")
        for i, d in enumerate(thickness[:, 0]):
            tw = matrix_transmittance(N_FILM, d, 1.0, wl, COS)
            assert np.allclose(t[i][inside[i]], (tw @ g.sum(axis=2))[inside[i]], atol=1e-9)
    # complementary tint: where the film reflects more red, it transmits less red
    order = np.argsort(r[3, 0])
    assert np.all(np.diff(t[3, 0][order]) <= 1e-12)


def test_cycles_thin_wall_conserves_energy_and_sums_the_slab_series():
    r = np.linspace(0.0, 1.0, 11)[:, None] * np.ones(3)
    t, s = transmit.wall(r, np.ones(11), transmit.WALL_CYCLES)
    assert np.allclose(t + s * r, 1.0)
    # the series t1 t2 Σ (r2²)^k and r1 + t' r2, summed term by term
    k = np.arange(200)[:, None, None]
    series_t = np.sum((1 - r) ** 2 * r ** (2 * k), axis=0)
    assert np.allclose(t[:-1], series_t[:-1], atol=1e-9)
    assert np.allclose((s * r)[:-1], (r + series_t * r)[:-1], atol=1e-9)


def test_a_tinted_cycles_thin_wall_absorbs_per_pass_and_reduces_to_the_untinted_one():
    """Base Color as Cycles' thin wall takes it: c = tint^(1 / cos θ_t) per pass through the
    sheet, the series t1 c t2 Σ (c r2)^(2k) and r1 + t' c r2; tint 1 gives the untinted wall."""
    r = np.linspace(0.0, 0.9, 10)[:, None] * np.ones(3)
    cos_v = np.linspace(1.0, 0.2, 10)
    tint = np.array([0.8, 0.5, 0.2])
    eta = 1.5
    t, s = transmit.wall(r, cos_v, transmit.WALL_CYCLES, eta, tint)
    cos_t = np.sqrt(1.0 - (1.0 - cos_v**2) / eta**2)
    c = tint[None, :] ** (1.0 / cos_t[:, None])
    k = np.arange(200)[:, None, None]
    series_t = np.sum(c * (1 - r) ** 2 * (c * r) ** (2 * k), axis=0)
    assert np.allclose(t, series_t, atol=1e-12)
    assert np.allclose(s * r, r + series_t * c * r, atol=1e-12)
    assert np.all(t + s * r < 1.0 - 1e-3)  # the tint absorbs: less than the lossless wall's 1
    assert np.allclose(t[0], tint, atol=1e-12)  # r = 0 at normal incidence: the tint alone
    t1, s1 = transmit.wall(r, cos_v, transmit.WALL_CYCLES, eta, np.ones(3))
    t0, s0 = transmit.wall(r, cos_v, transmit.WALL_CYCLES)
    assert np.allclose(t1, t0, atol=1e-12) and np.allclose(s1, s0, atol=1e-12)
    # a bubble (η = 1) at grazing: the path through the sheet grows as 1 / cos θ
    grazing = transmit.tint_pass(tint, np.array([1.0, 0.5]), 1.0)
    assert np.allclose(grazing, [tint, tint**2], atol=1e-12)
    assert np.allclose(transmit.wall_tint((transmit.WALL_SOLID, 1.5)), 1.0)
    assert np.allclose(transmit.wall_tint((transmit.WALL_SOLID, 1.5, 0.1, 0.2, 0.3)), [0.1, 0.2, 0.3])


def test_sheet_of_glass_conserves_energy_where_not_capped():
    material = film_material("spectral", 140.0, substrate=1.52)
    r = film_colour.white_reflectance(material, np.array([100.0, 200.0, 300.0])[:, None], COS[None, :])
    t, s = transmit.wall(r, COS[None, :], transmit.WALL_SHEET, 1.52)
    assert np.all(s < transmit.WALL_SCALE_MAX if hasattr(transmit, "WALL_SCALE_MAX") else s < 16)
    assert np.allclose(t + s * r, 1.0, atol=1e-9)
    # the bare back face costs transmission: less than the film alone lets through
    assert np.all(t < 1.0 - r + 1e-12)


@pytest.mark.parametrize("colour_mode", ["spectral", "per_channel"])
def test_zero_thickness_film_of_the_ambient_index_is_fully_transparent(colour_mode):
    material = film_material(colour_mode, 0.0)
    r = film_colour.white_reflectance(material, np.zeros((1, COS.size)), COS[None, :])
    t, s = transmit.wall(r, COS[None, :], transmit.WALL_SHEET, 1.0)
    behind = np.array([0.2, 0.5, 0.9])
    out = transmit.composite(behind, s * r * 1.0, t)  # under a white World
    assert np.allclose(out, behind, atol=1e-6)
    assert np.allclose(transmit.coverage(t), 0.0, atol=1e-6)


@pytest.mark.parametrize("colour_mode", ["spectral", "per_channel"])
def test_bubble_never_darkens_the_background_below_one_minus_r_max(colour_mode):
    """R_max of one film of index n in air at angle θ: the quarter-wave maximum 4ρ²/(1 + ρ²)² of
    the Airy sum for each polarisation (ρ: the air–film Fresnel amplitude), averaged."""
    material = preset("soap_film").with_(colour_mode=colour_mode, thickness_range_nm=None)
    d = np.linspace(0.0, 2000.0, 101)[:, None]
    r = film_colour.white_reflectance(material, d, COS[None, :])
    t, _ = transmit.wall(r, COS[None, :], transmit.WALL_SHEET, 1.0)
    cos_f = np.sqrt(1.0 - (1.0 - COS**2) / N_FILM**2)
    rho_s = (COS - N_FILM * cos_f) / (COS + N_FILM * cos_f)
    rho_p = (N_FILM * COS - cos_f) / (N_FILM * COS + cos_f)
    r_max = 0.5 * sum(4 * x**2 / (1 + x**2) ** 2 for x in (rho_s, rho_p))
    # per wavelength the film never reflects more than R_max (the Airy sum's maximum)
    from precompute.optics import reflectance

    wl = np.linspace(380.0, 780.0, 81)
    spectral = np.stack([reflectance([1.0, N_FILM, 1.0], [float(x)], wl, COS) for x in d[:, 0]])
    assert np.all(spectral <= r_max[None, :, None] + 1e-12)
    assert r_max[0] == pytest.approx(((N_FILM**2 - 1) / (N_FILM**2 + 1)) ** 2)
    # what the eye sees of a white background through the bubble: its luminance never drops
    # below 1 − R_max (Rec.709 Y; the matching functions' negative lobes let one channel dip)
    # (measured margins ≥ +0.001). Cycles' per-channel film (the Airy sum cut after three orders,
    # then clamped) overshoots R_max at grazing views: −0.015 at cos θ = 0.12, so it is held to
    # the bound down to cos θ = 0.3.
    luminance = t @ np.array([0.2126, 0.7152, 0.0722])
    held = COS >= (0.3 if colour_mode == "per_channel" else 0.0)
    margin = (luminance - (1.0 - r_max)[None, :])[:, held]
    assert np.all(margin >= 0.0), margin.min()
    dip = np.min(t - (1.0 - r_max)[None, :, None])
    lowest = np.min(luminance - (1 - r_max))
    print(f"{colour_mode}: lowest channel T − (1 − R_max) = {dip:.3f}; luminance {lowest:.3f}")
    assert t.min() < 1.0 - 0.5 * r_max.min()  # the bound is approached: the film does reflect


def _refract(d, n, eta):
    """Snell's law in vector form: d unit, n unit against d, eta = n_in / n_out."""
    c = -np.sum(d * n, axis=-1, keepdims=True)
    k = 1.0 - eta**2 * (1.0 - c**2)
    return eta * d + (eta * c - np.sqrt(k)) * n


def test_solid_exit_is_the_ray_traced_through_a_glass_sphere():
    """Trace rays into a unit sphere of glass (Snell in, chord, Snell out) and compare."""
    rng = np.random.default_rng(7)
    eta = 1.5
    d = np.tile([0.0, 1.0, 0.0], (200, 1))
    offsets = rng.uniform(-0.95, 0.95, size=(200, 2))
    keep = np.hypot(offsets[:, 0], offsets[:, 1]) < 0.95
    d, offsets = d[keep], offsets[keep]
    hit = np.stack([offsets[:, 0], -np.sqrt(1.0 - (offsets**2).sum(-1)), offsets[:, 1]], -1)
    n = hit.copy()  # outward normal, facing the viewer at -y
    inside = _refract(d, n, 1.0 / eta)
    inside /= np.linalg.norm(inside, axis=-1, keepdims=True)
    chord = -2.0 * np.sum(hit * inside, axis=-1, keepdims=True)
    out_n = hit + chord * inside
    out = _refract(inside, -out_n, eta)
    out /= np.linalg.norm(out, axis=-1, keepdims=True)
    assert np.allclose(transmit.solid_exit(n, -d, eta), out, atol=1e-9)
    assert np.allclose(transmit.solid_exit(n, -d, 1.0), d, atol=1e-12)  # η = 1: straight through


def test_cycles_stops_shadow_rays_only_at_rough_walls_of_another_index():
    """Cycles' rule as measured (tests/eevee/test_wall_shadows.py renders it): Roughness 0.0044
    lets a shadow ray through a thin wall of IOR 1.1 or 1.52, 0.0045 stops it; IOR 1 never does."""
    for eta in (1.1, 1.52, 0.75):
        assert not transmit.wall_stops_shadow_rays(eta, 0.0044)
        assert transmit.wall_stops_shadow_rays(eta, 0.0045)
    for roughness in (0.0, 0.05, 0.3, 1.0):
        assert not transmit.wall_stops_shadow_rays(1.0, roughness)
    assert transmit.wall_stops_shadow_rays(1.0001, 0.05)  # Cycles: 0.52 under it, 0.89 at IOR 1
