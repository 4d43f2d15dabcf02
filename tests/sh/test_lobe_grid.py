"""The integrated outgoing-radiance grid (precompute/shading/lobe_grid.py).

- each node is the single-scattering integral of the exact film lobe against the World: the
  brute-force ground truth (render.shade_reference, its own film matrices and quadrature) at
  the node's (n, v), on a smooth World;
- a uniform World gives the film's directional albedo × the multiple-scattering factor at every
  mirror cell and azimuth;
- a turned World (rotation Q, strength) equals the grid of the same World drawn in place;
- the policy: which films integrate their grid, and its weight against the split sum.
"""

from __future__ import annotations

import numpy as np
import pytest

from precompute.bakes import bake
from precompute.colour import film_colour
from precompute.materials.material import Layer, Material, Quality
from precompute.output import render
from precompute.shading import lobe_grid, policy, radiance_grid
from precompute.world import hdri

#: A small grid: (W, H, T, Ψ) with a few view angles, and a coarse quadrature (fast tests).
SHAPE = (16, 8, 4, 8)
SAMPLES = (24, 24)

_FILMS: dict = {}


def film_of(roughness: float = 0.3, multiscatter: str = "none", colour_mode: str = "per_channel"):
    key = (roughness, multiscatter, colour_mode)
    if key not in _FILMS:
        material = Material(
            layers=(Layer(1.33, 800.0),),
            substrate=1.5,
            roughness=roughness,
            colour_mode=colour_mode,
            multiscatter=multiscatter,
            quality=Quality(sh_order=2, view_samples=4, wavelength_count=48),
        )
        result = bake.bake(material)
        _FILMS[key] = (material, film_colour.film_table(result))
    return _FILMS[key]


def smooth_world(height: int = 64) -> np.ndarray:
    """A smooth, coloured World (low-order in direction), so bilinear lookups are exact enough."""
    d = hdri.equirect_directions(height, 2 * height)
    return np.stack([1.0 + 0.8 * d[..., 2], 1.0 + 0.6 * d[..., 0], 1.2 + 0.5 * d[..., 1] * d[..., 2]], -1)


def node_geometry(shape, layer: int, row: int, column: int):
    """(n, v) of the grid node (layer j·Ψ + k, row h, column i)."""
    n, v = radiance_grid.cell_geometry(shape)  # (T, Ψ, H, W, 3)
    j, k = divmod(layer, shape[3])
    return n[j, k, row, column], v[j, k, row, column]


def test_nodes_are_the_brute_force_integral():
    material, film = film_of()
    world = smooth_world()
    grid = lobe_grid.build(film, material.roughness, world, SHAPE, samples=SAMPLES)
    assert grid.shape == (SHAPE[2] * SHAPE[3], SHAPE[1], SHAPE[0], 3) and grid.dtype == np.float32
    rng = np.random.default_rng(7)
    for _ in range(6):
        layer = int(rng.integers(0, grid.shape[0] - SHAPE[3]))  # θo < 90°
        row, column = int(rng.integers(0, SHAPE[1])), int(rng.integers(0, SHAPE[0]))
        n, v = node_geometry(SHAPE, layer, row, column)
        truth = render.shade_reference(material, world, n[None], v[None], n_theta=96, n_phi=96)[0]
        np.testing.assert_allclose(grid[layer, row, column], truth, rtol=0.02, atol=1e-4)


