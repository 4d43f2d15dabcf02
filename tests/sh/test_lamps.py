"""The World's lamps (precompute/world/lamps.py): extraction keeps every watt, shading matches the BRDF.

Pure numpy; the shader's copy is checked per pixel in tests/drawing/test_gpu_draw.py.
"""

from __future__ import annotations

import numpy as np
import pytest
import tmm

from precompute import brdf
from precompute.bakes import bake
from precompute.colour import film_channels, film_colour
from precompute.materials.material import Layer, Material, Quality
from precompute.shading import lamps as lamp_shading
from precompute.shading import policy, split_sum
from precompute.world import hdri, lamps, prefilter

H, W = 64, 128


def sky(h=H, w=W):
    """A smooth sky gradient (no pixel above the lamp threshold)."""
    el = np.pi * (0.5 - (np.arange(h) + 0.5) / h)
    return np.repeat((0.5 + 0.3 * np.sin(el))[:, None, None] * np.array([0.6, 0.8, 1.0]), w, axis=1)


def with_suns(img, spots):
    """``spots``: ((row, col), radiance RGB) single pixels."""
    out = img.copy()
    for (r, c), rgb in spots:
        out[r, c] = rgb
    return out


def power(img):
    return np.einsum("hwc,hw->c", img, hdri.equirect_solid_angles(*img.shape[:2]))


def test_solid_angles_sum_to_the_sphere():
    assert np.isclose(hdri.equirect_solid_angles(H, W).sum(), 4 * np.pi, rtol=1e-12)


def test_no_lamps_in_a_smooth_sky_a_black_world_or_with_max_lamps_zero():
    for img in (sky(), np.zeros((H, W, 3))):
        found, mask = lamps.extract(img)
        assert found.count == 0 and not mask.any()
    found, mask = lamps.extract(with_suns(sky(), [((10, 20), (1e5, 1e5, 1e5))]), max_lamps=0)
    assert found.count == 0 and not mask.any()


def test_extraction_keeps_every_watt_and_finds_each_sun():
    spots = [
        ((10, 20), (2e4, 1.8e4, 1.5e4)),
        ((40, 90), (300.0, 600.0, 900.0)),
        ((41, 90), (300.0, 600.0, 900.0)),
    ]
    img = with_suns(sky(), spots)
    assert lamps.extract(img)[0].count == 3  # fewer lamp pixels than MAX_LAMPS: one lamp each
    found, mask = lamps.extract(img, max_lamps=2)
    rest = lamps.remove(img, mask)
    assert mask.sum() == 3 and found.count == 2  # the two neighbouring pixels are one lamp
    # rest + lamps = the World, channel by channel (float64 sums)
    assert np.allclose(power(rest) + found.power.sum(axis=0), power(img), rtol=1e-12)
    dirs = hdri.equirect_directions(H, W)
    omega = hdri.equirect_solid_angles(H, W)
    first = int(np.argmax(found.power[:, 1]))
    assert np.allclose(found.directions[first], dirs[10, 20], atol=1e-12)
    assert np.allclose(found.power[first], np.array(spots[0][1]) * omega[10, 20], rtol=1e-12)
    second = 1 - first
    mean_dir = dirs[40, 90] * omega[40, 90] + dirs[41, 90] * omega[41, 90]
    assert np.allclose(found.directions[second], mean_dir / np.linalg.norm(mean_dir), atol=1e-12)
    y = np.asarray(prefilter.LUMINANCE)
    assert np.isclose(found.share, found.power.sum(axis=0) @ y / (power(img) @ y), rtol=1e-12)


