"""The scene around solid glass (precompute/shading/glass/probe.py): six 90° views of a floor,
drawn exactly here, resampled to the probe's panorama; paths leaving near its point meet the
floor where a ray-plane intersection puts them."""

import numpy as np
import pytest

from precompute.shading.glass import probe

#: The floor lies this far below the probe's point; the views are FACE² texels.
HEIGHT = 1.0
FACE = 96
CENTRE = np.array([0.3, -0.2, 0.5])


def floor_colour(points):
    """A smooth colour over the floor (its pattern varies over about a unit)."""
    x, y = points[..., 0], points[..., 1]
    return np.stack([0.5 + 0.4 * np.sin(2.0 * x), 0.5 + 0.4 * np.cos(1.5 * y), 0.3 + 0.2 * np.sin(x + y)], -1)


def floor_views():
    """(colours (6, N, N, 3), depths along each view's axis) of the floor seen from CENTRE; the
    World (grey 0.05, no depth) above the horizon."""
    plane = probe.face_rays(FACE)
    local = np.concatenate([plane, -np.ones(plane.shape[:2] + (1,))], -1)  # camera space, z = −1
    colours, depths = [], []
    for m in probe.FACES:
        rays = local @ m.T  # world directions, unnormalised: the axis component is 1
        down = rays[..., 2] < 0.0
        t = np.where(down, HEIGHT / np.where(down, -rays[..., 2], 1.0), np.inf)  # along the axis
        hit = CENTRE + np.where(down, t, 0.0)[..., None] * rays
        colours.append(np.where(down[..., None], floor_colour(hit), 0.05))
        depths.append(t)
    return np.array(colours), np.array(depths)


@pytest.fixture(scope="module")
def floor_probe():
    colours, depths = floor_views()
    return probe.from_faces(colours, depths, 2 * FACE)


def test_the_probe_holds_the_floors_distance(floor_probe):
    from precompute.world import hdri

    rows = floor_probe.shape[0]
    dirs = hdri.equirect_directions(rows, 2 * rows)
    below = dirs[..., 2] < -0.2
    expected = HEIGHT / -dirs[..., 2][below]
    got = floor_probe[..., 3][below]
    # each texel's distance is its nearest view texel's: within that texel's spread of directions
    assert np.median(np.abs(got - expected) / expected) < 0.01
    assert np.all(floor_probe[..., 3][dirs[..., 2] > 0.02] == 0.0)  # above the horizon: the World


def test_paths_from_near_the_point_meet_the_floor_where_they_cross_it(floor_probe):
    from precompute.world import hdri

    rng = np.random.default_rng(5)
    count = 2000
    origins = CENTRE + rng.uniform(-0.35, 0.35, (count, 3))
    dirs = rng.normal(size=(count, 3))
    dirs[:, 2] = -np.abs(dirs[:, 2]) - 0.6  # heading down, at least 30° or so below the horizon
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    hits = origins + ((CENTRE[2] - HEIGHT - origins[:, 2]) / dirs[:, 2])[:, None] * dirs
    truth = floor_colour(hits)
    colour, seen = probe.lookup(floor_probe, CENTRE, origins, dirs)
    flat = hdri.equirect_lookup(floor_probe[..., :3], dirs)  # by direction alone
    assert seen.all()
    err = np.abs(colour - truth).max(-1)
    err_flat = np.abs(flat - truth).max(-1)
    print(f"probe: error median {np.median(err):.1e}, p95 {np.percentile(err, 95):.1e}")
    print(f"by direction alone: median {np.median(err_flat):.1e}")
    assert np.percentile(err, 95) < 0.02
    assert np.median(err) < 0.1 * np.median(err_flat)


def test_from_its_point_and_above_the_horizon(floor_probe):
    from precompute.world import hdri

    dirs = np.array([[0.3, 0.2, -0.9], [0.0, 0.6, -0.8], [0.5, 0.5, 0.7], [0.1, -0.3, 0.95]])
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    colour, seen = probe.lookup(floor_probe, CENTRE, np.tile(CENTRE, (4, 1)), dirs)
    assert seen.tolist() == [True, True, False, False]  # above the horizon: the caller's World
    assert np.allclose(colour[:2], hdri.equirect_lookup(floor_probe[..., :3], dirs[:2]))  # no parallax
    assert np.all(colour[2:] == 0.0)


def test_a_probe_needs_six_square_views():
    with pytest.raises(ValueError, match="six square views"):
        probe.from_faces(np.zeros((5, 8, 8, 3)), np.zeros((5, 8, 8)), 16)
    with pytest.raises(ValueError, match="six square views"):
        probe.from_faces(np.zeros((6, 8, 8, 3)), np.zeros((6, 8, 4)), 16)
