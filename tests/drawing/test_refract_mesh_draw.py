"""Solid glass leaving through its real mesh, drawn on the GPU (addon/gpu/glass_buffers.py,
glsl/tf_glass_exit.glsl ``tf_glass_exit``) against its numpy twin (precompute/shading/glass/refract.py
``mesh_exit``), per pixel.

A turned glass cube (flat faces: total internal reflection at its sides) over the scene-behind
texture of tests/drawing/test_refract_draw.py: its glass buffers are drawn on the GPU and checked against
the cube's exact faces, then the drawn colour against numpy's from the same buffers; the
glints (one reflection inside) see the scene behind where their ray meets it, as the refracted
ray does.
"""

import numpy as np
import pytest
from _extension import linked_extension
from _glass_mesh import Box
from test_gpu_draw import DISTANCE, FOV, PROJ, SIZE, VIEW, Item, world_sh
from test_refract_draw import as_solid_glass, glass_lighting, with_scene_mirror

from precompute.output import render
from precompute.shading import lamps, policy, split_sum, transmit
from precompute.shading.glass import glass_exit, refract, tails
from precompute.world.lamps import Lamps

pytestmark = pytest.mark.blender
assert linked_extension  # the fixture's module imports it

HALF = 0.7


def cube_arrays():
    """(positions (24, 3), flat outward normals, triangles (12, 3)) of a cube of half side HALF."""
    positions, normals, tris = [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = np.zeros(3)
            n[axis] = sign
            u, w = np.eye(3)[(axis + 1) % 3], np.eye(3)[(axis + 2) % 3]
            if sign < 0:
                u, w = w, u  # counter-clockwise seen from outside
            base = len(positions)
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                positions.append(HALF * (n + a * u + b * w))
                normals.append(n)
            tris += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return np.array(positions), np.array(normals), np.array(tris)


#: The second cube of the "pair" mesh, in object space: behind the first, partly hidden by it (one
#: object of two parts: a pixel may see a front face of each, as through a wine glass's bowl).
PAIR_OFFSET = np.array([0.5, 2.2, 0.3])


def smooth_arrays():
    """The cube shaded smooth: each corner's normal the mean of its three faces' (a box with
    Blender's *Shade Smooth*), so a face's shading normal leans up to 55° from its plane's."""
    positions, _normals, tris = cube_arrays()
    return positions, positions / np.linalg.norm(positions, axis=-1, keepdims=True), tris


def pair_arrays():
    """Two cubes in one mesh: the second PAIR_OFFSET away."""
    positions, normals, tris = cube_arrays()
    return (
        np.concatenate([positions, positions + PAIR_OFFSET]),
        np.concatenate([normals, normals]),
        np.concatenate([tris, tris + len(positions)]),
    )


def nearest_hits(model, rays, eye, shape):
    """(t_near, normal) of each pixel's nearest front face over the mesh's boxes."""
    boxes = [Box(model[:3, 3], [HALF] * 3, turn())]
    if shape == "pair":
        boxes.append(Box(model[:3, 3] + model[:3, :3] @ PAIR_OFFSET, [HALF] * 3, turn()))
    t_best = np.full(rays.shape[:2], np.inf)
    n_best = np.zeros(rays.shape)
    for box in boxes:
        t, _tf, n, _nf = box.hits(np.broadcast_to(eye, rays.shape), rays)
        nearer = t < t_best
        t_best = np.where(nearer, t, t_best)
        n_best = np.where(nearer[..., None], n, n_best)
    return t_best, n_best


def turn():
    c, s = np.cos(np.radians(35.0)), np.sin(np.radians(35.0))
    a = np.radians(20.0)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]) @ np.array(
        [[1.0, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]]
    )


