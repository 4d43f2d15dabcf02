"""A closed thin wall's reflections inside (precompute.shading.transmit: inside a bubble).

The path inside is checked against an independent ray–sphere intersection (the quadratic), the
reflections against energy in a white furnace (a lossless wall met at one angle lets out
T(1 + R + R²) = 1 − R³ of what its far side reflects), and the mesh analysis against meshes
whose answers are known (a closed sphere, an open hemisphere, a linear thickness).
"""

import numpy as np
import pytest

from precompute.colour import film_colour
from precompute.materials.material import Layer, Material
from precompute.shading import policy, transmit


def sphere_mesh(rings=12, segments=24, keep=None):
    """Per-corner positions and corner triangles of a UV sphere of radius 1 (every triangle's
    corners listed anew, as Blender's corners are); ``keep``: a filter on triangle centres."""
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)[:-1]
    grid = np.stack(
        [
            np.outer(np.sin(theta), np.cos(phi)),
            np.outer(np.sin(theta), np.sin(phi)),
            np.outer(np.cos(theta), 1 + 0 * phi),
        ],
        -1,
    )
    grid[0], grid[-1] = (0.0, 0.0, 1.0), (0.0, 0.0, -1.0)  # one point at each pole, as Blender's
    tris = []
    for i in range(rings):
        for j in range(segments):
            a, b = grid[i, j], grid[i, (j + 1) % segments]
            c, d = grid[i + 1, j], grid[i + 1, (j + 1) % segments]
            if i > 0:
                tris.append((a, c, b))
            if i < rings - 1:
                tris.append((b, c, d))
    tris = np.array(tris)
    if keep is not None:
        tris = tris[keep(tris.mean(axis=1))]
    return tris.reshape(-1, 3), np.arange(tris.shape[0] * 3).reshape(-1, 3)


def film(thickness_range=None, colour_mode="per_channel"):
    material = Material(
        layers=(Layer(1.33, 500.0),),
        substrate=1.0,
        roughness=0.0,
        thickness_range_nm=thickness_range,
        colour_mode=colour_mode,
    )
    return film_colour.film_table_of(material)


def far_wall(count=400, seed=5, centre=(0.0, 0.0, 0.0), radius=1.0):
    """Points on a sphere's far side seen from a camera on −y, with the normals facing it (inward)."""
    rng = np.random.default_rng(seed)
    cam = np.array([0.0, -4.0, 0.3])
    c = np.asarray(centre, dtype=float)
    rays = np.array([0.0, 1.0, 0.0]) + rng.uniform(-0.2, 0.2, (count, 3)) * np.array([1.0, 0.0, 1.0])
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    oc = cam - c
    b = rays @ oc
    disc = b * b - (oc @ oc - radius * radius)
    rays, b, disc = rays[disc > 0.05], b[disc > 0.05], disc[disc > 0.05]
    p = cam + (-b + np.sqrt(disc))[:, None] * rays
    return p, -(p - c) / radius, -rays


def test_the_path_follows_an_independent_ray_sphere_trace():
    centre = np.array([0.3, -0.2, 0.5])
    p, n, v = far_wall(centre=centre, radius=1.7)
    d = -v + 2.0 * np.sum(v * n, -1, keepdims=True) * n
    hits = transmit.inside_path(p, d, centre, orders=4)
    q, e = p, d
    for hit_p, hit_d, hit_cos in hits:
        oc = q - centre
        b = np.sum(e * oc, -1)
        t = -b + np.sqrt(b * b - (np.sum(oc * oc, -1) - 1.7**2))  # the far root of |q + t e − c| = ρ
        q = q + t[:, None] * e
        normal = (q - centre) / 1.7
        cos = np.sum(e * normal, -1)
        e = e - 2.0 * cos[:, None] * normal
        assert np.max(np.abs(hit_p - q)) < 1e-9 and np.max(np.abs(hit_d - e)) < 1e-9
        assert np.max(np.abs(hit_cos - cos)) < 1e-9
        # a sphere meets the ray at the far wall's angle at every hit
        assert np.max(np.abs(hit_cos - np.sum(v * n, -1))) < 1e-9


@pytest.mark.parametrize("mode", [transmit.WALL_CYCLES, transmit.WALL_SHEET])
def test_a_white_furnace_keeps_all_but_the_last_reflection(mode):
    """Constant thickness, radiance 1: T₂ + R₂T₃ + R₂R₃T₄ = 1 − R³ for a lossless wall (R + T = 1)."""
    f = film()
    p, n, v = far_wall()
    exit_t, extra = transmit.inside_reflections(
        f, p, n, v, np.zeros(3), None, mode, 1.0, None, lambda d: np.ones((len(d), 3))
    )
    cos = np.sum(v * n, -1)
    r = np.clip(transmit.white_reflectance(f, (np.zeros(len(p), int),) * 2 + (np.zeros(len(p)),), cos), 0, 1)
    t, s = transmit.wall(r, cos, mode, 1.0)
    big_r = s * r
    assert np.allclose(t + big_r, 1.0, atol=1e-9)  # lossless (η = 1: the sheet is the film alone)
    assert np.allclose(exit_t + extra, 1.0 - big_r ** (policy.INSIDE_ORDERS + 1), atol=1e-9)
    assert np.all(extra.sum(-1) > 0.0) and np.all(exit_t.sum(-1) < 3.0)
    # a tint absorbs at every pass: less comes out
    tinted_t, tinted_extra = transmit.inside_reflections(
        f,
        p,
        n,
        v,
        np.zeros(3),
        None,
        transmit.WALL_CYCLES,
        1.0,
        (0.8, 0.5, 0.2),
        lambda d: np.ones((len(d), 3)),
    )
    assert np.all(tinted_t + tinted_extra < exit_t + extra - 1e-3)


