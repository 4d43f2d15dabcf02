"""The outgoing-radiance grid (precompute/shading/radiance_grid.py, glsl/tf_radiance_grid.glsl).

- its nodes are the per-pixel SH sum (shading.sh_sum.shade_sh) at their (n, v);
- between the nodes it stays close to the per-pixel SH in colour (ΔE2000, with the bound's why);
- the GLSL reads the same values as the numpy twin, per pixel and through the draw path;
- the variant rules (policy.uses_grid, variant.choose_variant) and the compiled source (no
  generated SH code in a grid variant).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_gpu_draw import (
    PROJ,
    QUAD_NOR,
    QUAD_POS,
    QUAD_TRIS,
    SIZE,
    TEST_VERTEX,
    VIEW,
    baked,
    quad_local,
    quad_pixels,
    tilted_quad_item,
    unit,
    world_sh,
)

from precompute.bakes import bake
from precompute.colour.colour_difference import delta_e_2000
from precompute.materials.material import Layer, Material, Quality
from precompute.shading import codegen, policy, radiance_grid, sh_sum
from precompute.shading.variant import Variant, choose_variant

_GRIDS: dict = {}
_TABLES: dict = {}


def rough_table(roughness: float, colour_mode: str = "spectral") -> bake.BakeResult:
    """A constant-thickness film at l_max 12 (the automatic order for roughness 0.2–0.7)."""
    key = (roughness, colour_mode)
    if key not in _TABLES:
        material = Material(
            layers=(Layer(1.33, 380.0),),
            substrate=1.5,
            roughness=roughness,
            colour_mode=colour_mode,
            quality=Quality(sh_order=12, view_samples=16, wavelength_count=48),
        )
        _TABLES[key] = bake.bake(material)
    return _TABLES[key]


def windowed_world(result) -> np.ndarray:
    """The test World's SH windowed as the lighting buffer holds it (policy.lighting_window)."""
    world, _img = world_sh(result.sh_order)
    window = policy.lighting_window(result.sh_order, result.material.roughness)
    return world[: (result.sh_order + 1) ** 2] * window[:, None]


def grid_of(result) -> np.ndarray:
    key = id(result)
    if key not in _GRIDS:
        _GRIDS[key] = radiance_grid.build(result, windowed_world(result))
    return _GRIDS[key]


def random_pixels(count: int, seed: int):
    """Unit normals and front-facing unit views (float32-representable)."""
    rng = np.random.default_rng(seed)
    n = unit(rng.normal(size=(count, 3)))
    v = unit(rng.normal(size=(count, 3)))
    v = np.where(np.sum(n * v, -1, keepdims=True) < 0, -v, v)
    return unit(n.astype(np.float32)), unit(v.astype(np.float32))


# ----------------------------------------------------------------------------------------------
# numpy: the nodes, the accuracy between them
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("colour_mode", ["spectral", "per_channel"])
def test_grid_nodes_are_the_per_pixel_sh_sum(colour_mode):
    """Each node of build() equals shade_sh at the node's (n, v) (cell_geometry): the
    factorisation frame = Ry(θo)ᵀ Gᵀ and the folded table are exact, not an approximation."""
    result = rough_table(0.3, colour_mode)
    grid = grid_of(result)
    w, h, t, p = policy.grid_shape(result.data.shape[1])
    assert t == 16 and grid.shape == (t * p, h, w, 3) and grid.dtype == np.float32
    n, v = radiance_grid.cell_geometry((w, h, t, p))
    sel = (slice(None, None, 2), slice(None, None, 5), slice(None, None, 3), slice(None, None, 7))
    expected = sh_sum.shade_sh(result, windowed_world(result), n[sel], v[sel])
    got = grid.reshape(t, p, h, w, 3)[sel]
    scale = np.abs(expected).max()
    assert scale > 0.05
    # float32 storage: 6e-8 of the peak; a wrong rotation or table angle errs by ≥ 1e-2.
    assert np.abs(got - expected).max() / scale < 1e-6
    # and the lookup at a node returns the node (interpolation weights 0 or 1)
    looked = radiance_grid.lookup(grid, n[sel], v[sel])
    assert np.abs(looked - got).max() / scale < 1e-5