def test_the_glass_buffers_hold_the_cubes_faces(gd):  # noqa: F811
    """The GPU's front and back buffers against the cube's exact faces (slab method) per pixel:
    the same pixels covered, normals equal where a pixel sees one face, depth to float32, and the
    geometric normals' buffer holding those faces' normals."""
    from thinfilm_sh.addon.gpu import glass_buffers

    model = np.eye(4)
    model[:3, :3] = turn()
    model[:3, 3] = (0.1, 0.2, -0.1)
    positions, normals, tris = cube_arrays()
    item = Item(gd.mesh.MeshBatch.from_arrays(positions, normals, tris), None, None, model)
    item.name, item.wall, item.film = "cube", (transmit.WALL_SOLID, 1.5), object()
    buffers = glass_buffers.render_glass_buffers([item], VIEW, PROJ, SIZE, SIZE)
    assert buffers.ids == {id(item): 0}
    rays = render.sphere_view(SIZE, SIZE, DISTANCE, FOV).rays
    eye, vd = np.array([0.0, -DISTANCE, 0.0]), np.array([0.0, -1.0, 0.0])
    box = Box(model[:3, 3], [HALF] * 3, turn())
    want_front, want_back = box.buffers(rays, eye, vd)
    assert buffers.front.shape == (policy.GLASS_LAYERS, SIZE, SIZE, 4)
    # a convex object has one span per pixel: its further layers are empty
    assert not np.any(buffers.front[1:]) and not np.any(buffers.back[1:])
    for name, got, want in (("front", buffers.front[0], want_front), ("back", buffers.back[0], want_back)):
        ids, n, depth = glass_exit.glass_texel(got)
        want_ids, want_n, want_depth = glass_exit.glass_texel(want)
        covered = (ids == 0) & (want_ids == 0)
        mismatch = np.mean((ids == 0) != (want_ids == 0))
        same_face = covered & (np.sum(n * want_n, -1) > 0.999)
        share = same_face.sum() / max(covered.sum(), 1)
        print(f"{name}: {covered.sum()} px, coverage mismatch {mismatch:.2%}, same face {share:.1%}")
        assert mismatch < 0.02  # the silhouette's edge pixels
        assert same_face.sum() > 0.95 * covered.sum()  # edges between faces
        assert np.max(np.abs(depth - want_depth)[same_face]) < 1e-4
        # the faces' geometric normals (a flat cube's are its faces' normals), outward on both sides
        geometric = glass_exit.geometric_texel(buffers.geom[0])[0 if name == "front" else 1]
        err = np.linalg.norm(geometric - want_n, axis=-1)[same_face]
        print(f"{name}: geometric normal error median {np.median(err):.1e}, max {err.max():.1e}")
        assert np.median(err) < 1e-5 and np.percentile(err, 99) < 1e-3