def test_each_hit_reads_its_own_thickness():
    """A thickness varying over the sphere: every hit's wall is the one at its point."""
    f = film((200.0, 900.0))
    p, n, v = far_wall()
    fit = np.array([0.5, 0.0, 0.0, 0.5])  # parameter (x + 1) / 2
    seen = []
    exit_t, extra = transmit.inside_reflections(
        f,
        p,
        n,
        v,
        np.zeros(3),
        fit,
        transmit.WALL_CYCLES,
        1.0,
        None,
        lambda d: seen.append(d) or np.ones((len(d), 3)),
    )
    hits = transmit.inside_path(p, -v + 2.0 * np.sum(v * n, -1, keepdims=True) * n, np.zeros(3))

    def wall(point, cos):
        rows = transmit.thickness_lerp(f, (point[:, 0] + 1.0) / 2.0, len(point))
        r = np.clip(transmit.white_reflectance(f, rows, cos), 0, 1)
        return 2 * r / (1 + r), (1 - r) / (1 + r)

    (r2, t2), (r3, t3), (_r4, t4) = (wall(q, c) for q, _d, c in hits)
    assert np.allclose(exit_t, t2, atol=1e-12)
    assert np.allclose(extra, r2 * t3 + r2 * r3 * t4, atol=1e-12)
    assert np.allclose(seen[0], hits[0][1]) and np.allclose(seen[1], hits[1][1])
    # a constant thickness (the middle) gives another answer: the thickness at the hits matters
    flat = transmit.inside_reflections(
        f,
        p,
        n,
        v,
        np.zeros(3),
        np.array([0.0, 0.0, 0.0, 0.5]),
        transmit.WALL_CYCLES,
        1.0,
        None,
        lambda d: np.ones((len(d), 3)),
    )
    assert np.max(np.abs(flat[1] - extra)) > 0.01


def test_a_near_wall_lets_its_reflection_leave():
    p, n, v = far_wall()
    near = -p  # the opposite points, normals outward there (towards a viewer on the other side)
    exit_t, extra = transmit.inside_reflections(
        film(),
        near,
        -n,
        v,
        np.zeros(3),
        None,
        transmit.WALL_CYCLES,
        1.0,
        None,
        lambda d: np.ones((len(d), 3)),
    )
    assert np.all(exit_t == 1.0) and np.all(extra == 0.0)


def test_mesh_inside_tells_closed_from_open_and_fits_a_linear_thickness():
    positions, tris = sphere_mesh()
    thickness = 0.2 + 0.3 * positions[:, 0] - 0.1 * positions[:, 2]
    inside = transmit.mesh_inside(positions, tris, thickness)
    assert inside.closed and inside.drawn and inside.explained > 1.0 - 1e-9
    assert np.allclose(inside.fit, (0.3, 0.0, -0.1, 0.2), atol=1e-6)
    hemisphere = transmit.mesh_inside(*sphere_mesh(keep=lambda c: c[:, 2] > 0.0))
    assert not hemisphere.closed and hemisphere.fit == (0.0, 0.0, 0.0, 0.0)
    assert not transmit.mesh_inside(np.zeros((0, 3)), np.zeros((0, 3), int)).closed
    # a fin on one of the sphere's edges: that edge is shared by three triangles, not closed
    fin = np.concatenate([positions, positions[tris[0, :2]], [[0.0, 0.0, 3.0]]])
    n = len(positions)
    assert not transmit.mesh_inside(fin, np.concatenate([tris, [[n, n + 1, n + 2]]])).closed
    # a NaN-free constant thickness fits its value; too few values fall back to their mean
    assert np.allclose(
        transmit.mesh_inside(positions, tris, np.full(len(positions), 0.4)).fit, (0, 0, 0, 0.4), atol=1e-9
    )


def test_world_fit_moves_with_the_object():
    rng = np.random.default_rng(2)
    fit = np.array([0.3, -0.2, 0.1, 0.45])
    a = rng.normal(size=(3, 3)) + 2.0 * np.eye(3)
    model = np.eye(4)
    model[:3, :3], model[:3, 3] = a, (1.0, -2.0, 0.5)
    local = rng.normal(size=(50, 3))
    world = local @ a.T + model[:3, 3]
    w = transmit.world_fit(fit, model)
    assert np.allclose(world @ w[:3] + w[3], local @ fit[:3] + fit[3], atol=1e-12)


def test_a_noise_thickness_is_not_drawn_inside():
    """A thickness the linear fit cannot follow (a noise) leaves the reflections inside out: the
    other hits' thickness is not known (Inside.drawn)."""
    positions, tris = sphere_mesh()
    rng = np.random.default_rng(4)
    welded = np.unique(positions.round(6), axis=0, return_inverse=True)[1].reshape(-1)
    noise = rng.uniform(0.0, 1.0, welded.max() + 1)[welded]  # one value per vertex, as a noise
    inside = transmit.mesh_inside(positions, tris, noise)
    assert inside.closed and inside.explained < 0.1 and not inside.drawn
    # a gradient under a little noise is still followed
    ramp = transmit.mesh_inside(positions, tris, 0.5 + 0.4 * positions[:, 0] + 0.05 * (noise - 0.5))
    assert ramp.drawn and ramp.explained > 0.9