def test_the_view_geometry_of_a_cell_is_its_frame():
    """cell_geometry's (n, v) have the view-aligned frame Ry(θo)ᵀ Gᵀ (mirror_frames) and the
    mirror direction of the cell: r = 2 (n·v) n − v."""
    from precompute.shading.frame import view_aligned_frame

    shape = (8, 4, 5, 6)
    n, v = radiance_grid.cell_geometry(shape)
    g = np.moveaxis(radiance_grid.mirror_frames(shape), 2, 0)[None]  # (1, Ψ, H, W, 3, 3)
    r = g[..., 2, :]
    mirror = 2 * np.sum(n * v, -1, keepdims=True) * n - v
    assert np.allclose(mirror, np.broadcast_to(r, mirror.shape), atol=1e-12)
    theta = radiance_grid.view_angles(5)[1:-1, None, None, None, None]  # θo = 0: any tangent
    frames = view_aligned_frame(n[1:-1], v[1:-1])
    e1 = g[..., 0, :]
    assert np.allclose(frames[..., 0, :], np.cos(theta) * e1 - np.sin(theta) * r, atol=1e-12)
    assert np.allclose(frames[..., 1, :], np.broadcast_to(g[..., 1, :], frames[..., 1, :].shape), atol=1e-12)
    u, t, tp, pp = radiance_grid.coordinates(n[1:-1], v[1:-1], shape)
    k = np.arange(6)[None, :, None, None]
    i = np.arange(8)[None, None, None, :]
    assert np.allclose(u, np.broadcast_to((i + 0.5) / 8, u.shape), atol=1e-9)
    assert np.allclose(tp, np.broadcast_to(np.arange(1, 4)[:, None, None, None], tp.shape), atol=1e-9)
    wrapped = np.minimum(np.abs(pp - k), 6 - np.abs(pp - k))
    assert wrapped.max() < 1e-6


@pytest.mark.parametrize("roughness", [0.3, 0.6])
def test_grid_stays_close_to_the_per_pixel_sh_in_colour(roughness):
    """The interpolated grid against the per-pixel l = 12 SH at 20 000 random (n, v).

    Measured (policy.grid_shape, 16 view angles): mean ΔE2000 0.12 / 0.11, p95 0.46 / 0.38 at
    roughness 0.3 / 0.6 (docs/tuning.md#radiance-grid). Bounds: mean ≤ 0.3 and p95 ≤ 1 — well
    below the product's own distance to Cycles (mean 0.4–2.6) and one just-noticeable
    difference; half the view azimuths or θo nodes off the table's exceed the mean bound.
    """
    result = rough_table(roughness)
    grid = grid_of(result)
    n, v = random_pixels(20000, seed=int(roughness * 10))
    reference = sh_sum.shade_sh(result, windowed_world(result), n, v)
    got = radiance_grid.lookup(grid, n, v)
    de = delta_e_2000(got, reference)
    mean, p95 = float(de.mean()), float(np.percentile(de, 95))
    print(f"\nroughness {roughness}: ΔE2000 mean {mean:.3f} p95 {p95:.3f} max {de.max():.3f}")
    assert mean <= 0.3 and p95 <= 1.0, (mean, p95)
    # the comparison can fail: θo nodes between the table's (8 for its 16) and half the azimuths
    coarse_shape = (48, 24, 8, 16)
    coarse = radiance_grid.build(result, windowed_world(result), coarse_shape)
    worse = delta_e_2000(radiance_grid.lookup(coarse, n, v, 16), reference)
    assert worse.mean() > 0.3, worse.mean()


def turn(angle: float, axis) -> np.ndarray:
    """A rotation matrix (Rodrigues) of ``angle`` about ``axis``."""
    k = unit(np.asarray(axis, dtype=float))
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross


def test_a_turned_and_scaled_world_reads_the_content_grid():
    """The grid of the World's content, looked up at (Q n, Q v) and scaled by s, is the World
    L(d) = s · L_c(Q d) (the lighting buffer's turn and strength): at the content grid's nodes
    exactly the per-pixel SH of the turned World's own coefficients (sh.rotate), so a Strength
    or rotation edit needs no new grid."""
    from precompute.sh import rotations

    result = rough_table(0.3)
    content = windowed_world(result)
    q, s = turn(1.1, [0.3, -0.5, 0.8]), 2.5
    world = s * rotations.rotate(content, q.T)  # coefficients of d ↦ s L_c(Q d)
    grid = grid_of(result)  # built from the content
    shape = policy.grid_shape(result.data.shape[1])
    n, v = radiance_grid.cell_geometry(shape)  # nodes, in the content's frame
    sel = (slice(1, None, 3), slice(None, None, 5), slice(None, None, 3), slice(None, None, 7))
    n_w, v_w = n[sel] @ q, v[sel] @ q  # the same nodes in the World's frame: Q n_w = n
    expected = sh_sum.shade_sh(result, world, n_w, v_w)
    got = radiance_grid.lookup(grid, n_w, v_w, rotation=q, scale=s)
    peak = np.abs(expected).max()
    assert peak > 0.05
    # float32 storage and the node coordinates recomputed after the turn: measured 3e-8 of the
    # peak; a transposed Q (the inverse turn) errs by 0.54, a missing scale by 0.6
    assert np.abs(got - expected).max() / peak < 1e-5
    wrong = radiance_grid.lookup(grid, n_w, v_w, rotation=q.T, scale=s)
    assert np.abs(wrong - expected).max() / peak > 1e-2


def test_build_refuses_bad_input():
    """The radiance grid refuses World coefficients, grid shapes and lookups of the wrong shape with the
    argument named, not a numpy broadcast error."""
    result = rough_table(0.3)
    with pytest.raises(ValueError, match="world_coeffs"):
        radiance_grid.build(result, np.zeros((4, 3)))
    with pytest.raises(ValueError, match="grid shape"):
        radiance_grid.build(result, windowed_world(result), (64, 32, 1, 24))
    with pytest.raises(ValueError, match="a grid is"):
        radiance_grid.lookup(np.zeros((33, 4, 8, 3)), [[0.0, 0.0, 1.0]], [[0.0, 0.0, 1.0]])


# ----------------------------------------------------------------------------------------------
# Variant rules
# ----------------------------------------------------------------------------------------------
def test_grid_variant_rules():
    """The shader reads the radiance grid only where it is valid: constant thickness with an SH half; split-
    sum-only and low-order films are drawn per pixel; a varying thickness only in the hand-over
    (its basis grid, read with the film table), else per pixel."""
    base = dict(l_max=12, spectral=True, thickness_rows=1, has_thickness=False, display=False)
    # a rough film (SH alone) and a medium one (split + SH) with a grid read it
    assert choose_variant(**base, prefiltered=False, sh_weight=1.0, grid=True).grid
    assert choose_variant(**base, prefiltered=True, sh_weight=0.5, grid=True).grid
    # no SH half (split only), no grid, a varying thickness, a low order: per pixel
    assert not choose_variant(**base, prefiltered=True, sh_weight=0.0, grid=True).grid
    assert not choose_variant(**base, prefiltered=False, sh_weight=1.0).grid
    vary = dict(base, thickness_rows=8, has_thickness=True)
    assert not choose_variant(**vary, prefiltered=False, sh_weight=1.0, grid=True).grid
    assert not choose_variant(**vary, prefiltered=True, sh_weight=0.5, grid=True).grid  # no film table
    basis = choose_variant(**vary, prefiltered=True, sh_weight=0.5, grid=True, film=True)
    assert basis.grid and basis.film and basis.normalised() == basis
    low = dict(base, l_max=policy.GRID_MIN_L - 1)
    assert not choose_variant(**low, prefiltered=False, sh_weight=1.0, grid=True).grid
    # the weight counts only where the split sum runs: without a prefilter SH is drawn alone
    assert choose_variant(**base, prefiltered=False, sh_weight=0.0, grid=True).grid
    v = choose_variant(**base, prefiltered=False, sh_weight=1.0, grid=True)
    assert ("TF_RADIANCE_GRID", "1") in v.switches()
    assert v.normalised() == v