@pytest.mark.parametrize(
    ("colour_mode", "shape", "with_lamps"),
    [
        ("spectral", "cube", False),
        ("per_channel", "cube", False),
        ("spectral", "pair", False),
        ("per_channel", "smooth", False),
        ("spectral", "smooth", True),
    ],
)
def test_glass_leaving_through_its_mesh_draws_like_numpy(gd, colour_mode, shape, with_lamps, monkeypatch):
    """The refraction, the film from inside (spectral: the front film at the Snell-related angle;
    per channel: Cycles' back face, its table) and the glints through the mesh, per pixel; a mesh
    of two cubes, one behind the other, shows only its nearest front face (the far cube's faces
    seen through the near one are inside the glass's span, not drawn over it). With lamps: four
    World lamps a few degrees off the directions paths leave in, seen in the rough paths' tails
    (tails.lamp_tails) where the refracted ray and the glints see the World, and reflected by the
    film outside (shading.lamps.shade)."""
    from thinfilm_sh.addon.gpu import glass_buffers

    result, lighting, pre, film = glass_lighting(gd, colour_mode)
    model = np.eye(4)
    model[:3, :3] = turn()
    model[:3, 3] = (0.1, 0.2, -0.1)
    positions, normals, tris = {"cube": cube_arrays, "pair": pair_arrays, "smooth": smooth_arrays}[shape]()
    item = Item(gd.mesh.MeshBatch.from_arrays(positions, normals, tris), None, lighting, model)
    item.table = gd.resources.TableTexture.from_result(result)
    item.name = "cube"
    colour, depth, behind = as_solid_glass(gd, item, result, pre, film)
    buffers = glass_buffers.render_glass_buffers([item], VIEW, PROJ, SIZE, SIZE)
    behind.front, behind.back, behind.geom = buffers.textures()
    behind.ids = buffers.ids
    back_table = transmit.cycles_back_table(result.material)
    assert (back_table is None) == (colour_mode == "spectral")
    behind.film = glass_buffers.film_texture([back_table])

    rays = render.sphere_view(SIZE, SIZE, DISTANCE, FOV).rays
    eye = np.array([0.0, -DISTANCE, 0.0])
    t_near, n_near = nearest_hits(model, rays, eye, shape)
    ids, drawn_n, _d = glass_exit.glass_texel(buffers.front[0])
    inside = np.isfinite(t_near) & (ids == 0)
    points = eye + t_near[inside][:, None] * rays[inside]
    # the shading normal as the GPU interpolates it (the front buffer's); the face's own normal
    n, faces, views = drawn_n[inside], n_near[inside], -rays[inside]
    # the normal the draw shades solid glass with: Cycles' (glass_exit.valid_normal), the smooth
    # normal taken on the face's side
    n = glass_exit.valid_normal(faces, views, np.where(np.sum(n * faces, -1, keepdims=True) < 0.0, -n, n))
    if shape != "smooth":
        assert np.percentile(np.linalg.norm(n - faces, axis=-1), 95) < 1e-5
    inv_view = np.linalg.inv(VIEW)
    vp, cam, vd = PROJ @ VIEW, inv_view[:3, 3], inv_view[:3, 2]
    t, s = transmit.shade(film, n, views, transmit.WALL_SOLID, 1.5)
    centre = model[:3, 3]
    args = (buffers.front, buffers.back, vp, cam, vd)
    rules = {"geometric": buffers.geom, "entry_geometric": faces}
    exit_points, dirs, found, cosines, branches = glass_exit.mesh_exit(
        points, n, views, centre, 1.5, 0, *args, side=True, **rules
    )
    kept = ~np.isnan(cosines[:, 1])  # a path Cycles ends carries nothing
    hit, rows, cols = refract.march(exit_points, dirs, depth, vp, cam, vd, (1.0, 1.0, 0.0, 0.0))
    found_lamps = None
    if with_lamps:  # four lamps 4°–7° off the directions four paths that see the World leave in
        world_paths = np.flatnonzero(kept & found & ~hit)
        picks = dirs[world_paths[np.arange(1, 5) * len(world_paths) // 5]]
        off = np.cross(picks, [0.0, 0.0, 1.0])
        off /= np.linalg.norm(off, axis=-1, keepdims=True)
        angles = np.radians([4.0, 6.0, 5.0, 7.0])[:, None]
        power = np.array([[40.0, 30.0, 20.0], [20, 30, 40], [30, 30, 30], [40, 20, 30]])
        found_lamps = Lamps(np.cos(angles) * picks + np.sin(angles) * off, power)
        item.lighting = gd.resources.Lighting.from_sh(
            world_sh()[0], 8, result.material.roughness, found_lamps
        )
    image = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE, behind=behind)
    cos_o = np.sum(n * views, -1)

    def world(d, points_out, spread):  # the World along d, and the lamps in the path's tails
        return split_sum.lookup(pre, d, np.zeros(len(n))) + tails.lamp_tails(
            points, points_out, d, spread, result.material.roughness, found_lamps
        )

    spread = tails.path_spread(cos_o, np.nan_to_num(cosines[:, 1], nan=1.0), 1.5)
    seen = refract.seen(hit, rows, cols, colour, world(dirs, exit_points, spread), depth)
    with monkeypatch.context() as m:  # every ray that leaves the picture over a surface takes its edge
        m.setattr(refract, "_meets_ahead", lambda o, *_a: np.ones(len(o), bool))
        edge_hit, _r, _c = refract.march(exit_points, dirs, depth, vp, cam, vd, (1.0, 1.0, 0.0, 0.0))
    lerp = lamps.thickness_lerp(film, None, len(n))

    def back(c):
        return transmit.back_reflectance(film, lerp, c, 1.5, back_table)

    def crossed(entries):  # the film out and back in where the ray entered a further span
        factor = np.ones((len(n), 3))
        for c_out, c_in in entries.reshape(len(n), -1, 2).transpose(1, 2, 0):
            r_in = np.clip(transmit.white_reflectance(film, lerp, np.nan_to_num(c_in, nan=1.0)), 0.0, 1.0)
            step = (1.0 - back(np.nan_to_num(c_out, nan=1.0))) * (1.0 - r_in)
            factor *= np.where(np.isnan(c_out)[:, None], 1.0, step)
        return factor

    t_in = np.sqrt(t)
    # the glints: reflected back inside by the film at the first k faces the ray could leave
    # through (totally reflecting faces reflect on every path), out at the next, seeing the scene
    # where they meet it, else the World
    glint = np.zeros_like(seen)
    glint_hits = []
    for k in range(1, policy.GLASS_ORDERS + 1):
        g_points, g_dirs, g_found, g_cos = glass_exit.mesh_exit(
            points, n, views, centre, 1.5, 0, *args, reflections=k, **rules
        )
        g_hit, g_rows, g_cols = refract.march(g_points, g_dirs, depth, vp, cam, vd, (1.0, 1.0, 0.0, 0.0))
        g_spread = tails.path_spread(cos_o, np.nan_to_num(g_cos[:, 1], nan=1.0), 1.5, k)
        g_seen = refract.seen(g_hit, g_rows, g_cols, colour, world(g_dirs, g_points, g_spread), depth)
        chosen = g_cos[:, 2 : 2 + k]  # NaN where the path met no more faces to reflect at
        carried = crossed(g_cos[:, 2 + k :]) * np.prod(
            [np.where(np.isnan(c)[:, None], 1.0, back(np.nan_to_num(c, nan=1.0))) for c in chosen.T], axis=0
        )
        leaves = g_found & ~np.isnan(g_cos[:, 1])  # a path that never leaves carries nothing
        out = 1.0 - back(np.nan_to_num(g_cos[:, 1], nan=1.0))
        glint += np.where(leaves[:, None], carried * out * g_seen, 0.0)
        glint_hits.append(g_hit & g_found)
    glint *= t_in
    through = t_in * crossed(cosines[:, 2:]) * (1.0 - back(np.nan_to_num(cosines[:, 1], nan=1.0))) * seen
    through = np.where(kept[:, None], through, 0.0)

    # the film's mirror where the path first enters the far cube, and its reflection back inside
    # where the path leaves it: each followed back through the glass (glass_exit.branch_exit)
    def sees(q, d):
        q, d = np.nan_to_num(q), np.nan_to_num(d, nan=1.0)
        b_hit, b_rows, b_cols = refract.march(q, d, depth, vp, cam, vd, (1.0, 1.0, 0.0, 0.0))
        return refract.seen(b_hit, b_rows, b_cols, colour, split_sum.lookup(pre, d, np.zeros(len(n))), depth)

    def onward(cos):  # through the further spans the branch entered, then out through the film
        return crossed(cos[:, 2:]) * np.where(
            np.isnan(cos[:, 1:2]), 0.0, 1.0 - back(np.nan_to_num(cos[:, 1], nan=1.0))
        )

    mirrored = ~np.isnan(branches.mirror_point[:, 0])
    r_far = np.clip(transmit.white_reflectance(film, lerp, np.nan_to_num(cosines[:, 3], nan=1.0)), 0.0, 1.0)
    m_carried = t_in * (1.0 - back(np.nan_to_num(cosines[:, 2], nan=1.0))) * r_far
    m_q, m_d, m_followed, m_cos_entry, m_cos = glass_exit.branch_exit(
        branches.mirror_point, branches.mirror_dir, True, centre, 1.5, 0, *args, geometric=buffers.geom
    )
    m_met = ~np.isnan(m_cos_entry)
    r_in = np.clip(transmit.white_reflectance(film, lerp, np.nan_to_num(m_cos_entry, nan=1.0)), 0.0, 1.0)
    straight = ~m_met | ~m_followed  # meets the object no more (or its march no face): seen along itself
    m_seen = np.where(
        straight[:, None],
        sees(branches.mirror_point, branches.mirror_dir),
        (1.0 - r_in) * onward(m_cos) * sees(m_q, m_d),
    )
    side = np.where(mirrored[:, None], m_carried * m_seen, 0.0)
    inner = ~np.isnan(branches.inner_point[:, 0])
    i_carried = t_in * crossed(cosines[:, 2:]) * back(np.nan_to_num(cosines[:, 1], nan=1.0))
    i_q, i_d, i_followed, _c, i_cos = glass_exit.branch_exit(
        branches.inner_point, branches.inner_dir, False, centre, 1.5, 0, *args, geometric=buffers.geom
    )
    side += np.where((inner & i_followed)[:, None], i_carried * onward(i_cos) * sees(i_q, i_d), 0.0)
    through += side
    expected = s * split_sum.shade_split_sum(result, pre, n, views) + through
    if with_lamps:  # the film's reflection of the lamps outside, weighted as the split sum's levels
        lo, frac = split_sum.level_blend(
            policy.effective_roughness(result.material.roughness, cos_o), pre.roughness
        )
        lamp_w = lamps.lamp_weight(lo, frac, len(pre.levels))
        expected += s * lamp_w[:, None] * lamps.shade(film, found_lamps, result.material.roughness, n, views)
        tt_tails = tails.lamp_tails(points, exit_points, dirs, spread, result.material.roughness, found_lamps)
        shown = np.max(np.where((kept & found & ~hit)[:, None], tt_tails, 0.0)) / np.max(expected)
        print(f"lamps: the World's radiance in the refracted path's tails up to {shown:.2f} of the peak")
        assert shown > 0.05
    expected, _m_hit, _w = with_scene_mirror(
        expected + glint, (points, n, views), (colour, depth), pre, item.roughness, t
    )
    err = np.abs(image[inside][:, :3] - expected).max(axis=-1) / np.max(expected)
    print(
        f"cube: {inside.sum()} px, {found.mean():.0%} found their exit in the buffers, {hit.mean():.0%} hit"
        f" the scene behind; error median {np.median(err):.1e}, 95th percentile"
        f" {np.percentile(err, 95):.1e}, max {err.max():.1e} of the peak"
    )
    assert inside.sum() > 300 and found.mean() > 0.95
    # rays that leave the picture heading away from the wall see the World, not its edge
    assert (edge_hit & ~hit).sum() > (0.02 if shape == "smooth" else 0.05) * inside.sum()
    assert all(h.mean() > 0.05 for h in glint_hits[:2])  # glints that see the scene behind are exercised
    if shape == "smooth":  # Cycles' rules at the smooth faces are exercised: some paths end
        print(f"smooth: {1.0 - kept.mean():.0%} of the paths end as Cycles ends them")
        assert 0.01 < 1.0 - kept.mean() < 0.9
    if shape == "pair":  # the far cube shows beside the near one and behind it
        near_only, _n = nearest_hits(model, rays, eye, "cube")
        far = Box(model[:3, 3] + model[:3, :3] @ PAIR_OFFSET, [HALF] * 3, turn())
        far_t = far.hits(np.broadcast_to(eye, rays.shape), rays)[0]
        assert (inside & ~np.isfinite(near_only)).sum() > 100
        assert (np.isfinite(near_only) & np.isfinite(far_t)).sum() > 100  # seen through the near one
        # the rays that leave the near cube and enter the far one (its layer behind), and leave it
        entered = ~np.isnan(cosines[:, 2])
        both = (entered & kept).mean()
        print(f"pair: {entered.mean():.0%} of the paths enter the far cube, {both:.0%} leave it")
        assert mirrored.any() and not (mirrored & ~entered).any()
        assert inner.any() and not (inner & ~entered).any()
        print(
            f"pair: {inner.mean():.0%} of the paths reflect back inside the far cube,"
            f" {i_followed.mean():.0%} followed"
        )
        # the mirror branch is larger than the draw's tolerance where it is
        print(f"pair: the far cube's mirror up to {side.max() / np.max(expected):.1e} of the peak")
        assert np.percentile(side.max(-1)[mirrored], 50) / np.max(expected) > 1e-3
        assert both > 0.05
    if with_lamps:  # where the tails show, they agree (a few pixels over the whole would hide them)
        share = tt_tails.max(-1) / np.max(expected)
        tail_px = kept & found & ~hit & (share > 1e-4)
        of_tails = np.percentile(err[tail_px] / share[tail_px], 95)
        print(
            f"lamps: {tail_px.sum()} px show the tails, error 95th percentile {of_tails:.1e} of their tails"
        )
        assert tail_px.sum() > 20 and of_tails < 1e-2
    # float32 on the GPU may step to the neighbouring texel (a face's edge, a pattern's texel): a
    # few pixels differ, the rest agree to float32
    assert np.median(err) < 1e-4 and np.percentile(err, 95) < 2e-2
