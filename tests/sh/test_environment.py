"""The World analysis (precompute/world/environment.py): lamps, prefilter and SH, and every watt kept.

Pure numpy, no bpy: ``analyse_world`` is the one call the add-on's draw makes on a World
panorama (addon/scene_draw.world_lighting).
"""

from __future__ import annotations

import numpy as np

from precompute.sh import projection
from precompute.world import environment, hdri, lamps, prefilter

H, W = 32, 64
L_MAX = 4


def sky(h=H, w=W):
    """A smooth sky gradient (no pixel above the lamp threshold)."""
    el = np.pi * (0.5 - (np.arange(h) + 0.5) / h)
    return np.repeat((0.5 + 0.3 * np.sin(el))[:, None, None] * np.array([0.6, 0.8, 1.0]), w, axis=1)


def with_suns(img):
    """Two small, very bright lamps (three pixels) on the sky."""
    out = img.copy()
    out[6, 10] = (2e4, 1.8e4, 1.5e4)
    out[20, 45] = out[21, 45] = (300.0, 600.0, 900.0)
    return out


def power(img):
    """∫ L dω per channel (exact pixel solid angles)."""
    return np.einsum("hwc,hw->c", img, hdri.equirect_solid_angles(*img.shape[:2]))


def analyse(img):
    return environment.analyse_world(img, projection.project_equirect(img, L_MAX), l_max=L_MAX, width=W)


def test_rest_plus_lamps_keeps_every_watt_in_power_and_in_sh():
    img = with_suns(sky())
    env = analyse(img)
    assert env.lamps is not None and env.lamps.count >= 1 and env.lamp_mask.sum() == 3
    rest = lamps.remove(img, env.lamp_mask)
    # float64 sums of the same pixels: agreement to rounding
    np.testing.assert_allclose(power(rest) + env.lamps.power.sum(axis=0), power(img), rtol=1e-12)
    # Y₀₀ = 1/√(4π): the l = 0 coefficient of the lamps' SH is their power / √(4π)
    np.testing.assert_allclose(np.sqrt(4.0 * np.pi) * env.lamp_sh[0], env.lamps.power.sum(axis=0), rtol=1e-12)
    # the SH without the lamps is the SH of the rest (projection is linear)
    np.testing.assert_allclose(
        env.sh_without_lamps,
        projection.project_equirect(rest, L_MAX),
        rtol=1e-9,
        atol=1e-12 * power(img).max(),
    )
    np.testing.assert_allclose(env.sh_without_lamps + env.lamp_sh, env.world_sh, rtol=1e-12)


def test_lamp_sh_is_the_sh_of_the_masked_image():
    img = with_suns(sky())
    env = analyse(img)
    masked = np.where(env.lamp_mask[..., None], img, 0.0)
    np.testing.assert_allclose(
        env.lamp_sh,
        projection.project_equirect(masked, L_MAX),
        rtol=1e-12,
        atol=1e-12 * power(img).max(),
        err_msg="the lamps' SH must be the projection of exactly the masked pixels",
    )
    assert env.lamp_sh.shape == ((L_MAX + 1) ** 2, 3) and env.l_max == L_MAX


def test_a_world_without_lamps_has_no_lamp_sh_and_one_prefilter():
    img = sky()
    env = analyse(img)
    assert env.lamps is None and env.lamp_sh is None and not env.lamp_mask.any()
    assert env.prefiltered.lamp_weights is None  # no level lifts anything
    assert env.prefiltered_whole is env.prefiltered  # nothing filtered twice
    np.testing.assert_array_equal(env.sh_without_lamps, env.world_sh, err_msg="no lamps: nothing lifted out")


def test_prefilters_equal_the_prefilter_with_and_without_the_mask():
    img = with_suns(sky())
    env = analyse(img)
    lifted = prefilter.prefilter(img, width=W, lamp_mask=env.lamp_mask)
    whole = prefilter.prefilter(img, width=W)
    np.testing.assert_array_equal(env.prefiltered.lamp_weights, lifted.lamp_weights)
    for k, (ours, ref) in enumerate(zip(env.prefiltered.levels, lifted.levels, strict=True)):
        np.testing.assert_allclose(
            ours, ref, rtol=1e-12, atol=0, err_msg=f"level {k} with the lamps lifted out"
        )
    assert env.prefiltered_whole is env.prefiltered_whole  # computed once, then kept
    assert env.prefiltered_whole.lamp_weights is None
    for k, (ours, ref) in enumerate(zip(env.prefiltered_whole.levels, whole.levels, strict=True)):
        np.testing.assert_allclose(ours, ref, rtol=1e-12, atol=0, err_msg=f"level {k} of the whole World")


def test_per_axis_resampling_is_the_bilinear_lookup_at_the_texel_centres():
    rng = np.random.default_rng(3)
    for h, w in ((16, 32), (64, 128), (128, 256)):
        level = rng.random((h, w, 6)).astype(np.float32)
        ours = prefilter.resample_equirect(level, 256)
        lookup = hdri.equirect_lookup(level, hdri.equirect_directions(128, 256))
        assert ours.shape == (128, 256, 6)
        np.testing.assert_allclose(ours, lookup, atol=1e-5)


def test_each_level_is_the_narrowest_width_whose_texels_fit_its_lobe():
    for r in (0.0, 0.05, 0.14, 0.25, 0.4, 0.6, 1.0):
        alpha = max(r * r, prefilter.constants.MIN_ALPHA)
        width = prefilter.level_width(r)
        assert width & (width - 1) == 0 and 32 <= width <= prefilter.LEVEL_WIDTH
        if width < prefilter.LEVEL_WIDTH:
            assert 2 * np.pi / width <= prefilter.TEXEL_ALPHA * alpha
        if width > 32:
            assert 2 * np.pi / (width // 2) > prefilter.TEXEL_ALPHA * alpha


def test_a_lobe_under_a_texel_takes_fewer_samples_than_a_wider_one():
    texel = 2 * np.pi / 512
    sharp = prefilter.level_samples(0.01 * texel, 512)
    subtexel = prefilter.level_samples(0.3 * texel, 512)
    wide = prefilter.level_samples(3 * texel, 512)
    assert np.prod(sharp) < np.prod(subtexel) < np.prod(wide) == np.prod(prefilter.SAMPLES)
    assert subtexel[1] == prefilter.SAMPLES[1]  # the φ strata the error depends on are kept