# ----------------------------------------------------------------------------------------------
# GLSL against numpy
# ----------------------------------------------------------------------------------------------
GRID_FRAGMENT = """
void main()
{
  ivec2 p = ivec2(gl_FragCoord.xy);
  vec3 n = normalize(texelFetch(tf_test_normal, p, 0).xyz);
  vec3 v = normalize(texelFetch(tf_test_view, p, 0).xyz);
  tf_frag_color = vec4(tf_shade_grid(tf_view_aligned_frame(n, v)), 1.0);
}
"""


def grid_on_gpu(gd, gpu, texture, variant, normals, views, width: int, turn_=None, scale=1.0):
    """tf_shade_grid per pixel, inputs from two RGBA32F textures: RGB (N, 3); ``turn_`` and
    ``scale``: the lighting buffer's World turn Q and strength."""
    count = normals.shape[0]
    height = count // width
    info = gpu.types.GPUShaderCreateInfo()
    gd.shaders.declare_shading_resources(info, variant)
    info.sampler(1, "FLOAT_2D", "tf_test_normal")
    info.sampler(2, "FLOAT_2D", "tf_test_view")
    info.vertex_in(0, "VEC2", "pos")
    info.fragment_out(0, "VEC4", "tf_frag_color")
    info.vertex_source(TEST_VERTEX)
    library = gd.shaders.shading_library(variant.l_max, grid=True)
    assert codegen.banded_source(variant.l_max) not in library  # the slow-to-compile part
    assert codegen.banded_source(variant.l_max) in gd.shaders.shading_library(variant.l_max)
    info.fragment_source(library + GRID_FRAGMENT)
    shader = gpu.shader.create_from_info(info)

    def tex(rgb):
        data = np.zeros((height, width, 4), dtype=np.float32)
        data[..., :3] = rgb.reshape(height, width, 3)
        return gpu.types.GPUTexture((width, height), format="RGBA32F", data=gd.resources.float_buffer(data))

    tex_n, tex_v = tex(normals), tex(views)
    lighting = gd.resources.Lighting.from_sh(np.zeros((1, 3)), 0, 0.3, rotation=turn_, scale=scale)
    offscreen = gpu.types.GPUOffScreen(width, height, format="RGBA32F")
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            shader.bind()
            shader.uniform_sampler("tf_radiance_grid", texture.texture)
            shader.uniform_block("tf_lighting", lighting.ubo)
            shader.uniform_sampler("tf_test_normal", tex_n)
            shader.uniform_sampler("tf_test_view", tex_v)
            gd.draw._fullscreen_triangle().draw(shader)
            out = gd.draw.read_framebuffer(fb, width, height)
    finally:
        offscreen.free()
    return out[::-1].reshape(count, 4)[:, :3]


def half(grid) -> np.ndarray:
    """The grid as the RGBA16F texture stores it."""
    return np.asarray(grid, dtype=np.float16).astype(np.float64)


