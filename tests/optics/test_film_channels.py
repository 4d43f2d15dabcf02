"""The Cycles-matching colour mode: the film per channel (precompute/colour/film_channels.py,
precompute/optics/belcour2017.py) against independent implementations of the same method.

- the Airy cosine series summed to many orders is the exact Airy film (optics.reflectance) at
  one wavelength, for dielectric and conductor substrates;
- the sensitivity table is the discrete Fourier sum it stands for (evaluated directly, not by
  FFT) and close to the continuous Fourier integral of the sensitivities;
- in a white furnace, the per-channel film equals a direct spectral integration of the
  three-order series against the same RGB sensitivities (no table, no FFT) to ΔE2000 ≪ 1;
- the cutoffs (no film at ≤ 0.1 nm, the index blend below 1 nm), the clamp, the F82 metal, the
  per-channel white normalisation, and the bake's Cycles layering of a diffuse base.
Pure numpy: no bpy (the matrix against Blender's own OCIO config is in tests/optics/test_spectra.py).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from precompute.bakes import bake, kernel, planner
from precompute.colour import film_channels, film_colour, rgb_spaces, spectra
from precompute.colour.colour_difference import delta_e_2000
from precompute.materials.material import Layer, Material, Quality
from precompute.optics import belcour2017, reflectance

SPACE = "Linear Rec.709"


def _series_at_wavelength(stack, cos, d, wl, orders):
    r12, r23, phasor, opd, tir = belcour2017._interfaces(stack, cos, d)
    total = 0.0
    for pol in (0, 1):
        total = total + 0.5 * belcour2017.airy_series(
            r12[..., pol],
            r23[..., pol],
            phasor[..., pol],
            lambda m: np.exp(2j * np.pi * m * opd / wl),
            orders,
        )
    return np.where(tir, 1.0, total)[..., 0]


@pytest.mark.parametrize("substrate", [1.0, 1.5, 1.33, 2.4, complex(0.2, 3.0), complex(1.2, 0.5)])
@pytest.mark.parametrize("film", [1.33, 1.2, 2.5])
def test_airy_series_to_all_orders_is_the_exact_film(film, substrate):
    stack = belcour2017.FilmStack(1.0, film, np.array([substrate]))
    cos = np.linspace(0.05, 1.0, 9)
    for d, wl in ((437.0, 550.0), (1800.0, 433.0)):
        ours = _series_at_wavelength(stack, cos, np.asarray(d), wl, orders=400)
        exact = reflectance([1.0, film, substrate], [d], [wl], cos)[:, 0]
        # float64 against an independent implementation (transfer amplitudes, closed form).
        np.testing.assert_allclose(ours, exact, atol=1e-12)


def test_sensitivity_table_is_its_discrete_fourier_sum_and_close_to_the_integral():
    table = film_channels.sensitivity(SPACE).table
    lam, s = rgb_spaces.channel_sensitivities(SPACE)
    spline = belcour2017.natural_cubic_spline(lam, s)
    df = 1.0 / (2.0 * belcour2017.OPD_MAX_NM)
    f = np.arange(1, belcour2017.FREQUENCY_SAMPLES) * df  # f = 0 (λ = ∞) contributes nothing
    g = np.nan_to_num(spline(1.0 / f)) / (f * f)[:, None]
    t = np.arange(belcour2017.TABLE_SIZE) * belcour2017.OPD_MAX_NM / (belcour2017.TABLE_SIZE - 1)
    direct = np.exp(-2j * np.pi * np.outer(t, f)) @ g / g.sum(axis=0)
    np.testing.assert_allclose(table, direct, atol=1e-12)  # the FFT's bookkeeping, to rounding
    np.testing.assert_allclose(table[0], 1.0, atol=1e-15)  # white reflects 1 in every channel
    # Against the continuous integral ∫ s e^{−2πi t/λ} dλ / ∫ s dλ (fine λ quadrature): Cycles'
    # 1022 frequency samples are 8–33 nm apart in the visible, which costs ≤ 2.0e-3 per entry up
    # to 3 µm (measured; 8× finer sampling brings it to 1e-6).
    wl = np.linspace(lam[0], lam[-1], 47201)
    sv = spline(wl)
    near = t <= 3000.0
    integral = np.exp(-2j * np.pi * np.outer(t[near], 1.0 / wl)) @ sv / sv.sum(axis=0)
    assert np.max(np.abs(table[near] - integral)) < 2.5e-3


def _direct_three_orders(stack, cos, d, wl, weights):
    """The same method without its table: the three-order series integrated on a fine λ grid."""
    r12, r23, phasor, opd, tir = belcour2017._interfaces(stack, cos, d)
    total = 0.0
    for pol in (0, 1):
        series = belcour2017.airy_series(
            r12[..., pol, None],
            r23[..., pol, None],
            phasor[..., pol, None],
            lambda m: np.exp(2j * np.pi * m * opd[..., None] / wl),
            3,
        )  # (…, C, W)
        total = total + 0.5 * series[..., 0, :]
    rgb = total @ weights
    rgb = np.where(tir[..., :1], 1.0, rgb)
    return np.clip(rgb, 0.0, 1.0)


@pytest.mark.parametrize(
    ("film", "substrate", "d_range"),
    [
        (1.33, 1.0, (0.0, 1000.0)),
        (1.47, 1.33, (100.0, 800.0)),
        (2.5, 1.5, (0.0, 600.0)),
        (1.38, 1.52, (50.0, 400.0)),
    ],
)
def test_white_furnace_matches_direct_spectral_integration_of_the_same_method(film, substrate, d_range):
    material = Material(
        layers=(Layer(film, 300.0),), substrate=substrate, roughness=0.0, colour_mode="per_channel"
    )
    cos, d = np.meshgrid(np.linspace(0.03, 1.0, 40), np.linspace(*d_range, 24))
    ours = film_colour.white_reflectance(material, d, cos)
    wl = spectra.wavelength_grid(4700)  # 0.1 nm cells: the direct integral is converged
    direct = _direct_three_orders(
        film_channels.cycles_stack(material), cos, d, wl, rgb_spaces.channel_weights(wl)
    )
    de = delta_e_2000(ours.reshape(-1, 3), direct.reshape(-1, 3), xyz="E")
    # The two differ only by the table's frequency sampling (≤ 2e-3 per term) and its linear
    # interpolation in OPD (measured ≤ 4e-3 of a term's amplitude): mean ΔE2000 measured
    # 0.01–0.04 at this exposure; far below what a person sees (1) and the acceptance (0.3).
    assert float(np.mean(de)) < 0.1, float(np.mean(de))
    assert float(np.max(np.abs(ours - direct))) < 8e-3


def test_cutoffs_bare_interface_and_index_blend():
    stack = belcour2017.FilmStack(1.0, 2.0, np.full(3, 1.5 + 0j))
    sens = film_channels.sensitivity(SPACE)
    cos = np.linspace(0.05, 1.0, 20)
    bare = belcour2017.bare_reflectance(stack, cos)
    fresnel = reflectance([1.0, 1.5], [], [550.0], cos)[:, 0]
    np.testing.assert_allclose(bare, np.repeat(fresnel[:, None], 3, axis=1), atol=1e-15)
    # ≤ 0.1 nm: no film; just above, the index is 2.8 % of the way from the ambient's
    # (smoothstep(0.1)): close to bare, a step of ≤ 0.011 at grazing (as Cycles' cutoff).
    # Bit for bit: at ≤ 0.1 nm the film is dropped and the bare interface's own code runs.
    np.testing.assert_array_equal(
        belcour2017.film_reflectance(stack, cos, 0.1, sens),
        bare,
        err_msg="a 0.1 nm film must be the bare interface",
    )
    np.testing.assert_allclose(belcour2017.film_reflectance(stack, cos, 0.1 + 1e-6, sens), bare, atol=0.015)
    # The blend ends at 1 nm: continuous there.
    below = belcour2017.film_reflectance(stack, cos, 1.0 - 1e-7, sens)
    above = belcour2017.film_reflectance(stack, cos, 1.0 + 1e-7, sens)
    np.testing.assert_allclose(below, above, atol=1e-6)


def test_f82_metal_matches_base_color_and_tint_and_the_film_stays_in_range():
    f0, tint = np.array([0.9, 0.6, 0.3]), np.array([1.0, 0.8, 0.5])
    n3, f82 = film_channels.f82_tint_stack_substrate(f0, tint)
    stack = belcour2017.FilmStack(1.0, 1.5, n3, f82)
    bare = belcour2017.bare_reflectance(stack, np.array([1.0, belcour2017.F82_COS]))
    np.testing.assert_allclose(bare[0], f0, atol=1e-12)  # Gulbrandsen's fit keeps F0
    schlick = f0 + (1.0 - f0) * (1.0 - belcour2017.F82_COS) ** 5
    np.testing.assert_allclose(bare[1], schlick * tint, atol=1e-12)  # the F82 tint
    sens = film_channels.sensitivity(SPACE)
    d = np.linspace(0.0, 1500.0, 61)[:, None]
    film = belcour2017.film_reflectance(stack, np.linspace(0.0, 1.0, 33)[None, :], d, sens)
    assert film.shape == (61, 33, 3) and np.all((film >= 0.0) & (film <= 1.0))


def test_cycles_stack_only_for_what_cycles_expresses():
    assert film_channels.cycles_stack(Material(layers=(Layer(1.33, 400.0),), colour_mode="per_channel"))
    metal = {"f82_tint": {"f0": [0.9, 0.6, 0.3], "tint": [1.0, 1.0, 1.0]}}
    assert film_channels.cycles_stack(Material(layers=(Layer(1.5, 100.0),), substrate=metal)).f82 is not None
    for other in (
        Material(layers=(Layer(1.33, 100.0), Layer(1.5, 100.0))),  # a stack
        Material(layers=(Layer({"cauchy": [1.5, 0.004]}, 100.0),)),  # dispersion
        Material(layers=(Layer([2.6, 0.3], 60.0),)),  # an absorbing film
        Material(substrate={"metal": "gold"}),  # a measured metal
        Material(illuminant="D65"),  # a coloured light
        Material(model="glassner2000"),
    ):
        assert film_channels.cycles_stack(other) is None


def test_generic_per_channel_path_is_exact_optics_with_cycles_sensitivities():
    """A stack Cycles cannot express: the exact reflectance against the channel weights, clamped."""
    material = Material(
        layers=(Layer(1.33, 150.0), Layer(1.6, 90.0)), substrate=1.5, roughness=0.0, colour_mode="per_channel"
    )
    cos = np.linspace(0.1, 1.0, 7)
    ours = film_colour.white_reflectance(material, 150.0, cos)
    wl = spectra.wavelength_grid(planner.plan(material).wavelength_count)
    r = reflectance(material.indices(), [150.0, 90.0], wl, cos)
    np.testing.assert_allclose(ours, np.clip(r @ rgb_spaces.channel_weights(wl, SPACE), 0, 1), atol=1e-12)


def test_per_channel_white_is_one_in_every_channel_without_adaptation():
    wl = spectra.wavelength_grid(97)
    np.testing.assert_allclose(rgb_spaces.channel_weights(wl).sum(axis=0), 1.0, atol=1e-14)
    # No chromatic adaptation: the rows are Rec.709's own XYZ → RGB matrix (D65-relative XYZ).
    m = rgb_spaces.scene_linear_matrix(SPACE)
    np.testing.assert_allclose(m @ [0.95047, 1.0, 1.08883], 1.0, atol=5e-4)  # D65, to its 4 digits
    assert not np.allclose(m, rgb_spaces.xyz_to_rgb_matrix(SPACE), atol=1e-3)


def test_diffuse_base_is_layered_as_in_cycles_principled():
    """Per-channel mode: Base Color × (1 − max_c F_c(θo) · darkening) under a uniform World."""
    q = Quality(sh_order=2, view_samples=6)
    film = Material(
        layers=(Layer(1.33, 400.0),),
        substrate=1.5,
        roughness=0.3,
        colour_mode="per_channel",
        multiscatter="cycles",
        quality=q,
    )
    grey = (0.5, 0.5, 0.5)
    with_base = bake.bake(film.with_(base_color=grey))
    without = bake.bake(film)
    diffuse = (with_base.data - without.data)[0, :, 0, :] * math.sqrt(4.0 * math.pi)  # white World, L = 1
    cos_o = kernel.view_cosines(q.view_samples)
    film_o = film_channels.fourier_reflectance(film, film_channels.cycles_stack(film), 400.0, cos_o)
    weight = bake.layering_weight(film, film_o[None], cos_o)[0]
    np.testing.assert_allclose(diffuse, np.outer(weight, grey), rtol=1e-6, atol=1e-9)
    assert np.all(weight < 1.0) and np.all(weight[:-1] > 0.5)  # the film takes a little (all at 90°)
    np.testing.assert_allclose(diffuse[:, 0], diffuse[:, 2], rtol=1e-12)
