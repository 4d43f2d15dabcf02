"""Transparent films drawn on the GPU (glsl/tf_transmit.glsl, addon/gpu/draw.py's blend passes).

A wall is drawn over what the framebuffer holds: multiply by T, then add S·R·L, with alpha
1 − (1 − alpha behind)·mean(T). Checked per pixel against precompute.shading.transmit and
sh_sum.shade_sh on a tilted quad, and as a closed bubble (two walls) on a sphere.
"""

import numpy as np
import pytest
from test_gpu_draw import (
    DISTANCE,
    FOV,
    PROJ,
    SIZE,
    VIEW,
    Item,
    baked,
    erode,
    quad_pixels,
    tilted_quad_item,
    uv_sphere_mesh,
    world_sh,
)

from precompute.colour import film_colour
from precompute.output import render
from precompute.shading import sh_sum, transmit
from precompute.shading.variant import TRANSMIT_ADD, TRANSMIT_MULTIPLY

pytestmark = pytest.mark.blender

BEHIND = (0.3, 0.55, 0.8)


def behind(alpha):
    """A depth_from hook filling the frame with the BEHIND colour and ``alpha``."""

    def fill(_offscreen):
        import gpu

        gpu.state.active_framebuffer_get().clear(color=(*BEHIND, alpha))

    return fill


@pytest.mark.parametrize(
    "colour_mode, wall, film_ubo",
    [
        ("spectral", (transmit.WALL_SHEET, 1.0), True),
        ("per_channel", (transmit.WALL_CYCLES, 1.0), True),
        ("per_channel", (transmit.WALL_SHEET, 1.5), False),
        ("per_channel", (transmit.WALL_CYCLES, 1.45, 0.8, 0.5, 0.2), True),  # a Base Color tint
    ],
)
def test_wall_composites_like_numpy_per_pixel(gd, colour_mode, wall, film_ubo):
    result = baked(5, colour_mode, False)
    table = gd.resources.TableTexture.from_result(result)
    world, _img = world_sh()
    lighting = gd.resources.Lighting.from_sh(world, 5, result.material.roughness)
    film = film_colour.film_table(result)
    item = tilted_quad_item(gd, table, lighting)
    item.film = gd.resources.FilmTexture.from_film(film)
    if not film_ubo:
        import dataclasses

        item.film = dataclasses.replace(item.film, ubo=None)
    item.wall = wall
    groups = gd.draw.prepare_draw([item], VIEW, PROJ, display_srgb=False).groups
    assert [(g.cull, g.blend, g.variant.transmit) for g in groups] == [
        ("FRONT", "MULTIPLY", TRANSMIT_MULTIPLY),
        ("FRONT", "ADDITIVE_PREMULT", TRANSMIT_ADD),
        ("BACK", "MULTIPLY", TRANSMIT_MULTIPLY),
        ("BACK", "ADDITIVE_PREMULT", TRANSMIT_ADD),
    ]
    for alpha in (0.0, 1.0):
        image = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE, depth_from=behind(alpha))
        inside, n, views = quad_pixels(item.model_matrix)
        tint = transmit.wall_tint(wall) if len(wall) >= 5 else None
        t, s = transmit.shade(film, n, views, wall[0], wall[1], tint=tint)
        reflected = s * sh_sum.shade_sh(result, lighting.coefficients, n, views)
        expected = transmit.composite(np.array(BEHIND), reflected, t)
        err = np.max(np.abs(image[inside][:, :3] - expected)) / np.max(expected)
        print(f"wall {colour_mode} {wall}: {err:.1e} of the peak; T mean {t.mean():.3f}")
        assert inside.sum() > 300 and err < 1e-4, err
        expected_alpha = 1.0 - (1.0 - alpha) * t.mean(axis=-1)
        assert np.max(np.abs(image[inside][:, 3] - expected_alpha)) < 1e-5
        assert np.allclose(image[erode(erode(~inside))][:, :3], BEHIND)  # nothing drawn off the quad
    # the behind colour is seen through the film: T > 0.5 on every channel (less the tint)
    assert np.all(t > 0.5 * (transmit.wall_tint(wall) ** 2))


