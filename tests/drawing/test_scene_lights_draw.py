"""Blender's light objects in the shader (glsl/tf_lights.glsl) against the numpy mirror, per pixel.

A tilted quad (many view angles and light distances in one frame) lit by each kind of light,
drawn on whatever OpenGL is present (Mesa llvmpipe here) and compared with
:func:`precompute.shading.lights.shade` pixel by pixel, in both colour modes, with the film
table in its uniform buffer and in its texture, with and without the split sum.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from test_gpu_draw import PROJ, SIZE, VIEW, baked, quad_pixels, tilted_quad_item, world_sh

from precompute.colour import film_colour
from precompute.output import render
from precompute.sh import projection
from precompute.shading import lights as light_shading
from precompute.shading import sh_sum

pytestmark = pytest.mark.blender


def translation(x, y, z, rot=None) -> np.ndarray:
    """A 4×4 with rotation ``rot`` (3×3, default identity) and translation (x, y, z)."""
    m = np.eye(4)
    if rot is not None:
        m[:3, :3] = rot
    m[:3, 3] = (x, y, z)
    return m


def facing(direction) -> np.ndarray:
    """A rotation whose −Z axis points along ``direction``."""
    z = -np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    x = np.cross([0.0, 0.0, 1.0], z)
    if np.linalg.norm(x) < 1e-6:
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


def scene_lights():
    """One light of each kind (and a disk area light), all in front of the quad."""
    rows = [
        light_shading.light_from_blender(
            "SUN", translation(0, 0, 0, facing([0.3, 0.8, -0.4])), (1.0, 0.9, 0.8), 3.0, angle=0.05
        ),
        light_shading.light_from_blender(
            "POINT", translation(0.8, -2.0, 0.6), (0.9, 1.0, 0.7), 400.0, radius=0.1
        ),
        light_shading.light_from_blender(
            "SPOT",
            translation(-0.5, -2.5, -0.4, facing([0.2, 1.0, 0.1])),
            (1.0, 0.7, 0.6),
            600.0,
            radius=0.05,
            spot_size=math.radians(40.0),
            spot_blend=0.3,
        ),
        light_shading.light_from_blender(
            "AREA",
            translation(0.3, -2.0, 1.2, facing([-0.1, 1.0, -0.5])),
            (0.6, 0.8, 1.0),
            300.0,
            shape="RECTANGLE",
            size=1.0,
            size_y=0.5,
        ),
        light_shading.light_from_blender(
            "AREA",
            translation(-1.0, -1.5, 0.8, facing([0.5, 1.0, -0.3])),
            (1.0, 1.0, 1.0),
            200.0,
            shape="DISK",
            size=0.6,
            spread=math.radians(120.0),
        ),
    ]
    return light_shading.Lights.from_rows(rows)


def quad_positions(model):
    """World positions of :func:`test_gpu_draw.quad_pixels`' pixels (camera ray ∩ the quad's plane)."""
    rays = render.sphere_view(SIZE, SIZE, 4.0, 32.0).rays
    cam = np.array([0.0, -4.0, 0.0])
    normal = np.linalg.inv(model[:3, :3]).T @ np.array([0.0, -1.0, 0.0])
    t = ((model[:3, 3] - cam) @ normal) / (rays @ normal)
    return cam + t[..., None] * rays


def draw_lit_quad(gd, result, film_ubo: bool, sh_weight: float = 1.0, prefiltered=None):
    """The tilted quad of ``result``'s film under :func:`test_gpu_draw.world_sh` × 0.05 and
    :func:`scene_lights`, drawn with its film table in its uniform buffer (``film_ubo``) or its
    texture: a namespace of the draw's group and image, the film table, the lights, the lighting
    and the quad's inside pixels (mask, normals, views, world positions)."""
    from types import SimpleNamespace

    coeffs, _img = world_sh()
    lighting = gd.resources.Lighting.from_sh(coeffs * 0.05, 5, result.material.roughness)
    film = film_colour.film_table(result)
    item = tilted_quad_item(gd, gd.resources.TableTexture.from_result(result), lighting)
    item.roughness = result.material.roughness
    item.sh_weight = sh_weight
    item.film = gd.resources.FilmTexture.from_film(film)
    if not film_ubo:
        item.film = dataclasses.replace(item.film, ubo=None)
    item.prefiltered = prefiltered
    found = scene_lights()
    item.lights = gd.resources.lights_content(found)
    (group,) = gd.draw.prepare_draw([item], VIEW, PROJ, display_srgb=False).groups
    image = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE)
    inside, n, views = quad_pixels(item.model_matrix)
    p = quad_positions(item.model_matrix)[inside]
    return SimpleNamespace(
        group=group,
        image=image,
        film=film,
        lights=found,
        lighting=lighting,
        inside=inside,
        n=n,
        views=views,
        p=p,
    )


