"""The EEVEE film image's maths (precompute/bakes/eevee_table.py): EEVEE's split sum and the bands.

EEVEE's Glossy BSDF multiplies its colour by its split-sum LUT E(μ, r) (single-scattering GGX,
separable Smith, eevee_bxdf_lut); the image divides the film's albedo by it. E is checked against
an independent brute-force Monte Carlo integral of the same BRDF over light directions (not the
half-vector quadrature the module uses), and against its closed forms: E = 1 at roughness 0 and
the white-furnace bound E ≤ 1.
"""

import math

import numpy as np
import pytest

from precompute.bakes import bake, eevee_table
from precompute.colour import film_colour
from precompute.materials.material import Layer, Material
from precompute.shading import transmit


def _monte_carlo_e(mu: float, roughness: float, n: int = 400_000, seed: int = 7) -> tuple[float, float]:
    """E by uniform hemisphere sampling of the light: (mean, standard error)."""
    rng = np.random.default_rng(seed)
    a2 = roughness**4
    z = rng.random(n)
    phi = 2 * np.pi * rng.random(n)
    r = np.sqrt(1 - z * z)
    light = np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)
    view = np.array([math.sqrt(1 - mu * mu), 0.0, mu])
    h = light + view
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    nh = h[:, 2]
    d = a2 / (np.pi * ((1 - nh * nh) + a2 * nh * nh) ** 2)

    def g1(c):
        return 2 / (1 + np.sqrt(1 + a2 * (1 / (c * c) - 1)))

    f = d * g1(mu) * g1(z) / (4 * mu)  # BRDF × cos θl = D G / (4 μ)
    values = f * 2 * np.pi  # pdf 1/(2π)
    return float(values.mean()), float(values.std() / math.sqrt(n))


@pytest.mark.parametrize("mu, roughness", [(0.9, 0.5), (0.5, 0.7), (0.3, 0.9), (0.7, 1.0)])
def test_split_sum_matches_monte_carlo(mu, roughness):
    """E(μ, r) against an independent Monte Carlo estimate, within 4 standard errors (rough
    lobes: uniform sampling converges there)."""
    mean, error = _monte_carlo_e(mu, roughness)
    found = float(eevee_table.eevee_split_sum(mu, roughness))
    assert abs(found - mean) < 4 * error + 2e-4, (
        f"E({mu}, {roughness}) = {found:.5f}, Monte Carlo {mean:.5f} ± {error:.5f}: EEVEE's split sum "
        "is what the film image divides by"
    )


def test_split_sum_limits():
    """Roughness 0 reflects everything (E = 1), and no roughness reflects more than the light."""
    mu = np.linspace(0.05, 1.0, 20)
    assert np.allclose(eevee_table.eevee_split_sum(mu, 0.0), 1.0, atol=1e-4)
    for roughness in (0.1, 0.4, 0.8, 1.0):
        e = eevee_table.eevee_split_sum(mu, roughness)
        assert np.all(e <= 1.0 + 1e-6) and np.all(e > 0.3), (roughness, e)


def test_lut_scale_reads_the_grid_like_eevee():
    """The bilinear LUT reading equals the exact integral at the grid's nodes and stays within
    the grid's interpolation error (< 3e-3) between them."""
    r = 7 / 63  # a roughness node
    y = np.array([5, 17, 40]) / 63
    mu = 1 - y * y
    assert np.allclose(eevee_table.eevee_lut_scale(mu, r), eevee_table.eevee_split_sum(mu, r), atol=1e-9)
    mu = np.linspace(0.1, 1.0, 17)
    for roughness in (0.13, 0.42, 0.77):
        gap = eevee_table.eevee_lut_scale(mu, roughness) - eevee_table.eevee_split_sum(mu, roughness)
        assert np.max(np.abs(gap)) < 3e-3, (roughness, gap)