def test_closed_bubble_shows_both_walls(gd, bpy):
    """A sphere as a bubble: through the middle two walls, T_back·T_front·B + …; never below
    (1 − R_max)² of the background per channel at normal incidence, and brighter than opaque."""
    mesh = uv_sphere_mesh(bpy, name="tf_bubble")
    positions, normals, tris, _ = gd.mesh.mesh_arrays(mesh)
    bpy.data.meshes.remove(mesh)
    result = baked(5, "per_channel", False)
    world, _img = world_sh()
    lighting = gd.resources.Lighting.from_sh(world, 5, result.material.roughness)
    film = film_colour.film_table(result)
    item = Item(gd.mesh.MeshBatch.from_arrays(positions, normals, tris), None, lighting)
    item.table = gd.resources.TableTexture.from_result(result)
    item.film = gd.resources.FilmTexture.from_film(film)
    item.wall = (transmit.WALL_SHEET, 1.0)
    image = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE, depth_from=behind(0.0))
    item.wall = None
    opaque = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE, depth_from=behind(0.0))
    view = render.sphere_view(SIZE, SIZE, DISTANCE, FOV)
    inner = erode(erode(view.mask))
    # numpy: front wall at the sphere's near hit, back wall at its far hit (normal towards the viewer)
    cam = np.array([0.0, -DISTANCE, 0.0])
    rays = view.rays[inner]
    b = rays @ cam
    far = -b + np.sqrt(np.maximum(b * b - (cam @ cam - 1.0), 0.0))
    back_n = -(cam + far[:, None] * rays)
    v_back = -rays
    front_n, v_front = view.normals[inner], view.views[inner]
    t_back, s_back = transmit.shade(film, back_n, v_back, transmit.WALL_SHEET, 1.0)
    t_front, s_front = transmit.shade(film, front_n, v_front, transmit.WALL_SHEET, 1.0)
    r_back = s_back * sh_sum.shade_sh(result, lighting.coefficients, back_n, v_back)
    r_front = s_front * sh_sum.shade_sh(result, lighting.coefficients, front_n, v_front)
    expected = transmit.composite(transmit.composite(np.array(BEHIND), r_back, t_back), r_front, t_front)
    rel = np.abs(image[inner][:, :3] - expected) / np.max(expected)
    print(f"bubble: median {np.median(rel):.1e}, max {np.max(rel):.1e} of the peak")
    assert np.median(rel) < 2e-3 and np.max(rel) < 5e-2
    alpha = 1.0 - t_back.mean(-1) * t_front.mean(-1)
    assert np.median(np.abs(image[inner][:, 3] - alpha)) < 2e-3
    # the background shows through: far more of it than behind the opaque film
    assert np.all(image[inner][:, :3] >= 0.8 * np.array(BEHIND))
    assert np.mean(image[inner][:, :3]) > np.mean(opaque[inner][:, :3]) + 0.2


def glossy_item(gd, result, make_item):
    """(item, prefilter, film table): ``make_item(table, lighting)`` lit by world_sh() through a
    64-wide prefilter with its moments, split sum only (SH weight 0), with ``result``'s film."""
    from precompute.shading import policy
    from precompute.world import prefilter

    world, img = world_sh()
    lighting = gd.resources.Lighting.from_sh(world, 5, result.material.roughness)
    full = prefilter.prefilter(img, width=64)
    levels, moments = full.resampled(64), full.resampled_moments(64)
    pre = prefilter.Prefiltered(tuple(levels), np.asarray(policy.ROUGHNESS_LEVELS), 0, tuple(moments))
    film = film_colour.film_table(result)
    item = make_item(gd.resources.TableTexture.from_result(result), lighting)
    item.prefiltered = gd.resources.PrefilterTexture.from_levels(levels, moments)
    item.roughness, item.sh_weight = result.material.roughness, 0.0
    item.film = gd.resources.FilmTexture.from_film(film)
    return item, pre, film


@pytest.mark.parametrize("tint", [None, (0.8, 0.5, 0.2)])
def test_solid_glass_shows_the_world_along_the_exit_ray(gd, tint):
    """WALL_SOLID with the split sum: what is behind is replaced by T × the prefiltered World at
    roughness 0 along transmit.solid_exit, plus the film's reflection (split only, weight 0);
    a Base Color ``tint`` multiplies what passed in and out (√tint each way, Cycles' glass)."""
    import dataclasses

    from precompute.shading import split_sum

    result = baked(5, "spectral", False)
    item, pre, film = glossy_item(gd, result, lambda table, lighting: tilted_quad_item(gd, table, lighting))
    item.wall = (transmit.WALL_SOLID, 1.5, *(tint or ()))
    image = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE, depth_from=behind(0.0))
    inside, n, views = quad_pixels(item.model_matrix)
    t, s = transmit.shade(film, n, views, transmit.WALL_SOLID, 1.5)
    exit_dirs = transmit.solid_exit(n, views, 1.5)
    seen = split_sum.lookup(pre, exit_dirs, np.zeros(len(n)))
    glint = (
        t
        * (1.0 - np.sqrt(t))
        * split_sum.lookup(pre, transmit.solid_internal(n, views, 1.5), np.zeros(len(n)))
    )
    through = transmit.wall_tint(item.wall)
    expected = s * split_sum.shade_split_sum(result, pre, n, views) + through * (t * seen + glint)
    err = np.max(np.abs(image[inside][:, :3] - expected)) / np.max(expected)
    print(f"solid glass: {err:.1e} of the peak")
    assert inside.sum() > 300 and err < 1e-3, err
    assert np.allclose(image[inside][:, 3], 1.0, atol=1e-6)  # opaque: the glass replaces what is behind
    # the exit ray is bent: a straight view through would see other parts of the World
    straight = split_sum.lookup(pre, -views, np.zeros(len(n)))
    assert np.max(np.abs(seen - straight)) > 0.02
    assert dataclasses.is_dataclass(pre)