@pytest.mark.blender
@pytest.mark.parametrize(
    "colour_mode, turned", [("spectral", False), ("per_channel", False), ("spectral", True)]
)
def test_glsl_grid_lookup_matches_numpy_per_pixel(gd, colour_mode, turned):
    """tf_shade_grid against radiance_grid.lookup of the half-float grid, per pixel (``turned``:
    under a World turn and strength from the lighting buffer)."""
    import gpu

    result = rough_table(0.3, colour_mode)
    grid = grid_of(result)
    texture = gd.resources.RadianceGridTexture.from_grid(grid)
    variant = Variant(12, colour_mode == "spectral", False, False, grid=True)
    width = 64
    n, v = random_pixels(width * 32, seed=5)
    z = np.array([0.0, 0.0, 1.0])  # special views: normal incidence, grazing, the mirror at a pole
    n[:6] = [z, z, unit([1, 0, 0]), unit([0.3, -0.2, 0.9]), unit([0, 1, 1]), unit([1, 1, 0])]
    v[:6] = [
        unit([0.2, 0.1, 1.0]),
        unit([1, 0, 0.01]),
        unit([1, 0, 0]),
        unit([0.3, -0.2, 0.9]),
        unit([0, 1, 1.5]),
        unit([1, 1.0, 0.0]),
    ]
    q, s = (turn(2.0, [-0.4, 0.7, 0.2]), 1.7) if turned else (None, 1.0)
    got = grid_on_gpu(gd, gpu, texture, variant, n, v, width, q, s)
    expected = radiance_grid.lookup(half(grid), n, v, rotation=q, scale=s)
    if turned:  # it did turn and scale
        assert np.abs(expected - radiance_grid.lookup(half(grid), n, v)).max() > 0.05 * np.abs(expected).max()
    scale = np.abs(expected).max()
    assert scale > 0.05 and np.all(np.isfinite(got))
    err = np.max(np.abs(got - expected), axis=-1) / scale
    print(f"\n{colour_mode}: GLSL vs numpy max {err.max():.2e} median {np.median(err):.2e}")
    # float32 coordinates and llvmpipe's bilinear weights against float64: measured max 2e-5.
    # A swapped axis, a wrong azimuth origin or an off-by-half texel errs by ≥ 1e-2.
    assert err.max() < 1e-3 and np.median(err) < 1e-5


@pytest.mark.blender
def test_grid_variant_draws_the_grid_through_the_draw_path(gd):
    """A tilted quad drawn by draw_items with a grid: the grid variant is chosen, the sampler is
    bound, and the pixels are radiance_grid.lookup — close to the per-pixel SH drawn without it."""
    result = rough_table(0.6)
    grid = grid_of(result)
    table = gd.resources.TableTexture.from_result(result)
    world, _img = world_sh(12)
    lighting = gd.resources.Lighting.from_sh(world, 12, result.material.roughness)
    assert np.allclose(lighting.coefficients, windowed_world(result))
    item = tilted_quad_item(gd, table, lighting)
    item.grid = gd.resources.RadianceGridTexture.from_grid(grid)
    (group,) = gd.draw.prepare_draw([item], VIEW, PROJ, display_srgb=False).groups
    assert group.variant.grid and group.grid is item.grid.texture
    image = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE)
    inside, n, views = quad_pixels(item.model_matrix)
    expected = radiance_grid.lookup(half(grid), n, views)
    err = np.max(np.abs(image[inside][:, :3] - expected)) / np.max(expected)
    assert inside.sum() > 300 and err < 1e-3, err
    per_pixel = sh_sum.shade_sh(result, lighting.coefficients, n, views)
    de = delta_e_2000(image[inside][:, :3], per_pixel)
    assert de.mean() < 0.8, de.mean()