def test_glossy_colour_times_split_sum_is_the_albedo():
    rng = np.random.default_rng(3)
    albedo = rng.random((5, 3)) * 0.3
    mu = np.array([1.0, 0.8, 0.5, 0.2, 0.05])
    colour = eevee_table.glossy_colour(albedo, mu, 0.35)
    back = colour * eevee_table.eevee_lut_scale(mu, 0.35)[:, None]
    assert np.allclose(back, albedo, rtol=1e-12)


def _film(**kw):
    base = dict(layers=(Layer(1.33, 500.0),), substrate=1.5, roughness=0.3, colour_mode="per_channel")
    base.update(kw)
    return Material(**base)


def test_table_albedo_is_the_split_sums_entry():
    """The specular band before the division is the l = 0 entry × √(4π) the overlay's split sum
    reads (shading/split_sum.shade_split_sum): the same numbers, per view angle."""
    result = bake.bake(_film(quality={"sh_order": 0}))
    albedo = eevee_table.table_albedo(result.data)
    assert albedo.shape == result.data.shape[:2] + (3,)
    assert np.allclose(albedo, result.data[:, :, 0] * math.sqrt(4 * math.pi))
    spectral = bake.bake(_film(colour_mode="spectral", quality={"sh_order": 0}))
    summed = eevee_table.table_albedo(spectral.data)
    assert np.allclose(summed, spectral.data[:, :, 0].sum(-1) * math.sqrt(4 * math.pi))


def test_image_layout_and_bands():
    """Bands stack in BANDS order, each T rows; pixel (row, column) = the band at (thickness row,
    view angle); the specular band is the albedo, the inverse band 1/E (so their product is
    what EEVEE's Glossy needs); RGBA float32 with alpha 1."""
    desc = _film(thickness_range_nm=(200.0, 600.0), quality={"sh_order": 0, "thickness_samples": 9})
    result = bake.bake(desc)
    made = eevee_table.film_image(result)
    t, a = result.data.shape[:2]
    assert made.pixels.shape == (2 * t, a, 4) and made.pixels.dtype == np.float32
    assert made.rows == t and made.thickness_nm == (200.0, 600.0)
    assert made.bands == {"specular": 0, "inverse": 1}
    assert np.all(made.pixels[..., 3] == 1.0)
    cos_o = np.cos(result.view_angles_rad)
    assert np.allclose(made.pixels[:t, :, :3], eevee_table.table_albedo(result.data), rtol=2e-6, atol=1e-7)
    e = eevee_table.eevee_lut_scale(cos_o, 0.3)
    assert np.allclose(made.pixels[t:, :, :3] * e[None, :, None], 1.0, rtol=2e-6)


def test_wall_bands_follow_the_overlays_wall():
    """A transparent film's bands: transmission = the wall's T, specular = albedo × S / E, with
    T and S from shading/transmit.wall at the film's white reflectance (a soap film in air)."""
    desc = Material(layers=(Layer(1.33, 400.0),), substrate=1.0, roughness=0.1, quality={"sh_order": 0})
    result = bake.bake(desc)
    film = film_colour.film_table(result)
    made = eevee_table.film_image(result, film=film, wall=(transmit.WALL_CYCLES, 1.0))
    assert made.bands == {"specular": 0, "inverse": 1, "transmission": 2}
    cos_o = np.cos(result.view_angles_rad)
    r = eevee_table.white_reflectance_at(film, cos_o)
    t, s = transmit.wall(r, cos_o[None, :], transmit.WALL_CYCLES)
    assert np.allclose(made.pixels[2:3, :, :3], t, atol=1e-6)
    spec = eevee_table.table_albedo(result.data) * s
    assert np.allclose(made.pixels[0:1, :, :3], spec, rtol=1e-5, atol=1e-7)
    through = made.pixels[2, cos_o > 0.5, :3]  # a soap film lets most light through, short of grazing
    assert np.all(through < 1.0) and np.all(through > 0.5), through
    # a Principled Base Color tint (Cycles' thin wall absorbs it per pass), and solid glass's
    # tint in and out on its transmission band
    tint = np.array([0.8, 0.5, 0.2])
    tinted = eevee_table.film_image(result, film=film, wall=(transmit.WALL_CYCLES, 1.0, *tint))
    t_tint, s_tint = transmit.wall(r, cos_o[None, :], transmit.WALL_CYCLES, 1.0, tint)
    assert np.allclose(tinted.pixels[2:3, :, :3], t_tint, atol=1e-6)
    assert np.allclose(
        tinted.pixels[0:1, :, :3], eevee_table.table_albedo(result.data) * s_tint, rtol=1e-5, atol=1e-7
    )
    front = cos_o > 0.5
    assert np.all(tinted.pixels[2, front, 2] < tinted.pixels[2, front, 0])  # blue absorbed most
    solid = eevee_table.film_image(result, film=film, wall=(transmit.WALL_SOLID, 1.5, *tint))
    t_solid, _ = transmit.wall(r, cos_o[None, :], transmit.WALL_SOLID, 1.5)
    assert np.allclose(solid.pixels[2:3, :, :3], t_solid * tint, atol=1e-6)