def test_a_uniform_world_gives_the_albedo_times_multiscatter():
    material, film = film_of(multiscatter="cycles")
    colour = np.array([0.5, 1.0, 2.0])
    world = np.broadcast_to(colour, (32, 64, 3))
    grid = lobe_grid.build(film, material.roughness, world, SHAPE, samples=SAMPLES)
    rows = (np.zeros(1, int), np.zeros(1, int), np.zeros(1))
    for j, theta in enumerate(radiance_grid.view_angles(SHAPE[2])[:-1]):
        wi, weight, u = lobe_grid.node_samples(material.roughness, float(theta), SAMPLES)
        zeros = np.zeros(u.size, int)
        albedo = weight @ lobe_grid.film_at(film, film.reflectance, (zeros, zeros, np.zeros(u.size)), u)
        ms = lobe_grid.film_at(film, film.multiscatter, rows, np.array([np.cos(theta)]))[0]
        layers = grid[j * SHAPE[3] : (j + 1) * SHAPE[3]]
        np.testing.assert_allclose(layers, np.broadcast_to(albedo * ms * colour, layers.shape), rtol=1e-4)
        assert np.all(ms > 1.0) and np.all(albedo > 0.0) and np.all(albedo < 1.0)


def test_a_turned_world_equals_the_world_drawn_in_place():
    material, film = film_of()
    angle = 0.7
    q = np.array([[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0], [0.0, 0.0, 1.0]])
    d = hdri.equirect_directions(64, 128)

    def field(x):
        return np.stack([1.0 + 0.8 * x[..., 0], 1.0 + 0.6 * x[..., 1], 1.0 + 0.4 * x[..., 2]], -1)

    world = field(d)  # the World in place
    content = field(d @ q)  # content direction e = Q d: the content at e shows the World at Qᵀ e
    placed = lobe_grid.build(film, material.roughness, world, SHAPE, samples=(12, 12))
    turned = lobe_grid.build(
        film, material.roughness, content, SHAPE, rotation=q, scale=2.0, samples=(12, 12)
    )
    np.testing.assert_allclose(turned, 2.0 * placed, rtol=0.01, atol=1e-4)


def test_a_bad_panorama_is_refused():
    material, film = film_of()
    with pytest.raises(ValueError, match="panorama"):
        lobe_grid.build(film, material.roughness, np.ones((8, 16)), SHAPE)


def test_which_films_integrate_their_grid_and_its_weight():
    lo, hi = policy.SH_BLEND
    assert not policy.uses_lobe_grid(lo) and not policy.uses_lobe_grid(hi)
    assert policy.uses_lobe_grid(0.3)
    # a diffuse base or a transparent wall: the table holds more than the lobe, the SH grid stays
    assert not policy.uses_lobe_grid(0.3, diffuse_base=True) and not policy.uses_lobe_grid(0.3, wall=True)
    assert policy.grid_weight(0.6, False) == policy.sh_weight(0.6) == 1.0
    assert policy.grid_weight(policy.LOBE_GRID_RAMP[1], True) == pytest.approx(policy.LOBE_GRID_WEIGHT)
    ramp = [policy.grid_weight(r, True) for r in np.linspace(lo, policy.LOBE_GRID_RAMP[1], 9)]
    assert ramp[0] == 0.0 and np.all(np.diff(ramp) > 0.0)


def test_a_content_grid_read_through_the_worlds_turn_is_the_turned_worlds_grid():
    """The viewport builds the grid of the World's *content* (no turn, strength 1) and the shader
    turns and scales its lookup (radiance_grid.lookup's rotation and scale, the lighting buffer's
    world block): at the nodes of a World turned about z by whole cells and scaled, that equals
    the grid built for the turned World in place (every node maps onto a content node)."""
    material, film = film_of()
    world = smooth_world()
    w = SHAPE[0]
    angle = 2.0 * (2.0 * np.pi / w)  # two mirror cells
    q = np.array([[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0], [0.0, 0.0, 1.0]])
    content = lobe_grid.build(film, material.roughness, world, SHAPE, samples=SAMPLES)
    turned = lobe_grid.build(film, material.roughness, world, SHAPE, rotation=q, scale=1.7, samples=SAMPLES)
    n, v = radiance_grid.cell_geometry(SHAPE)  # the turned World's nodes, (T, Ψ, H, W, 3)
    n, v = n[1:-1], v[1:-1]  # θo strictly inside (0, 90°): a unique view-aligned frame
    got = radiance_grid.lookup(content, n, v, azimuths=SHAPE[3], rotation=q, scale=1.7)
    expected = turned.reshape(SHAPE[2], SHAPE[3], SHAPE[1], SHAPE[0], 3)[1:-1]
    peak = float(np.abs(expected).max())
    assert peak > 0.05
    assert np.abs(got - expected).max() / peak < 1e-4
    unturned = radiance_grid.lookup(content, n, v, azimuths=SHAPE[3], scale=1.7)
    assert np.abs(unturned - expected).max() / peak > 1e-2  # the turn matters