def test_at_most_max_lamps_and_deterministic():
    rng = np.random.default_rng(1)
    spots = [
        ((int(r), int(c)), (5e3, 5e3, 5e3))
        for r, c in zip(rng.integers(2, H - 2, 30), rng.integers(0, W, 30), strict=True)
    ]
    img = with_suns(sky(), spots)
    a, mask = lamps.extract(img)
    b, _ = lamps.extract(img)
    assert a.count == policy.MAX_LAMPS
    assert np.array_equal(a.directions, b.directions) and np.array_equal(a.power, b.power)
    assert np.allclose(a.power.sum(axis=0), power(np.where(mask[..., None], img, 0.0)), rtol=1e-12)
    assert np.allclose(np.linalg.norm(a.directions, axis=1), 1.0)


def test_nan_and_inf_pixels_are_never_lamps():
    img = with_suns(
        sky(), [((5, 5), (np.nan, 1.0, 1.0)), ((6, 6), (np.inf, np.inf, np.inf)), ((30, 30), (1e5, 1e5, 1e5))]
    )
    found, mask = lamps.extract(img)
    assert found.count == 1 and mask.sum() == 1 and mask[30, 30]
    assert np.all(np.isfinite(found.power)) and np.all(np.isfinite(found.directions))


def test_bad_arguments_are_named():
    """Lamp extraction refuses a bad threshold, lamp count or image shape with the argument named."""
    with pytest.raises(ValueError, match="threshold"):
        lamps.extract(sky(), threshold=0.0)
    with pytest.raises(ValueError, match="max_lamps"):
        lamps.extract(sky(), max_lamps=-1)
    with pytest.raises(ValueError, match="shape"):
        lamps.extract(np.zeros((4,)))


def film_material(colour_mode="spectral", roughness=0.3, multiscatter="none", thickness=380.0):
    return Material(
        layers=(Layer(1.33, thickness),),
        substrate=1.5,
        roughness=roughness,
        colour_mode=colour_mode,
        multiscatter=multiscatter,
        quality=Quality(sh_order=2, view_samples=8, thickness_samples="auto"),
    )


@pytest.mark.parametrize("colour_mode", ["spectral", "per_channel"])
def test_one_lamp_is_the_microfacet_brdf_times_its_power(colour_mode):
    """lamp_shading.shade against brdf.film_brdf (D G₂ F / 4 cos cos) × cos θi × power, per direction."""
    result = bake.bake(film_material(colour_mode))
    film = film_colour.film_table(result)
    rng = np.random.default_rng(4)
    n = np.tile([0.0, 0.0, 1.0], (200, 1))
    v = rng.normal(size=(200, 3))
    v[:, 2] = np.abs(v[:, 2]) + 0.05
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    d = np.array([0.3, -0.2, 0.9])
    d /= np.linalg.norm(d)
    p = np.array([2.0, 1.0, 0.5])
    got = lamp_shading.shade(film, lamps.Lamps(d[None], p[None]), 0.3, n, v)
    u_grid = np.linspace(0, 1, film.reflectance.shape[1])

    def film_r(u):  # the table's own reflectance, interpolated in u (per output row)
        r = film.reflectance[0]
        flat = r.reshape(r.shape[0], -1)
        return np.stack([np.interp(u, u_grid, flat[:, k]) for k in range(flat.shape[1])], -1)

    f = brdf.film_brdf(np.broadcast_to(d, v.shape), v, 0.3, film_r)  # (N, 9) or (N, 3)
    f = f.reshape(-1, 3, 3) @ p if colour_mode == "spectral" else f * p
    expected = f * d[2]
    assert np.allclose(got, expected, rtol=1e-10, atol=1e-14)