def test_a_walls_shadow_curve_is_fitted_to_its_transmittance():
    """shadow_fit recovers a curve made by shadow_model (r0 per channel, e on its grid); on a real
    wall (a soap film of 200–900 nm in air, Cycles' thin wall) the curve it gives stays within
    0.04 of the wall's thickness-averaged T at every view angle, which falls from ≈ 0.9 at normal
    incidence to 0 at grazing; the image carries the fit, solid glass and opaque films none."""
    cos_o = np.cos(np.linspace(0.0, 0.5 * math.pi, 48))
    r0 = np.array([0.02, 0.05, 0.11])
    made_up = eevee_table.shadow_model(r0, 3.5, cos_o[:, None])
    found, exponent = eevee_table.shadow_fit(np.stack([made_up, made_up]), cos_o)
    assert exponent == pytest.approx(3.5) and np.allclose(found, r0, atol=1e-9), (found, exponent)
    desc = Material(
        layers=(Layer(1.33, 500.0),),
        substrate=1.0,
        roughness=0.0,
        thickness_range_nm=(200.0, 900.0),
        quality={"sh_order": 0, "thickness_samples": 15},
    )
    result = bake.bake(desc)
    film = film_colour.film_table(result)
    made = eevee_table.film_image(result, film=film, wall=(transmit.WALL_CYCLES, 1.0))
    cos_o = np.cos(result.view_angles_rad)
    through = made.pixels[2 * made.rows :, :, :3].mean(axis=0)
    curve = eevee_table.shadow_model(np.array(made.shadow[:3]), made.shadow[3], cos_o[:, None])
    assert np.max(np.abs(curve - through)) < 0.04, np.max(np.abs(curve - through))
    assert np.all(through[0] > 0.85) and np.all(through[-1] < 0.05) and np.all(curve[-1] < 0.05)
    assert eevee_table.film_image(result).shadow is None
    assert eevee_table.film_image(result, film=film, wall=(transmit.WALL_SOLID, 1.5)).shadow is None


def test_diffuse_band_is_the_weight_under_the_film():
    """With a diffuse base the band is (total − film) / base per channel: in the per-channel
    mode that is Cycles' layering weight, the same for every channel, in [0, 1]."""
    base = (0.6, 0.3, 0.1)
    film = bake.bake(_film(quality={"sh_order": 0}))
    full = bake.bake(_film(base_color=base, quality={"sh_order": 0}))
    made = eevee_table.film_image(film, base_result=full, base_color=base)
    assert made.bands == {"specular": 0, "inverse": 1, "diffuse": 2}
    weight = made.pixels[2, :, :3]
    assert np.all(weight >= 0.0) and np.all(weight <= 1.0 + 1e-6)
    assert np.allclose(weight[:, 0], weight[:, 1], atol=1e-6) and np.allclose(
        weight[:, 1], weight[:, 2], atol=1e-6
    )
    assert weight[0, 0] > 0.8  # a weak film over a dielectric: most light reaches the base