# ----------------------------------------------------------------------------------------------
# Shaders compiled ahead: the stand-in while a variant is not compiled
# ----------------------------------------------------------------------------------------------
@pytest.mark.blender
def test_an_uncompiled_variant_is_drawn_by_its_stand_in_until_compiled(gd):
    """prepare_draw(compile_now=False) never compiles the item's variant: it asks for it and draws
    the stand-in (order ≤ policy.STAND_IN_L, the same table and lighting), which is the SH sum
    truncated there; compile_next (the idle step) compiles it and the next frame uses it."""
    import dataclasses

    from precompute.shading.variant import stand_in

    result = baked(5, "spectral", False)
    table = gd.resources.TableTexture.from_result(result)
    world, _img = world_sh(5)
    lighting = gd.resources.Lighting.from_sh(world, 5, result.material.roughness)
    item = tilted_quad_item(gd, table, lighting)
    cache = gd.shaders.ShaderCache()
    (group,) = gd.draw.prepare_draw(
        [item], VIEW, PROJ, display_srgb=False, shaders=cache, compile_now=False
    ).groups
    wanted = cache.wanted()
    assert len(wanted) == 1 and wanted[0].l_max == 5 and not cache.compiled(wanted[0])
    assert group.variant == stand_in(wanted[0]) and group.variant.l_max == policy.STAND_IN_L
    assert cache.compile_count == 1  # the stand-in only
    import gpu

    out = gpu.types.GPUOffScreen(SIZE, SIZE, format="RGBA32F")
    try:
        with out.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            gd.draw.draw_items([item], VIEW, PROJ, display_srgb=False, shaders=cache, compile_now=False)
            image = gd.draw.read_framebuffer(fb, SIZE, SIZE)
    finally:
        out.free()
    inside, n, views = quad_pixels(item.model_matrix)
    k2 = (policy.STAND_IN_L + 1) * (policy.STAND_IN_L + 2) // 2
    truncated = dataclasses.replace(result, data=result.data[:, :, :k2], sh_order=policy.STAND_IN_L)
    expected = sh_sum.shade_sh(truncated, lighting.coefficients, n, views)
    full = sh_sum.shade_sh(result, lighting.coefficients, n, views)
    err = np.max(np.abs(image[inside][:, :3] - expected)) / np.max(expected)
    assert inside.sum() > 300 and err < 1e-4, err
    assert np.max(np.abs(full - expected)) / np.max(expected) > 1e-3  # the truncation shows
    assert cache.compile_next() == wanted[0] and cache.compiled(wanted[0]) and not cache.wanted()
    assert cache.compile_next() is None
    (group,) = gd.draw.prepare_draw(
        [item], VIEW, PROJ, display_srgb=False, shaders=cache, compile_now=False
    ).groups
    assert group.variant == wanted[0] and cache.compile_seconds


@pytest.mark.blender
def test_a_film_waiting_for_its_grid_does_not_ask_for_its_per_pixel_variant(gd):
    """While its grid is built (under a second) a film is drawn by the stand-in, and its per-pixel
    variant is not queued for the idle compile (77–83 s of llvmpipe for a per-pixel l = 12
    variant, needed for a frame or two); once compiled it would be used."""
    result = baked(5, "spectral", False)
    table = gd.resources.TableTexture.from_result(result)
    world, _img = world_sh(5)
    lighting = gd.resources.Lighting.from_sh(world, 5, result.material.roughness)
    item = tilted_quad_item(gd, table, lighting)
    item.grid_pending = True
    cache = gd.shaders.ShaderCache()
    (group,) = gd.draw.prepare_draw(
        [item], VIEW, PROJ, display_srgb=False, shaders=cache, compile_now=False
    ).groups
    assert not cache.wanted() and group.variant.l_max == policy.STAND_IN_L
    item.grid_pending = False  # no grid coming (a failed build): the variant is asked for
    gd.draw.prepare_draw([item], VIEW, PROJ, display_srgb=False, shaders=cache, compile_now=False)
    (wanted,) = cache.wanted()
    assert wanted.l_max == 5
    cache.compile_next()
    item.grid_pending = True  # compiled already: the per-pixel variant is drawn, not the stand-in
    (group,) = gd.draw.prepare_draw(
        [item], VIEW, PROJ, display_srgb=False, shaders=cache, compile_now=False
    ).groups
    assert group.variant == wanted


def test_a_grid_under_another_world_is_not_the_cached_one():
    """The grid's World part is kept per World (radiance_grid._turned_world): building under
    World A, then B, then A again gives A's grid both times and B's is B's own (a key that
    missed the World would hand B A's light)."""
    result = rough_table(0.5)
    shape = (16, 8, result.data.shape[1], 8)
    a = windowed_world(result)
    b = a * np.array([0.2, 1.0, 3.0])  # another World: its colour differs per channel
    first = radiance_grid.build(result, a, shape)
    other = radiance_grid.build(result, b, shape)
    again = radiance_grid.build(result, a, shape)
    np.testing.assert_array_equal(again, first)
    scale = np.abs(first).max()
    assert np.abs(other - first).max() > 0.1 * scale
    radiance_grid._TURNED.clear()
    np.testing.assert_allclose(radiance_grid.build(result, b, shape), other, rtol=0, atol=1e-6 * scale)