def test_film_table_matches_tmm_at_every_angle():
    """The per-channel film table is the channel-weighted tmm reflectance (independent code).

    On a two-layer stack, which Cycles' single-film model cannot express: the per-channel mode
    integrates the exact film against Cycles' channel sensitivities there. A single film goes
    through Cycles' own three-order Fourier-space film instead (issue 22), checked below
    against that function and, to every order, against exact optics in
    tests/optics/test_film_channels.py.
    """
    material = Material(
        layers=(Layer(1.33, 380.0), Layer(1.6, 120.0)),
        substrate=1.5,
        roughness=0.3,
        colour_mode="per_channel",
        quality=Quality(sh_order=2, view_samples=8),
    )
    result = bake.bake(material)
    film = film_colour.film_table(result, samples=9)
    from precompute.colour.film_colour import film_rgb_matrices

    u, rg, r, wl, g = film_rgb_matrices(material, None, 9)
    nk = [1.0, 1.33, 1.6, 1.5]
    for i, cos in enumerate(u):
        theta = float(np.arccos(np.clip(cos, 0.0, 1.0)))
        if theta > np.radians(89.9):
            continue
        ref = [
            0.5
            * (
                tmm.coh_tmm("s", nk, [np.inf, 380.0, 120.0, np.inf], theta, lam)["R"]
                + tmm.coh_tmm("p", nk, [np.inf, 380.0, 120.0, np.inf], theta, lam)["R"]
            )
            for lam in wl
        ]
        expected = bake.clamp_film_rgb(np.einsum("w,wkc->kc", np.array(ref), g), material.colour_mode)
        assert np.allclose(film.reflectance[0, i], np.diag(expected), atol=2e-6), (
            cos,
            film.reflectance[0, i],
        )
    single = film_material("per_channel")
    film = film_colour.film_table(bake.bake(single), samples=9)
    cycles = film_channels.fourier_reflectance(single, film_channels.cycles_stack(single), 380.0, u)
    np.testing.assert_allclose(film.reflectance[0], cycles, atol=1e-12)


def test_multiscatter_factor_matches_the_bake():
    """Lamps get the factor the table got: cycles mode up to the linear interpolation over 128
    samples in u (1e-5), film mode up to its own quadrature of F_avg (5e-3)."""
    for mode, tol in (("cycles", 1e-5), ("film", 5e-3)):
        material = film_material("per_channel", roughness=0.6, multiscatter=mode)
        result = bake.bake(material)
        film = film_colour.film_table(result)
        plain = bake.bake(film_material("per_channel", roughness=0.6, multiscatter="none"))
        # the bake's factor at its own view angles: scaled table ÷ unscaled table (l = 0 entry)
        cos_o = np.cos(result.view_angles_rad)
        ratio = result.data[0, :, 0] / plain.data[0, :, 0]
        ours = np.stack(
            [
                np.interp(cos_o, np.linspace(0, 1, film.multiscatter.shape[1]), film.multiscatter[0, :, c])
                for c in range(3)
            ],
            -1,
        )
        keep = cos_o > 0.05
        assert np.allclose(ours[keep], ratio[keep], rtol=tol), (
            mode,
            np.max(np.abs(ours[keep] / ratio[keep] - 1)),
        )


def test_split_sum_levels_keep_the_lamps_only_at_the_mirror_level():
    img = with_suns(sky(), [((20, 40), (1e5, 1e5, 1e5))])
    found, mask = lamps.extract(img)
    pre = prefilter.prefilter(img, width=W, lamp_mask=mask)
    whole = prefilter.prefilter(img, width=W)
    rest = prefilter.prefilter(lamps.remove(img, mask), width=W)
    assert np.array_equal(pre.lamp_weights, (np.arange(len(pre.levels)) >= policy.LAMP_LEVEL).astype(float))
    for j, level in enumerate(pre.levels):
        ref = whole.levels[j] if j < policy.LAMP_LEVEL else rest.levels[j]
        assert np.allclose(level, ref, rtol=1e-9, atol=1e-9 * np.max(ref)), j
    # the analytic weight follows the level blend: 0 at roughness 0, 1 from level LAMP_LEVEL on
    assert split_sum.lamp_weight_at(pre, 0.0) == 0.0
    assert split_sum.lamp_weight_at(pre, pre.roughness[policy.LAMP_LEVEL]) == 1.0
    assert split_sum.lamp_weight_at(pre, 0.6) == 1.0