def test_dominant_directions_point_at_a_lamp():
    """A black World with one small bright lamp: in every reflection direction whose GGX lobe
    reaches the lamp, the lobe light's mean direction c is the lamp's; the image is in Blender's
    pixel order (bottom row first, its Environment Texture mapping) and, without light objects,
    stores c at length 0.5 (their share 0). A World without moments gives the reflection
    direction itself."""
    from precompute.world import hdri, prefilter

    height, width = 64, 128
    image = np.full((height, width, 3), 1e-4)
    lamp = np.array([0.6, -0.3, 0.74])
    lamp /= np.linalg.norm(lamp)
    directions = hdri.equirect_directions(height, width)
    image[(directions @ lamp) > np.cos(np.radians(3.0))] = 500.0
    pre = prefilter.prefilter(image)
    pixels = eevee_table.dominant_directions(pre, 0.3, size=(64, 32))
    assert pixels.shape == (32, 64, 4)
    raw = 2.0 * pixels[::-1, :, :3] - 1.0  # top row first again, as hdri.equirect_directions
    c, share = eevee_table.decode_directions(pixels[::-1])
    grid = hdri.equirect_directions(32, 64)
    near = (grid @ lamp) > np.cos(np.radians(20.0))
    assert near.sum() > 4
    assert np.all(c[near] @ lamp > 0.99), "near the lamp the mean light direction is the lamp's"
    assert np.allclose(np.linalg.norm(raw, axis=-1), eevee_table.SHARE_FLOOR, atol=1e-5)
    assert share.max() < 1e-5
    plain = eevee_table.dominant_directions(None, 0.3, size=(64, 32))
    assert np.allclose(eevee_table.decode_directions(plain[::-1])[0], grid, atol=1e-6)


def test_dominant_weight_ramps_with_roughness():
    """Glossy films are read at the view angle, rough ones at the lobe light's angle, linearly
    between (the measured ramp, eevee_table.DOMINANT_RAMP)."""
    lo, hi = eevee_table.DOMINANT_RAMP
    assert eevee_table.dominant_weight(0.0) == 0.0 and eevee_table.dominant_weight(lo) == 0.0
    assert eevee_table.dominant_weight(hi) == 1.0 and eevee_table.dominant_weight(1.0) == 1.0
    assert eevee_table.dominant_weight(0.5 * (lo + hi)) == pytest.approx(0.5)


def _sun_scene(sun, world_radiance=1e-3, irradiance=4.0, roughness=0.3, height=64, width=128):
    """A uniform dim World's prefilter and one sun of ``irradiance`` (W/m², luminance) at ``sun``."""
    from precompute.world import prefilter

    pre = prefilter.prefilter(np.full((height, width, 3), world_radiance))
    lights = eevee_table.LobeLights(np.array([sun]), np.array([irradiance]), np.array([1e-5]))
    return pre, lights


def test_a_sun_dominating_a_dim_world_is_the_lobe_light_everywhere_it_reaches():
    """A sun of 4 W/m² over a uniform World of 0.001 W/(m² sr), roughness 0.3: wherever the
    film's reflection direction is within 45° of the sun (its GGX lobe still holds ≥ 80× the
    World's light there: D at θh = 22.5°), the stored direction is the sun's within 1° and the
    lights' share of the lobe is over 0.98; opposite the sun the World alone lights the lobe
    (share < 0.01) and c is the reflection direction (a uniform World's mean light direction,
    within 1°)."""
    from precompute.world import hdri

    sun = np.array([0.4, -0.5, 0.77])
    sun /= np.linalg.norm(sun)
    pre, lights = _sun_scene(sun)
    pixels = eevee_table.dominant_directions(pre, 0.3, size=(64, 32), lights=lights)
    c, share = eevee_table.decode_directions(pixels[::-1])  # top row first, as equirect_directions
    grid = hdri.equirect_directions(32, 64)
    near = grid @ sun > np.cos(np.radians(45.0))
    far = grid @ sun < np.cos(np.radians(150.0))
    assert near.sum() > 30 and far.sum() > 20
    worst = np.degrees(np.arccos(np.clip(c[near] @ sun, -1.0, 1.0))).max()
    assert worst < 1.0, f"within 45° of the sun the lobe light must be the sun: worst {worst:.3f}°"
    assert share[near].min() > 0.98, f"the sun's share there: min {share[near].min():.4f}"
    assert share[far].max() < 0.01, f"opposite the sun the World lights the lobe: {share[far].max():.4f}"
    off = np.degrees(np.arccos(np.clip(np.sum(c[far] * grid[far], axis=-1), -1.0, 1.0))).max()
    assert off < 1.0, f"a uniform World's lobe light is the reflection direction: worst {off:.3f}°"