# ----------------------------------------------------------------------------------------------
# A varying film's film-free basis grid
# ----------------------------------------------------------------------------------------------
#: A basis grid's shape: W ≥ T (its hat ranges sit in one row), Ψ as the small grids'.
BASIS_SHAPE = (16, 8, 6, 8)


def test_the_hats_over_u_sum_to_one():
    u = np.linspace(0.0, 1.0, 1001)
    weights = lobe_grid.hat_weights(u)
    assert weights.shape == (policy.GRID_HATS, u.size) and np.all(weights >= 0.0)
    np.testing.assert_allclose(weights.sum(axis=0), 1.0, atol=1e-12)
    nodes = np.arange(policy.GRID_HATS) / (policy.GRID_HATS - 1)
    np.testing.assert_allclose(lobe_grid.hat_weights(nodes), np.eye(policy.GRID_HATS), atol=1e-12)


@pytest.mark.parametrize("roughness", [0.3, 0.4])
def test_the_basis_grid_read_with_a_film_is_that_films_lobe_grid(roughness):
    """The basis holds the lobe with the film's reflectance linear in u between GRID_HATS nodes:
    read with any film it is that film's own integrated grid (lobe_grid.build) but for that
    interpolation, largest at grazing views, where a film's colour changes fastest across the
    wide lobe. Two films of the same roughness read one basis."""
    world = smooth_world()
    basis = lobe_grid.build_basis(roughness, world, BASIS_SHAPE, samples=SAMPLES)
    p = BASIS_SHAPE[3]
    assert basis.shape == (
        (BASIS_SHAPE[2] + 1) * p,
        BASIS_SHAPE[1],
        policy.GRID_HATS * (BASIS_SHAPE[0] + 2),
        3,
    )
    n, v = random_pixels(3000, seed=4)
    cos = np.sum(n * v, axis=-1)
    for nm in (300.0, 800.0):
        material = Material(
            layers=(Layer(1.33, nm),),
            substrate=1.5,
            roughness=roughness,
            colour_mode="per_channel",
            quality=Quality(sh_order=2, view_samples=4, wavelength_count=48),
        )
        film = film_colour.film_table(bake.bake(material))
        exact = radiance_grid.lookup(
            lobe_grid.build(film, roughness, world, BASIS_SHAPE, samples=SAMPLES), n, v, azimuths=p
        )
        rows = (np.zeros(n.shape[0], int), np.zeros(n.shape[0], int), np.zeros(n.shape[0]))
        got = lobe_grid.lookup_basis(basis, n, v, film, rows, p)
        err = np.max(np.abs(got - exact), axis=-1) / np.max(exact)
        # Measured (16 hats): median 0.16–0.22 % of the peak, 0.26–0.43 % above cos θo 0.4, the
        # most 1.6–2.0 % (grazing); 12 hats about double it, one film colour across the lobe is
        # 5–30 % at grazing.
        assert np.median(err) < 0.01 and np.max(err[cos > 0.4]) < 0.02 and np.max(err) < 0.06, (
            np.median(err),
            np.max(err),
        )


def random_pixels(count: int, seed: int):
    rng = np.random.default_rng(seed)
    n = rng.normal(size=(count, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    v = rng.normal(size=(count, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return n, np.where((np.sum(n * v, axis=-1) < 0.0)[:, None], -v, v)