def test_a_closed_bubbles_far_wall_reflects_on_inside(gd, bpy):
    """A closed thin wall with the split sum and a thickness varying across it: the far wall's
    reflection leaves through the wall it meets next and is reflected on inside
    (shading.transmit.inside_reflections, tf_wall_inside). The draw with the reflections inside minus the draw
    without equals numpy's T_front·(S₁r₁L(d₁)(T₂ − 1) + R₁·extra) per pixel."""
    import dataclasses

    from precompute.shading import split_sum

    mesh = uv_sphere_mesh(bpy, name="tf_bubble_inside")
    positions, normals, tris, _ = gd.mesh.mesh_arrays(mesh)
    bpy.data.meshes.remove(mesh)
    parameter = (positions[:, 0] + 1.0) / 2.0  # the thickness across the bubble, linear in x
    batch = gd.mesh.MeshBatch.from_arrays(positions, normals, tris, parameter, wall=True)
    assert batch.inside.closed and np.allclose(batch.inside.fit, (0.5, 0.0, 0.0, 0.5), atol=1e-5)
    result = baked(5, "per_channel", True)
    item, pre, film = glossy_item(gd, result, lambda table, lighting: Item(batch, table, lighting))
    item.wall = (transmit.WALL_CYCLES, 1.0)
    image = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE, depth_from=behind(0.0))
    item.batch = dataclasses.replace(batch, inside=None)
    without = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE, depth_from=behind(0.0))
    item.batch = dataclasses.replace(batch, inside=transmit.Inside(False, batch.inside.fit))
    open_mesh = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE, depth_from=behind(0.0))
    assert np.array_equal(open_mesh, without)  # an open mesh has no inside

    view = render.sphere_view(SIZE, SIZE, DISTANCE, FOV)
    inner = erode(erode(erode(view.mask)))
    cam = np.array([0.0, -DISTANCE, 0.0])
    rays = view.rays[inner]
    b = rays @ cam
    p_back = cam + (-b + np.sqrt(np.maximum(b * b - (cam @ cam - 1.0), 0.0)))[:, None] * rays
    back_n, v_back = -p_back, -rays
    front_n, v_front = view.normals[inner], view.views[inner]
    lo, hi = result.thicknesses_nm[0], result.thicknesses_nm[-1]
    back_param, front_param = (p_back[:, 0] + 1.0) / 2.0, (front_n[:, 0] + 1.0) / 2.0
    t_back, s_back = transmit.shade(film, back_n, v_back, transmit.WALL_CYCLES, 1.0, back_param)
    t_front, _s = transmit.shade(film, front_n, v_front, transmit.WALL_CYCLES, 1.0, front_param)
    cos_back = np.sum(back_n * v_back, -1)
    rows = transmit.thickness_lerp(film, back_param, len(cos_back))
    r_far = s_back * np.clip(transmit.white_reflectance(film, rows, cos_back), 0.0, 1.0)
    reflected = s_back * split_sum.shade_split_sum(result, pre, back_n, v_back, lo + back_param * (hi - lo))
    roughness = np.full(len(rays), result.material.roughness)
    exit_t, extra = transmit.inside_reflections(
        film,
        p_back,
        back_n,
        v_back,
        np.zeros(3),
        batch.inside.fit,
        transmit.WALL_CYCLES,
        1.0,
        None,
        lambda d: split_sum.lookup(pre, d, roughness[: len(d)]),
    )
    expected = t_front * (reflected * (exit_t - 1.0) + r_far * extra)
    found = image[inner][:, :3] - without[inner][:, :3]
    rel = np.abs(found - expected) / np.max(np.abs(expected))
    print(
        f"inside: change {np.abs(expected).mean(0).round(4)} mean, max {np.abs(expected).max():.3f}; "
        f"GPU − numpy median {np.median(rel):.1e}, 99th {np.quantile(rel, 0.99):.1e} of the peak"
    )
    assert np.abs(expected).max() > 0.01  # the reflections inside are there to see
    assert np.median(rel) < 2e-3 and np.quantile(rel, 0.99) < 3e-2