# ----------------------------------------------------------------------------------------------
# A varying thickness: the film-free basis grid
# ----------------------------------------------------------------------------------------------
@pytest.mark.blender
@pytest.mark.parametrize("colour_mode", ["spectral", "per_channel"])
def test_a_varying_film_reads_the_basis_grid_per_pixel(gd, colour_mode):
    """A thickness varying across a tilted quad in the split-sum/SH hand-over (roughness 0.3, SH
    weight 0.5) with a basis grid (lobe_grid.build_basis): the grid variant is chosen with the
    film table bound, and each pixel is the split sum plus lobe_grid.lookup_basis at its own
    thickness (tf_grid_basis.glsl), where the per-pixel SH was drawn before."""
    from precompute.colour import film_colour
    from precompute.shading import lobe_grid, split_sum
    from precompute.shading.lamps import thickness_lerp
    from precompute.world import prefilter

    result = baked(5, colour_mode, True)
    film = film_colour.film_table(result)
    world, img = world_sh()
    lighting = gd.resources.Lighting.from_sh(world, 5, result.material.roughness)
    full = prefilter.prefilter(img, width=64)
    levels, moments = full.resampled(64), full.resampled_moments(64)
    pre = prefilter.Prefiltered(
        tuple(levels), np.asarray(policy.ROUGHNESS_LEVELS), 0, tuple(moments), full.lamp_weights
    )
    basis = lobe_grid.build_basis(
        result.material.roughness, img, (24, 12, 4, policy.GRID_AZIMUTHS), samples=(12, 12)
    )
    table = gd.resources.TableTexture.from_result(result)
    item = tilted_quad_item(gd, table, lighting)
    along = 0.5 + 0.45 * QUAD_POS[:, 0]  # the thickness parameter, linear across the quad
    item.batch = gd.mesh.MeshBatch.from_arrays(QUAD_POS, QUAD_NOR, QUAD_TRIS, thickness=along)
    item.prefiltered = gd.resources.PrefilterTexture.from_levels(levels, moments)
    item.roughness, item.sh_weight = result.material.roughness, 0.5
    item.film = gd.resources.FilmTexture.from_film(film)
    item.grid = gd.resources.RadianceGridTexture.from_grid(basis)
    (group,) = gd.draw.prepare_draw([item], VIEW, PROJ, display_srgb=False).groups
    assert group.variant.grid and group.variant.vary_thickness and group.variant.film, group.variant
    image = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE)

    inside, n, views = quad_pixels(item.model_matrix)
    t01 = 0.5 + 0.45 * quad_local(item.model_matrix)[0][inside][:, 0]
    nm = result.thicknesses_nm[0] + t01 * (result.thicknesses_nm[-1] - result.thicknesses_nm[0])
    if not policy.uses_moment(5, False):
        pre = dataclasses.replace(pre, moments=None)
    grid_half = lobe_grid.lookup_basis(
        half(basis), n, views, film, thickness_lerp(film, t01, t01.size), policy.GRID_AZIMUTHS
    )
    expected = 0.5 * split_sum.shade_split_sum(result, pre, n, views, nm) + 0.5 * grid_half
    err = np.max(np.abs(image[inside][:, :3] - expected), axis=-1) / np.max(expected)
    print(f"basis grid {colour_mode}: GLSL vs numpy max {err.max():.1e} median {np.median(err):.1e}")
    # Measured on llvmpipe: see below. A swapped block, node or thickness row errs by ≥ 1e-2.
    assert inside.sum() > 300 and np.ptp(t01) > 0.5 and err.max() < 1e-3, err.max()