@pytest.mark.parametrize(
    "colour_mode, film_ubo, split",
    [("spectral", True, False), ("per_channel", False, False), ("per_channel", True, True)],
)
def test_lights_variant_matches_numpy_per_pixel(gd, colour_mode, film_ubo, split):
    """tf_lights.glsl against shading.lights.shade: every light kind, 1e-4 of the peak (float32)."""
    from precompute.shading import policy, split_sum
    from precompute.world import prefilter

    result = baked(5, colour_mode, False)
    pre = prefiltered = None
    if split:
        _coeffs, img = world_sh()
        full = prefilter.prefilter(img * 0.05, width=64)
        levels, moments = full.resampled(64), full.resampled_moments(64)
        prefiltered = gd.resources.PrefilterTexture.from_levels(levels, moments)
        pre = prefilter.Prefiltered(
            tuple(levels), np.asarray(policy.ROUGHNESS_LEVELS), 0, tuple(moments), None
        )
    d = draw_lit_quad(gd, result, film_ubo, 0.5 if split else 1.0, prefiltered)
    assert d.group.variant.lights and d.group.variant.film_ubo == film_ubo and not d.group.variant.lamps

    roughness = result.material.roughness
    lit = light_shading.shade(d.film, d.lights, roughness, d.p, d.n, d.views)
    world = sh_sum.shade_sh(result, d.lighting.coefficients, d.n, d.views)
    if split:
        if not policy.uses_moment(5, False):
            pre = dataclasses.replace(pre, moments=None)
        world = 0.5 * split_sum.shade_split_sum(result, pre, d.n, d.views) + 0.5 * world
    expected = world + lit
    assert np.max(lit) > 0.5 * np.max(expected)  # the lights dominate
    err = np.max(np.abs(d.image[d.inside][:, :3] - expected)) / np.max(expected)
    print(f"lights variant {colour_mode} ubo {film_ubo} split {split}: {err:.1e} of the peak")
    assert d.inside.sum() > 300 and err < 1e-4, err


def test_no_lights_no_loop(gd):
    """Without lights the variant has no light loop, and an empty light list packs to None."""
    assert gd.resources.lights_content(light_shading.Lights.from_rows([])) is None
    result = baked(5, "per_channel", False)
    item = tilted_quad_item(
        gd,
        gd.resources.TableTexture.from_result(result),
        gd.resources.Lighting.from_sh(projection.project_equirect(np.ones((8, 16, 3)), 5), 5, 0.3),
    )
    item.film = gd.resources.FilmTexture.from_film(film_colour.film_table(result))
    (group,) = gd.draw.prepare_draw([item], VIEW, PROJ, display_srgb=False).groups
    assert not group.variant.lights


@pytest.mark.parametrize("colour_mode, film_ubo", [("spectral", False), ("per_channel", True)])
def test_a_diffuse_base_is_lit_by_the_lights_as_numpy_lights_it(gd, colour_mode, film_ubo):
    """A film over a diffuse base (Base Color): tf_lights.glsl's base term against
    shading.lights.shade per pixel, 1e-4 of the peak; without the term the picture would be
    off by far more (the base carries most of what the lights bring)."""
    from precompute.bakes import bake

    result = bake.bake(baked(5, colour_mode, False).material.with_(base_color=(0.7, 0.35, 0.15)))
    d = draw_lit_quad(gd, result, film_ubo)
    assert d.film.diffuse is not None
    assert d.group.variant.lights and d.group.variant.film_ubo == film_ubo

    roughness = result.material.roughness
    lit = light_shading.shade(d.film, d.lights, roughness, d.p, d.n, d.views)
    bare = light_shading.shade(
        dataclasses.replace(d.film, diffuse=None), d.lights, roughness, d.p, d.n, d.views
    )
    expected = sh_sum.shade_sh(result, d.lighting.coefficients, d.n, d.views) + lit
    err = np.max(np.abs(d.image[d.inside][:, :3] - expected)) / np.max(expected)
    base = np.max(np.abs(lit - bare)) / np.max(expected)
    print(f"diffuse base {colour_mode} ubo {film_ubo}: {err:.1e} of the peak, the base term {base:.2f}")
    assert d.inside.sum() > 300 and err < 1e-4, err
    assert base > 0.2