def test_a_zero_power_light_changes_nothing():
    """A light that brings no light (0 W, or no light at all) leaves the image as the World alone
    makes it: every pixel within 1e-7 (the same arithmetic: exact up to float32 storage), share 0."""
    sun = np.array([0.0, 0.6, 0.8])
    pre, _lights = _sun_scene(sun)
    alone = eevee_table.dominant_directions(pre, 0.3, size=(64, 32))
    dark = eevee_table.LobeLights(np.array([sun]), np.array([0.0]), np.array([1e-5]))
    with_dark = eevee_table.dominant_directions(pre, 0.3, size=(64, 32), lights=dark)
    assert np.allclose(with_dark, alone, rtol=0.0, atol=1e-7)
    empty = eevee_table.dominant_directions(pre, 0.3, size=(64, 32), lights=eevee_table.LobeLights.empty())
    assert np.allclose(empty, alone, rtol=0.0, atol=1e-7)
    assert eevee_table.decode_directions(alone)[1].max() < 1e-6, "no lights: share 0 everywhere"


@pytest.mark.parametrize("roughness", [0.3, 0.5])
def test_a_light_weighs_as_the_same_light_painted_into_the_world(roughness):
    """The lights' weight against the World: a light of irradiance E must add to the lobe's
    luminance what a 3° patch of the panorama with the same irradiance adds to the World's
    prefilter (an independent computation: precompute.world.prefilter's filtered importance
    sampling of an image, and its level blend). Compared in the reflection direction of the
    patch, where the lobe holds it: within 10%. (Further out, 10–30°, the prefilter's tails of a
    small patch come out 1.2–3.5× lower than the lobe's integral: its coarse mip reads; the
    lights' lobe is the exact one.)"""
    from precompute.shading.split_sum import lookup
    from precompute.world import hdri, prefilter

    height, width = 256, 512
    sun = np.array([0.5, -0.6, 0.62])
    sun /= np.linalg.norm(sun)
    directions = hdri.equirect_directions(height, width)
    patch = directions @ sun > np.cos(np.radians(3.0))
    theta = (np.arange(height) + 0.5) / height * np.pi
    solid = (np.pi / height) * (2.0 * np.pi / width) * np.sin(theta)[:, None] * np.ones((1, width))
    image = np.zeros((height, width, 3))
    image[patch] = 200.0
    irradiance = 200.0 * solid[patch].sum()  # the patch's radiance × its solid angle (W/m²)
    pre = prefilter.prefilter(image)
    painted = float(lookup(pre, sun[None], roughness)[0] @ np.asarray(prefilter.LUMINANCE))
    footprint = np.sin(np.radians(3.0)) ** 2 / 4.0  # the patch's size, as lights.footprint
    lights = eevee_table.LobeLights(sun[None], np.array([irradiance]), np.array([footprint]))
    _moment, ours = eevee_table.light_moments(sun[None], roughness, lights, level_roughness=pre.roughness)
    assert ours[0] == pytest.approx(painted, rel=0.10), (
        f"light {ours[0]:.3f} vs the same light in the World's prefilter {painted:.3f} (E {irradiance:.3f})"
    )
