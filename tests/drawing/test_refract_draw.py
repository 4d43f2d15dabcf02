"""Solid glass refracting the scene behind it, drawn on the GPU (glsl/tf_refract.glsl,
``TF_REFRACT``) against its numpy twin (precompute/shading/glass/refract.py), per pixel.

A flat tilted glass quad whose object origin lies behind it (the sphere the exit ray assumes),
over a scene-behind texture: a wall 3 units behind the origin with a smooth colour pattern, its
top rows empty (the World along the exit ray is seen there).
"""

import numpy as np
import pytest
from test_gpu_draw import DISTANCE, FOV, PROJ, SIZE, VIEW, Item, baked, rotation, unit, world_sh

from precompute.colour import film_colour
from precompute.output import render
from precompute.shading import policy, split_sum, transmit
from precompute.shading.glass import probe, refract
from precompute.shading.variant import TRANSMIT_ADD, TRANSMIT_MULTIPLY
from precompute.world import prefilter

pytestmark = pytest.mark.blender

#: The quad's plane in object space (its origin 0.6 behind it).
QUAD_Y = -0.6


def behind_scene():
    """(colour (H, W, 3), depth (H, W)) of the scene behind, top row first: a wall at y = 3 with a
    smooth pattern, nothing in the top eighth of the picture, a near ledge in its bottom third."""
    u = (np.arange(SIZE) + 0.5) / SIZE
    uu, vv = np.meshgrid(u, u[::-1])
    colour = np.stack([0.2 + 0.6 * uu, 0.3 + 0.5 * vv, 0.5 + 0.3 * np.sin(6 * uu) * np.cos(5 * vv)], -1)
    depth = np.full((SIZE, SIZE), 3.0 + DISTANCE)
    depth[: SIZE // 8] = np.inf
    depth[-SIZE // 3 :] = 2.5  # a near ledge: the glass's mirror rays meet it
    return colour, depth


def quad_item(gd, table, lighting):
    """A 2×2 quad at local y = QUAD_Y, tilted 35° about x and 25° about z."""
    positions = np.array([[-1, QUAD_Y, -1], [1, QUAD_Y, -1], [1, QUAD_Y, 1], [-1, QUAD_Y, 1]], np.float32)
    batch = gd.mesh.MeshBatch.from_arrays(
        positions, np.tile([0.0, -1.0, 0.0], (4, 1)), [[0, 1, 2], [0, 2, 3]]
    )
    return Item(batch, table, lighting, rotation(0, 35.0) @ rotation(2, 25.0))


def quad_hits(model):
    """(inside mask, points, normals towards the viewer, views) of the pixels seeing the quad."""
    rays = render.sphere_view(SIZE, SIZE, DISTANCE, FOV).rays
    cam = np.array([0.0, -DISTANCE, 0.0])
    m3 = model[:3, :3]
    normal = unit(np.linalg.inv(m3).T @ np.array([0.0, -1.0, 0.0]))
    anchor = m3 @ np.array([0.0, QUAD_Y, 0.0])
    t = ((anchor - cam) @ normal) / (rays @ normal)
    hit = cam + t[..., None] * rays
    local = hit @ np.linalg.inv(m3).T
    inside = (np.abs(local[..., 0]) < 0.97) & (np.abs(local[..., 2]) < 0.97) & (t > 0)
    views = unit(cam - hit[inside])
    n = np.broadcast_to(normal, views.shape)
    n = np.where(np.sum(n * views, -1, keepdims=True) < 0, -n, n)
    return inside, hit[inside], n, views


def glass_lighting(gd, colour_mode):
    """(bake, lighting buffer, prefiltered World, film table) of a roughness-0.15 film (l = 8) on
    solid glass under the test World."""
    result = baked(8, colour_mode, False)
    world, img = world_sh()
    lighting = gd.resources.Lighting.from_sh(world, 8, result.material.roughness)
    full = prefilter.prefilter(img, width=64)
    levels, moments = full.resampled(64), full.resampled_moments(64)
    pre = prefilter.Prefiltered(tuple(levels), np.asarray(policy.ROUGHNESS_LEVELS), 0, tuple(moments))
    return result, lighting, pre, film_colour.film_table(result)


def as_solid_glass(gd, item, result, pre, film):
    """Make ``item`` solid glass (η = 1.5) of the bake ``result``, the World ``pre`` and ``film``;
    (colour, depth, :class:`BehindTexture`) of :func:`behind_scene` behind it."""
    item.prefiltered = gd.resources.PrefilterTexture.from_levels(pre.levels, pre.moments)
    item.roughness, item.sh_weight = result.material.roughness, 0.0
    item.film = gd.resources.FilmTexture.from_film(film)
    item.wall = (transmit.WALL_SOLID, 1.5)
    colour, depth = behind_scene()
    return colour, depth, gd.resources.BehindTexture.from_image(colour, depth)


def refracted_paths(item, film, depth, edge: bool = True):
    """The quad's pixels (inside mask), their (points, normals, views), the film's (T, R) there,
    the exit rays (points, directions) and their march over ``depth`` (hit, rows, columns;
    ``edge``: the picture's edge taken as the scene beyond it, as where no probe is drawn)."""
    inside, points, n, views = quad_hits(item.model_matrix)
    t, s = transmit.shade(film, n, views, transmit.WALL_SOLID, 1.5)
    exit_points, dirs = refract.exit_ray(points, n, views, item.model_matrix[:3, 3], 1.5)
    inv_view = np.linalg.inv(VIEW)
    marched = refract.march(
        exit_points, dirs, depth, PROJ @ VIEW, inv_view[:3, 3], inv_view[:3, 2], (1.0, 1.0, 0.0, 0.0), edge
    )
    return inside, (points, n, views), (t, s), (exit_points, dirs), marched


def with_scene_mirror(expected, surface, scene, pre, roughness, t, around=None):
    """(``expected`` + the scene mirrored in place of the World where the mirror ray meets it,
    clamped at 0; which mirror rays met it; the mirror's weight) at the pixels ``surface`` =
    (points, normals, views) of solid glass of transmittance ``t``, over ``scene`` = (colour, depth)
    seen from VIEW, PROJ; ``around``: the scene probe (image, centre) where the march meets
    nothing, or None."""
    points, n, views = surface
    colour, depth = scene
    inv_view = np.linalg.inv(VIEW)
    mirror = -views + 2.0 * np.sum(n * views, -1, keepdims=True) * n
    m_hit, m_rows, m_cols = refract.march(  # with a probe, it shows what lies beyond the edge
        points,
        mirror,
        depth,
        PROJ @ VIEW,
        inv_view[:3, 3],
        inv_view[:3, 2],
        (1.0, 1.0, 0.0, 0.0),
        around is None,
    )
    world_m = split_sum.lookup(pre, mirror, np.zeros(len(n)))
    fallback = world_m
    if around is not None:  # where the march meets nothing, the probe where it shows something
        p_colour, p_seen = probe.lookup(*around, points, mirror, covered=picture(depth))
        fallback = np.where(p_seen[:, None], p_colour, world_m)
    scene_m = refract.seen(m_hit, m_rows, m_cols, colour, fallback, depth)
    weight = refract.mirror_weight(roughness)
    return np.maximum(expected + weight * (1.0 - np.sqrt(t)) * (scene_m - world_m), 0.0), m_hit, weight


@pytest.mark.parametrize("tint", [None, (0.8, 0.5, 0.2)])
def test_solid_glass_refracts_the_scene_behind_like_numpy(gd, tint):
    """…and with a Principled Base Color ``tint``: what passed in and out (the scene or World
    refracted, the glints) times the tint (√tint each way, Cycles' glass); the reflections not."""
    result, lighting, pre, film = glass_lighting(gd, "spectral")  # the scene's mirror weighs 0.7
    item = quad_item(gd, gd.resources.TableTexture.from_result(result), lighting)
    colour, depth, behind = as_solid_glass(gd, item, result, pre, film)
    item.wall = (*item.wall, *(tint or ()))
    through = transmit.wall_tint(item.wall)
    groups = gd.draw.prepare_draw([item], VIEW, PROJ, display_srgb=False, behind=behind).groups
    assert [(g.variant.transmit, g.variant.refract) for g in groups] == [
        (TRANSMIT_MULTIPLY, True),
        (TRANSMIT_ADD, True),
    ] * 2
    image = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE, behind=behind)

    inside, (points, n, views), (t, s), (exit_points, dirs), marched = refracted_paths(item, film, depth)
    hit, rows, cols = marched
    seen = refract.seen(hit, rows, cols, colour, split_sum.lookup(pre, dirs, np.zeros(len(n))), depth)
    glint = (
        t
        * (1.0 - np.sqrt(t))
        * split_sum.lookup(pre, transmit.solid_internal(n, views, 1.5), np.zeros(len(n)))
    )
    expected = s * split_sum.shade_split_sum(result, pre, n, views) + through * (t * seen + glint)
    expected, m_hit, weight = with_scene_mirror(
        expected, (points, n, views), (colour, depth), pre, item.roughness, t
    )
    err = np.abs(image[inside][:, :3] - expected).max(axis=-1) / np.max(expected)
    print(
        f"refracted glass (tint {tint}): {inside.sum()} px, {hit.mean():.0%} hit the scene behind; "
        f"error median {np.median(err):.1e}, 99th percentile {np.percentile(err, 99):.1e}, "
        f"max {err.max():.1e} of the peak"
    )
    print(f"mirror rays meeting the scene: {m_hit.mean():.0%}, weight {weight}")
    assert inside.sum() > 300 and 0.3 < hit.mean() < 0.98  # both the scene and the World are seen
    assert m_hit.mean() > 0.05 and weight > 0.0  # the mirror of the scene is exercised
    # float32 on the GPU may pick the neighbouring texel at a texel's edge: one texel of the
    # pattern is ≤ 0.6 / SIZE ≈ 0.01 of the peak
    assert np.median(err) < 1e-4 and np.percentile(err, 99) < 2e-2 and err.max() < 5e-2
    assert np.allclose(image[inside][:, 3], 1.0, atol=1e-6)  # the glass replaces what is behind
    # the refracted picture is not the picture straight behind
    straight = colour[np.nonzero(inside)]
    assert np.median(np.abs(seen[hit] - straight[hit])) > 0.02


def picture(depth):
    """Whether world points lie in the picture of the scene behind (``depth``'s shape), seen from
    VIEW, PROJ: there the march is read, not the probe."""
    return lambda q: refract.on_picture(q, PROJ @ VIEW, (1.0, 1.0, 0.0, 0.0), depth.shape)


def probe_around():
    """(image, centre) of a scene probe: a smooth colour over every direction at distance 5 from
    a point beside the quad, the World (no distance) in a cap about +z."""
    from precompute.world import hdri

    dirs = hdri.equirect_directions(32, 64)
    x, y, z = dirs[..., 0], dirs[..., 1], dirs[..., 2]
    distance = np.where(z < 0.5, 5.0, 0.0)
    image = np.stack([0.4 + 0.3 * x, 0.5 + 0.2 * np.sin(3 * y), 0.3 + 0.25 * z, distance], -1)
    return image, np.array([0.2, 0.5, -0.3])


def test_paths_that_leave_the_picture_see_the_probe_like_numpy(gd):
    """Where the refracted ray's march and the mirror's meet nothing, the scene probe
    (tf_probe.glsl ↔ shading.glass.probe.lookup) stands in for the World where it shows
    something off the picture (in it, the march has read the picture and the World stands): per
    pixel as numpy, and not the World there."""
    result, lighting, pre, film = glass_lighting(gd, "spectral")
    item = quad_item(gd, gd.resources.TableTexture.from_result(result), lighting)
    colour, depth, behind = as_solid_glass(gd, item, result, pre, film)
    depth[: SIZE // 2] = np.inf  # the upper half of the picture empty: more paths leave it
    behind = gd.resources.BehindTexture.from_image(colour, depth)
    around = probe_around()
    image = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE, behind=behind.with_probe(*around))

    inside, (points, n, views), (t, s), (exit_points, dirs), marched = refracted_paths(
        item, film, depth, False
    )
    hit, rows, cols = marched
    world = split_sum.lookup(pre, dirs, np.zeros(len(n)))
    p_colour, p_seen = probe.lookup(*around, exit_points, dirs, covered=picture(depth))
    # without a probe the picture's edge stands for the scene beyond it (policy.REFRACT_EDGE);
    # with one, the probe (or the World) does
    edge_hit, edge_rows, edge_cols = refracted_paths(item, film, depth)[4]
    by_edge = edge_hit & ~hit
    fallback = np.where(p_seen[:, None], p_colour, world)
    edge_seen = refract.seen(edge_hit, edge_rows, edge_cols, colour, fallback, depth)
    _c, p_any = probe.lookup(*around, exit_points, dirs)
    seen = refract.seen(hit, rows, cols, colour, fallback, depth)
    glint = (
        t
        * (1.0 - np.sqrt(t))
        * split_sum.lookup(pre, transmit.solid_internal(n, views, 1.5), np.zeros(len(n)))
    )
    expected = s * split_sum.shade_split_sum(result, pre, n, views) + t * seen + glint
    expected, _m_hit, _w = with_scene_mirror(
        expected, (points, n, views), (colour, depth), pre, item.roughness, t, around
    )
    err = np.abs(image[inside][:, :3] - expected).max(axis=-1) / np.max(expected)
    shown = ~hit & p_seen
    print(
        f"probe: {inside.sum()} px, {shown.mean():.0%} see it, {(~hit & ~p_seen).mean():.0%} the World;"
        f" error median {np.median(err):.1e}, 99th percentile {np.percentile(err, 99):.1e}"
    )
    mirror = -views + 2.0 * np.sum(n * views, -1, keepdims=True) * n
    _c, mirror_seen = probe.lookup(*around, points, mirror, covered=picture(depth))
    print(
        f"probe: {(~hit & p_any & ~p_seen).mean():.0%} meet it in the picture (the World stands);"
        f" the mirror rays: {mirror_seen.mean():.0%} see it"
    )
    assert shown.sum() > 20 and (~hit & ~p_seen).any() and (~hit & p_any & ~p_seen).any()
    # where the edge rule would have met the picture's edge, the draw is numpy's without it
    edge_err = np.abs(t * (edge_seen - seen))[by_edge].max(axis=-1) / np.max(expected)
    print(f"probe: {by_edge.sum()} px the edge rule would take; it would be off by {np.median(edge_err):.1e}")
    assert by_edge.sum() >= 10 and np.median(edge_err) > 1e-2
    assert np.percentile(err[by_edge], 99) < 2e-3
    assert mirror_seen.mean() > 0.2
    # the probe is smooth: no texel of a pattern to pick differently (read by the path's direction
    # instead of the point it meets, the 99th percentile is 1.8e-2)
    assert np.median(err) < 1e-4 and np.percentile(err, 99) < 2e-3
    # the probe is not the World where it is seen
    assert np.median(np.abs(p_colour[shown] - world[shown]).max(-1)) > 0.05
    assert np.median(np.abs(image[inside][:, :3] - expected).max(axis=-1)) < 1e-4


def test_the_scene_behind_is_placed_in_the_widened_window_and_checked(gd):
    """BehindTexture.screen maps the headless frame's widened window (filter pad) to the
    overscanned background pass (margin): its pixel pad + i is the picture's pixel margin + i; a
    colour and depth of different sizes are refused, naming both shapes."""
    width, height, pad, margin = 40, 30, 3, 10
    sx, sy, ox, oy = gd.resources.BehindTexture.screen(width, height, pad, margin)
    for i in (0, 17, width - 1):
        x = (pad + i + 0.5) / (width + 2 * pad)
        assert (x * sx + ox) * (width + 2 * margin) == pytest.approx(margin + i + 0.5)
    y = (pad + height - 0.5) / (height + 2 * pad)
    assert (y * sy + oy) * (height + 2 * margin) == pytest.approx(margin + height - 0.5)
    assert gd.resources.BehindTexture.screen(width, height, 0) == (1.0, 1.0, 0.0, 0.0)
    with pytest.raises(ValueError, match=r"colour \(H, W, 3\) and depth \(H, W\).*\(8, 8, 3\).*\(8, 9\)"):
        gd.resources.BehindTexture.from_image(np.zeros((8, 8, 3)), np.zeros((8, 9)))
