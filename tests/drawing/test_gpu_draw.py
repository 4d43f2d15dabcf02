"""GPU drawing (addon/gpu/ + glsl/) in a real bpy session on whatever OpenGL is present.

The key test runs the production GLSL chunks (frame, SH rotation, table lookup, sum) on normals
and views read from textures, one per pixel, and compares them with
:func:`precompute.output.render.shade_sh`. The rest renders meshes off-screen: silhouettes, depth
masking through the ``depth_from`` hook, the restored GPU state, the shader cache, mesh arrays.
"""

import dataclasses
import importlib
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from _extension import EXTENSION_ID, REFERENCE_ROTATION, REPO

from precompute.bakes import bake
from precompute.colour import film_colour
from precompute.materials import ramp
from precompute.materials.material import Layer, Material, Quality
from precompute.materials.noise import value_noise
from precompute.materials.perlin import NoiseSpec
from precompute.output import image_io, render
from precompute.sh import projection
from precompute.shading import codegen, policy, sh_rotation, sh_sum, split_sum
from precompute.shading import lamps as lamp_shading
from precompute.shading.variant import Variant
from precompute.world import hdri

pytestmark = pytest.mark.blender

THICKNESS_RANGE = (200.0, 800.0)


# ----------------------------------------------------------------------------------------------
# Fixtures and helpers
# ----------------------------------------------------------------------------------------------
_BAKES = {}


def baked(l_max: int, colour_mode: str, varies: bool) -> bake.BakeResult:
    key = (l_max, colour_mode, varies)
    if key not in _BAKES:
        material = Material(
            layers=(Layer(1.33, 380.0),),
            substrate=1.5,
            roughness={2: 0.55, 5: 0.3, 6: 0.3, 8: 0.15, 12: 0.5}[l_max],
            thickness_range_nm=THICKNESS_RANGE if varies else None,
            colour_mode=colour_mode,
            quality=Quality(
                sh_order=l_max,
                view_samples=16,
                thickness_samples=8 if varies else "auto",
                wavelength_count=48,
            ),
        )
        _BAKES[key] = bake.bake(material)
    return _BAKES[key]


def world_sh(l_max: int = 12, seed: int = 3) -> np.ndarray:
    """A bright, mostly positive environment: a sky-like gradient plus a soft sun, projected."""
    h, w = 32, 64
    el = np.pi * (0.5 - (np.arange(h) + 0.5) / h)
    phi = 2 * np.pi * (0.5 - (np.arange(w) + 0.5) / w)
    phi, el = np.meshgrid(phi, el)
    d = np.stack([np.cos(el) * np.cos(phi), np.cos(el) * np.sin(phi), np.sin(el)], -1)
    sun = np.exp(8.0 * (d @ np.array([0.48, -0.6, 0.64]) - 1.0))
    img = (
        0.3 + 0.2 * d[..., 2:3] * np.array([0.6, 0.8, 1.0]) + 4.0 * sun[..., None] * np.array([1.0, 0.9, 0.7])
    )
    rng = np.random.default_rng(seed)
    img = img * (1.0 + 0.1 * rng.random((1, 1, 3)))
    return projection.project_equirect(img, l_max), img


def unit(a):
    a = np.asarray(a, dtype=np.float64)
    return a / np.linalg.norm(a, axis=-1, keepdims=True)


def shading_inputs(count: int, seed: int):
    """Normals, views (unit, float32-representable) and thickness positions in [0, 1]."""
    rng = np.random.default_rng(seed)
    n = unit(rng.normal(size=(count, 3)))
    v = unit(rng.normal(size=(count, 3)))
    v = np.where(np.sum(n * v, -1, keepdims=True) < 0, -v, v)  # mostly front-facing
    special_n, special_v = [], []
    z = np.array([0.0, 0.0, 1.0])
    for pole in (z, -z):  # poles: views all around, along the normal and grazing
        for view in (
            pole,
            unit([0.3, 0.4, pole[2]]),
            unit([1.0, 0.0, 0.0]),
            unit([-0.2, 0.9, 0.05 * pole[2]]),
        ):
            special_n.append(pole)
            special_v.append(view)
    for tilt in (1e-9, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2):  # near the poles (gimbal threshold 1e-7)
        for pole in (1.0, -1.0):
            nn = unit([tilt, -0.5 * tilt, pole])
            special_n += [nn, nn]
            special_v += [unit([0.2, 0.7, pole]), nn]
    for p in range(6):  # v ∥ n and nearly so
        nn = n[p]
        tangent = unit(np.cross(nn, [0.3, 0.1, 0.9]))
        for eps in (0.0, 1e-4, 1e-2):
            special_n.append(nn)
            special_v.append(unit(nn + eps * tangent))
    for p in range(6, 12):  # grazing: exactly 90°, 89.5°, 89°, and slightly behind (clamped)
        nn = n[p]
        tangent = unit(np.cross(nn, [0.3, 0.1, 0.9]))
        for el in (0.0, 0.5, 1.0, -0.5):
            e = np.radians(el)
            special_n.append(nn)
            special_v.append(unit(np.cos(e) * tangent + np.sin(e) * nn))
    for axis in np.eye(3):  # normals along ±x, ±y (helper switch of the v ∥ n fallback)
        for s in (1.0, -1.0):
            special_n += [s * axis, s * axis]
            special_v += [s * axis, unit(s * axis + [0.1, 0.2, 0.3])]
    k = len(special_n)
    n[-k:] = special_n
    v[-k:] = special_v
    t = rng.random(count)
    t[:4] = [0.0, 1.0, 0.5, 1.0 / 7.0]
    # The GPU reads float32 values and normalises them; numpy gets those exact unit vectors
    # (shade_sh takes cos θo = n·v with v as given, so v must be unit to float64 precision).
    return (
        unit(n.astype(np.float32)),
        unit(v.astype(np.float32)),
        t.astype(np.float32).astype(np.float64),
    )


TEST_FRAGMENT = """
void main()
{
  ivec2 p = ivec2(gl_FragCoord.xy);
  vec4 nt = texelFetch(tf_test_normal, p, 0);
  vec3 v = texelFetch(tf_test_view, p, 0).xyz;
  tf_frag_color = vec4(tf_shade(normalize(nt.xyz), normalize(v), nt.w), 1.0);
}
"""

TEST_VERTEX = "void main() { gl_Position = vec4(pos, 0.0, 1.0); }"


def shade_on_gpu(
    gd, gpu, table, lighting, normals, views, thickness01, vary: bool, width: int, generated=True
):
    """Run tf_shade per pixel with inputs from two RGBA32F textures; RGB (N, 3)."""
    count = normals.shape[0]
    height = count // width
    assert width * height == count
    info = gpu.types.GPUShaderCreateInfo()
    gd.shaders.declare_shading_resources(info, Variant(table.l_max, table.spectral, vary, False))
    info.sampler(1, "FLOAT_2D", "tf_test_normal")
    info.sampler(2, "FLOAT_2D", "tf_test_view")
    info.vertex_in(0, "VEC2", "pos")
    info.fragment_out(0, "VEC4", "tf_frag_color")
    info.vertex_source(TEST_VERTEX)
    reference = None if generated else REFERENCE_ROTATION
    info.fragment_source(
        gd.shaders.shading_library(table.l_max, reference_rotation=reference) + TEST_FRAGMENT
    )
    shader = gpu.shader.create_from_info(info)

    def tex(rgb, w):
        data = np.zeros((height, width, 4), dtype=np.float32)
        data[..., :3] = rgb.reshape(height, width, 3)
        data[..., 3] = w.reshape(height, width)
        return gpu.types.GPUTexture((width, height), format="RGBA32F", data=gd.resources.float_buffer(data))

    tex_n = tex(normals, thickness01)
    tex_v = tex(views, np.zeros(count))
    offscreen = gpu.types.GPUOffScreen(width, height, format="RGBA32F")
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            shader.bind()
            shader.uniform_block("tf_lighting", lighting.ubo)
            shader.uniform_sampler("tf_table", table.texture)
            shader.uniform_sampler("tf_test_normal", tex_n)
            shader.uniform_sampler("tf_test_view", tex_v)
            gd.draw._fullscreen_triangle().draw(shader)
            out = gd.draw.read_framebuffer(fb, width, height)
    finally:
        offscreen.free()
    return out[::-1].reshape(count, 4)[:, :3]  # back to row 0 = first pixel row (gl_FragCoord.y = 0)


# Measured max |GLSL − numpy| / max |numpy| per variant, printed at the end (pytest -s / -rA).
AGREEMENT = {}


# ----------------------------------------------------------------------------------------------
# GLSL chunks against numpy
# ----------------------------------------------------------------------------------------------
def _shading_cases():
    """(thickness, colour_mode, l_max) of every variant; at l = 12 (a 35–60 s compile each on
    llvmpipe with a cold shader cache) the fast set keeps the spectral constant-thickness
    variant (and its first-row twin, the same shader) and the full set (``slow``) the rest."""
    cases = []
    for l_max in (2, 5, 8, 12):
        for colour_mode in ("spectral", "per_channel"):
            for thickness in ("constant", "varying", "varying_table_first_row"):
                fast = l_max < 12 or (colour_mode == "spectral" and thickness != "varying")
                marks = () if fast else (pytest.mark.slow,)
                cases.append(pytest.param(thickness, colour_mode, l_max, marks=marks))
    return cases


@pytest.mark.parametrize("thickness, colour_mode, l_max", _shading_cases())
def test_glsl_shading_matches_numpy_shade_sh(gd, l_max, colour_mode, thickness):
    check_against_numpy(gd, l_max, colour_mode, thickness, generated=True)


@pytest.mark.parametrize(
    "l_max, colour_mode, thickness",
    [
        (2, "per_channel", "constant"),
        (5, "spectral", "varying"),
        (8, "spectral", "constant"),
        pytest.param(12, "per_channel", "constant", marks=pytest.mark.slow),  # a 50 s compile
    ],
)
def test_glsl_loop_rotation_matches_numpy_shade_sh(gd, l_max, colour_mode, thickness):
    """The generic X(±90°) loops of tests/glsl/tf_sh_rotate_loops.glsl (the generated code switched
    off)."""
    check_against_numpy(gd, l_max, colour_mode, thickness, generated=False)


def check_against_numpy(gd, l_max, colour_mode, thickness, generated):
    import gpu

    varies = thickness != "constant"
    vary = thickness == "varying"
    result = baked(l_max, colour_mode, varies)
    table = gd.resources.TableTexture.from_result(result)
    world, _img = world_sh()
    lighting = gd.resources.Lighting.from_sh(world, l_max, result.material.roughness)
    width = 32
    n, v, t01 = shading_inputs(width * 16, seed=l_max)
    got = shade_on_gpu(gd, gpu, table, lighting, n, v, t01, vary, width, generated)
    thick_nm = THICKNESS_RANGE[0] + t01 * (THICKNESS_RANGE[1] - THICKNESS_RANGE[0]) if vary else None
    expected = sh_sum.shade_sh(result, lighting.coefficients, n, v, thick_nm)
    scale = np.max(np.abs(expected))
    assert scale > 0.05 and np.all(np.isfinite(got))
    per_pixel = np.max(np.abs(got - expected), axis=-1) / scale
    err, typical = float(per_pixel.max()), float(np.median(per_pixel))
    AGREEMENT[(l_max, colour_mode, thickness, "generated" if generated else "loops")] = (err, typical)
    # Everything runs in float32 (interpolation included: texelFetch, no hardware filtering).
    # Measured on llvmpipe: max ≤ 6e-6, median ~1e-7 — float32 rounding of the same maths (numpy
    # redone in float32 errs by up to 2e-5). The bounds leave room for GPUs with less exact
    # atan/inversesqrt; a wrong index, sign or weight shows up as ≥ 1e-3.
    assert err <= 1e-4, f"max relative error {err:.2e}"
    assert typical <= 2e-6, f"median relative error {typical:.2e}"


def test_print_agreement():
    """Prints the GLSL-vs-numpy agreement collected by the draw tests above (reported for the docs; the
    asserts are in those tests)."""
    if AGREEMENT:
        lines = [
            f"  l={k[0]} {k[1]:11s} {k[2]:24s} {k[3]:9s} max {v[0]:.2e} median {v[1]:.2e}"
            for k, v in sorted(AGREEMENT.items())
        ]
        print("\nGLSL vs numpy (|error| / max |value|):\n" + "\n".join(lines))


def test_table_layers_and_lighting_layout(gd):
    result = baked(2, "spectral", True)
    layers = gd.resources.TableTexture.layer_array(result.data)
    t, a, k = result.data.shape[:3]
    assert layers.shape == (3 * k, t, a, 4) and layers.dtype == np.float32
    assert np.array_equal(layers[3 * 4 + 2, 5, 7, :3], result.data[5, 7, 4, 2].astype(np.float32))
    assert np.all(layers[..., 3] == 0)
    pc = baked(2, "per_channel", False)
    assert np.array_equal(
        gd.resources.TableTexture.layer_array(pc.data)[3, 0, 9, :3], pc.data[0, 9, 3].astype(np.float32)
    )

    world, _img = world_sh()
    lighting = gd.resources.Lighting.from_sh(world, 5, 0.3)
    window = policy.lighting_window(5, 0.3)
    assert np.allclose(lighting.coefficients, world[:36] * window[:, None])
    packed = gd.resources.Lighting.pack(lighting.coefficients).reshape(-1, 4)
    assert packed.nbytes == gd.layout.LIGHTING_VEC4 * 16 <= gd.layout.UBO_LIMIT_BYTES
    slots = gd.layout.SH_SLOTS
    assert np.allclose(packed[:36, :3], lighting.coefficients) and np.all(packed[36:slots] == 0)
    assert np.all(packed[slots : slots + gd.layout.LAMP_VEC4] == 0)  # no lamps: count 0
    rx = packed[slots + gd.layout.LAMP_VEC4 :].ravel()
    # One set: X(+90°) row-major; X(−90°) is read as its transpose.
    for sign in (+1, -1):
        for l, block in enumerate(sh_rotation.x_rotation_bands(gd.layout.MAX_L, sign)):
            stored = rx[codegen.rx_offset(l) : codegen.rx_offset(l) + block.size].reshape(block.shape)
            assert np.allclose(stored if sign > 0 else stored.T, block, atol=1e-7)
    # The generated X(±90°) code (band by band, codegen.banded_source) multiplies exactly the
    # structurally non-zero entries.
    nonzero = sum(
        int(np.sum(np.abs(b) > policy.X90_ZERO))
        for s in (1, -1)
        for b in sh_rotation.x_rotation_bands(8, s)[1:]
    )
    assert codegen.banded_source(8).count("tf_rx(") == nonzero == 2 * 246


# ----------------------------------------------------------------------------------------------
# Meshes rendered off-screen
# ----------------------------------------------------------------------------------------------
def uv_sphere_mesh(bpy, segments=64, rings=32, name="tf_sphere"):
    import bmesh

    mesh = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=segments, v_segments=rings, radius=1.0)
    bm.to_mesh(mesh)
    bm.free()
    mesh.shade_smooth()
    return mesh


def look_at_view(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    eye, target, up = (np.asarray(x, dtype=float) for x in (eye, target, up))
    back = unit(eye - target)
    right = unit(np.cross(up, back))
    upv = np.cross(back, right)
    world = np.eye(4)
    world[:3, 0], world[:3, 1], world[:3, 2], world[:3, 3] = right, upv, back, eye
    return np.linalg.inv(world)


def perspective(fov_deg, aspect=1.0, near=0.1, far=100.0) -> np.ndarray:
    f = 1.0 / np.tan(np.radians(fov_deg) / 2)
    return np.array(
        [
            [f / aspect, 0, 0, 0],
            [0, f, 0, 0],
            [0, 0, (far + near) / (near - far), 2 * far * near / (near - far)],
            [0, 0, -1, 0],
        ]
    )


def orthographic(half, near=0.1, far=100.0) -> np.ndarray:
    return np.array(
        [
            [1 / half, 0, 0, 0],
            [0, 1 / half, 0, 0],
            [0, 0, -2 / (far - near), -(far + near) / (far - near)],
            [0, 0, 0, 1],
        ]
    )


class Item:
    def __init__(self, batch, table, lighting, model=None):
        self.batch, self.table, self.lighting = batch, table, lighting
        self.model_matrix = np.eye(4) if model is None else model


@pytest.fixture(scope="module")
def sphere_scene(gd, bpy):
    mesh = uv_sphere_mesh(bpy)
    arrays = gd.mesh.mesh_arrays(mesh)
    bpy.data.meshes.remove(mesh)
    positions, normals, tris, _ = arrays
    result = baked(5, "spectral", False)
    world, img = world_sh()
    table = gd.resources.TableTexture.from_result(result)
    lighting = gd.resources.Lighting.from_sh(world, 5, result.material.roughness)
    batch = gd.mesh.MeshBatch.from_arrays(positions, normals, tris)
    return dict(result=result, table=table, lighting=lighting, batch=batch, image=img)


def shift(mask, dy, dx):
    out = np.zeros_like(mask)
    h, w = mask.shape
    out[max(dy, 0) : h + min(dy, 0), max(dx, 0) : w + min(dx, 0)] = mask[
        max(-dy, 0) : h + min(-dy, 0), max(-dx, 0) : w + min(-dx, 0)
    ]
    return out


def dilate(mask):
    out = mask.copy()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            out |= shift(mask, dy, dx)
    return out


def erode(mask):
    return ~dilate(~mask)


SIZE = 64
DISTANCE, FOV = 4.0, 32.0
VIEW = look_at_view((0.0, -DISTANCE, 0.0), (0.0, 0.0, 0.0))
PROJ = perspective(FOV)


def test_sphere_render_silhouette_and_values(gd, sphere_scene):
    s = sphere_scene
    # Turned and moved, but still the unit sphere at the origin: exercises the model matrix and
    # the normal matrix (uniform scale 2 with a mesh of radius 0.5 would too; rotation suffices).
    angle = np.radians(35.0)
    model = np.eye(4)
    model[:3, :3] = [[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]]
    item = Item(s["batch"], s["table"], s["lighting"], model)
    bg_only = gd.draw.render_offscreen([], VIEW, PROJ, SIZE, SIZE, background=s["image"])
    img = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE, background=s["image"])
    bare = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE)
    assert img.shape == (SIZE, SIZE, 4) and img.dtype == np.float32
    assert np.all(np.isfinite(img)) and np.all(img >= 0)

    view = render.sphere_view(SIZE, SIZE, DISTANCE, FOV)
    drawn = bare[..., 3] > 0.5
    assert np.all(drawn <= dilate(view.mask)) and np.all(erode(view.mask) <= drawn)
    assert abs(int(drawn.sum()) - int(view.mask.sum())) <= 0.05 * view.mask.sum()
    differs = np.any(np.abs(img[..., :3] - bg_only[..., :3]) > 1e-6, axis=-1)
    assert np.array_equal(differs, drawn)
    assert np.all(bg_only[..., 3] == 1.0)

    # The background is the equirect image seen through the camera (hardware-filtered lookup).
    expected_bg = hdri.equirect_lookup(s["image"], view.rays)
    bg_err = np.max(np.abs(bg_only[..., :3] - expected_bg)) / np.max(expected_bg)
    assert bg_err < 1e-3, bg_err  # measured 8e-5 on llvmpipe (hardware bilinear weights)

    # Inside the silhouette the mesh shading approximates shade_sh on the analytic sphere: the
    # mesh's interpolated normals and flat facets differ from the sphere's by ~1e-3 (measured:
    # median 2e-4, max 1.2e-2 of the peak, the max near the rim where the lobe changes fastest).
    inner = erode(erode(view.mask))
    expected = sh_sum.shade_sh(
        s["result"], s["lighting"].coefficients, view.normals[inner], view.views[inner]
    )
    rel = np.abs(bare[inner][:, :3] - expected) / np.max(expected)
    assert np.median(rel) < 1e-3 and np.max(rel) < 3e-2, (np.median(rel), np.max(rel))


def test_a_smooth_mesh_shares_its_vertices_and_draws_the_same(gd, bpy, sphere_scene):
    """A mesh shaded smooth (normals per vertex) gives ``vertex_arrays``: one row per vertex, a
    quarter of the per-corner rows of its quads, and the same triangles through them; drawn
    with the same table and lighting it gives the per-corner batch's picture to float
    precision. Shaded flat (normals per face) it gives none: corners keep their own normals."""
    s = sphere_scene
    mesh = uv_sphere_mesh(bpy, name="tf_shared")
    try:
        shared = gd.mesh.vertex_arrays(mesh)
        corners = gd.mesh.mesh_arrays(mesh)
        assert shared is not None and len(shared[0]) == len(mesh.vertices) == 64 * 31 + 2
        assert len(corners[0]) == len(mesh.loops) > 3.5 * len(mesh.vertices)
        np.testing.assert_array_equal(shared[0][shared[2]], corners[0][corners[2]])  # same triangles
        np.testing.assert_allclose(shared[1][shared[2]], corners[1][corners[2]], atol=1e-6)
        pictures = [
            gd.draw.render_offscreen(
                [Item(gd.mesh.MeshBatch.from_arrays(*arrays[:3]), s["table"], s["lighting"])],
                VIEW,
                PROJ,
                SIZE,
                SIZE,
            )
            for arrays in (shared, corners)
        ]
        assert (pictures[0][..., 3] > 0.5).sum() > 0.4 * SIZE * SIZE / 4
        np.testing.assert_allclose(pictures[0], pictures[1], atol=1e-6)
        mesh.shade_flat()
        assert gd.mesh.vertex_arrays(mesh) is None
    finally:
        bpy.data.meshes.remove(mesh)


def rotation(axis: int, degrees: float) -> np.ndarray:
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    i, j = [k for k in range(3) if k != axis]
    m = np.eye(4)
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


@pytest.mark.parametrize("flip", [False, True])
def test_flat_quad_matches_shade_sh_per_pixel(gd, flip):
    """Perspective view vectors, normal matrix (non-uniform scale) and two-sided normals, exactly.

    A flat quad has one normal, so every pixel's expected colour follows from the camera ray's
    hit point: v = normalise(camera − hit), n = the transformed normal, flipped towards the viewer.
    """
    result = baked(8, "spectral", False)
    table = gd.resources.TableTexture.from_result(result)
    world, _img = world_sh()
    lighting = gd.resources.Lighting.from_sh(world, 8, result.material.roughness)
    pos = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], dtype=np.float32)
    nor = np.tile([0.0, 1.0 if flip else -1.0, 0.0], (4, 1))  # towards or away from the camera
    batch = gd.mesh.MeshBatch.from_arrays(pos, nor, [[0, 1, 2], [0, 2, 3]])
    translate = np.eye(4)
    translate[:3, 3] = [0.1, 0.3, -0.2]
    model = translate @ rotation(2, 20.0) @ rotation(0, 50.0) @ np.diag([1.4, 1.0, 0.6, 1.0])
    img = gd.draw.render_offscreen([Item(batch, table, lighting, model)], VIEW, PROJ, SIZE, SIZE)

    rays = render.sphere_view(SIZE, SIZE, DISTANCE, FOV).rays
    cam = np.array([0.0, -DISTANCE, 0.0])
    normal = np.linalg.inv(model[:3, :3]).T @ np.array([0.0, -1.0, 0.0])
    normal /= np.linalg.norm(normal)
    origin = model[:3, 3]
    t = ((origin - cam) @ normal) / (rays @ normal)
    hit = cam + t[..., None] * rays
    local = (hit - origin) @ np.linalg.inv(model[:3, :3]).T
    inside = (np.abs(local[..., 0]) < 0.97) & (np.abs(local[..., 2]) < 0.97) & (t > 0)
    outside = (np.abs(local[..., 0]) > 1.03) | (np.abs(local[..., 2]) > 1.03) | (t <= 0)
    drawn = img[..., 3] > 0.5
    assert inside.sum() > 500 and np.all(drawn[inside]) and not np.any(drawn[outside])
    views = unit(cam - hit[inside])
    n = np.broadcast_to(normal, views.shape)
    n = np.where(np.sum(n * views, -1, keepdims=True) < 0, -n, n)
    expected = sh_sum.shade_sh(result, lighting.coefficients, n, views)
    err = np.max(np.abs(img[inside][:, :3] - expected)) / np.max(expected)
    assert err < 1e-4, err


def test_orthographic_view_uses_the_constant_view_direction(gd, sphere_scene):
    s = sphere_scene
    item = Item(s["batch"], s["table"], s["lighting"])
    half = 1.25
    img = gd.draw.render_offscreen([item], VIEW, orthographic(half), SIZE, SIZE)
    xs = ((np.arange(SIZE) + 0.5) / SIZE * 2 - 1) * half
    x, z = np.meshgrid(xs, -xs)
    r2 = x * x + z * z
    mask = r2 < 1.0
    drawn = img[..., 3] > 0.5
    assert np.all(drawn <= dilate(mask)) and np.all(erode(mask) <= drawn)
    inner = erode(erode(mask))
    normals = np.stack([x, -np.sqrt(np.maximum(1 - r2, 0)), z], -1)[inner]
    views = np.broadcast_to([0.0, -1.0, 0.0], normals.shape)
    expected = sh_sum.shade_sh(s["result"], s["lighting"].coefficients, normals, views)
    rel = np.abs(img[inner][:, :3] - expected) / np.max(expected)
    assert np.median(rel) < 1e-3 and np.max(rel) < 3e-2, (np.median(rel), np.max(rel))


def test_display_output_is_srgb_encoded_with_exposure(gd, sphere_scene):
    import gpu

    s = sphere_scene
    item = Item(s["batch"], s["table"], s["lighting"])
    linear = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE)
    offscreen = gpu.types.GPUOffScreen(SIZE, SIZE, format="RGBA32F")
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            gd.draw.draw_items([item], VIEW, PROJ, display_srgb=True, exposure=0.7)
            display = gd.draw.read_framebuffer(fb, SIZE, SIZE)
    finally:
        offscreen.free()
    drawn = linear[..., 3] > 0.5
    expected = image_io.srgb_encode(linear[..., :3], 0.7)
    assert np.max(np.abs(display[..., :3][drawn] - expected[drawn])) < 1e-4


@pytest.mark.parametrize("exposure", [0.7, 4.0])
def test_display_lut_output_matches_numpy_per_pixel(gd, sphere_scene, exposure):
    """TF_DISPLAY_LUT (tf_display.glsl) against precompute.colour.display_lut.apply, pixel by pixel,
    with a LUT that mixes the channels (every corner of a cell matters)."""
    import gpu

    from precompute.colour import display_lut
    from precompute.shading import policy

    lattice = display_lut.lattice(policy.DISPLAY_LUT_SIZE)
    mix = np.array([[0.8, 0.15, 0.05], [0.1, 0.7, 0.2], [0.05, 0.25, 0.7]])
    table = np.tanh(lattice @ mix.T) ** (1 / 2.2)  # a tone curve with cross-talk, in [0, 1)
    matrix = np.array([[1.2, -0.15, -0.05], [-0.1, 1.1, 0.0], [0.0, -0.05, 1.05]])  # into the LUT's space
    lut = gd.resources.DisplayLUTTexture.from_table(table, matrix)
    s = sphere_scene
    item = Item(s["batch"], s["table"], s["lighting"])
    linear = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE)
    offscreen = gpu.types.GPUOffScreen(SIZE, SIZE, format="RGBA32F")
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            gd.draw.draw_items([item], VIEW, PROJ, display_srgb=True, exposure=exposure, display_lut=lut)
            display = gd.draw.read_framebuffer(fb, SIZE, SIZE)
    finally:
        offscreen.free()
    drawn = linear[..., 3] > 0.5
    expected = display_lut.apply(table, linear[..., :3], exposure, matrix)
    err = np.abs(display[..., :3][drawn] - expected[drawn])
    spread = np.ptp(display_lut.shaper(linear[..., :3][drawn] * 2.0**exposure @ matrix.T))
    assert spread > 0.1, spread  # the pixels span many cells of the LUT
    assert np.max(err) < 2e-4, np.max(err)


def test_depth_from_hook_masks_the_sphere(gd, sphere_scene):
    import gpu
    from gpu_extras.batch import batch_for_shader

    s = sphere_scene
    item = Item(s["batch"], s["table"], s["lighting"])
    # An opaque quad between camera and sphere covering the left half of the view (x < 0).
    quad = np.array(
        [[-5.0, -2.0, -5.0], [0.0, -2.0, -5.0], [0.0, -2.0, 5.0], [-5.0, -2.0, 5.0]], dtype=np.float32
    )
    colour = (0.1, 0.7, 0.2, 1.0)
    calls = []

    def occluder(offscreen):
        calls.append(offscreen)
        shader = gpu.shader.from_builtin("UNIFORM_COLOR")
        batch = batch_for_shader(
            shader, "TRIS", {"pos": quad}, indices=np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)
        )
        gpu.matrix.load_matrix(_mathutils(VIEW))
        gpu.matrix.load_projection_matrix(_mathutils(PROJ))
        gpu.state.depth_test_set("LESS_EQUAL")
        gpu.state.depth_mask_set(True)
        shader.uniform_float("color", colour)
        batch.draw(shader)
        gpu.state.depth_test_set("NONE")

    free = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE)
    masked = gd.draw.render_offscreen(
        [item], VIEW, PROJ, SIZE, SIZE, background=s["image"], depth_from=occluder
    )
    assert len(calls) == 1
    left, right = np.s_[:, : SIZE // 2], np.s_[:, SIZE // 2 :]
    assert np.allclose(masked[left][..., :3], colour[:3], atol=1e-6)  # quad everywhere, no sphere
    sphere_right = free[right][..., 3] > 0.5
    assert sphere_right.sum() > 100
    assert np.allclose(masked[right][sphere_right], free[right][sphere_right], atol=1e-6)


def _mathutils(m):
    from mathutils import Matrix

    return Matrix(np.asarray(m).tolist())


def test_gpu_state_is_restored_after_draw_items(gd, sphere_scene):
    import gpu

    s = sphere_scene
    item = Item(s["batch"], s["table"], s["lighting"])
    offscreen = gpu.types.GPUOffScreen(16, 16, format="RGBA32F")
    try:
        with offscreen.bind():
            for depth_test, mask, blend in (("ALWAYS", False, "ALPHA"), ("NONE", True, "ADDITIVE")):
                gpu.state.depth_test_set(depth_test)
                gpu.state.depth_mask_set(mask)
                gpu.state.blend_set(blend)
                before = (gpu.state.depth_test_get(), gpu.state.depth_mask_get(), gpu.state.blend_get())
                gd.draw.draw_items([item], VIEW, PROJ, display_srgb=False)
                after = (gpu.state.depth_test_get(), gpu.state.depth_mask_get(), gpu.state.blend_get())
                assert before == after == (depth_test, mask, blend)
            gpu.state.depth_test_set("NONE")
            gpu.state.depth_mask_set(False)
            gpu.state.blend_set("NONE")
    finally:
        offscreen.free()


def test_shader_cache_compiles_each_variant_once(gd):
    cache = gd.shaders.ShaderCache()
    first = cache.get(2, True, False, False)
    assert cache.compile_count == 1
    assert cache.get(2, True, False, False) is first
    cache.get(2, False, False, False)
    cache.get(2, True, True, False)
    cache.get(2, True, False, True)
    cache.get(3, True, False, False)
    assert cache.compile_count == 5
    for _ in range(3):
        cache.get(2, False, False, False)
        cache.get(3, True, False, False)
    cache.background(False)
    cache.background(False)
    assert cache.compile_count == 6 == len(cache)
    with pytest.raises(ValueError):
        cache.get(gd.layout.MAX_L + 1, True, False, False)


def test_chunks_are_joined_by_their_includes(gd, tmp_path):
    """Each chunk names what it needs; the closure comes once each, after what it includes, and
    the product never joins the reference rotation of tests/glsl/."""
    shaders = gd.shaders
    library = [
        "tf_common.glsl",
        "tf_frame.glsl",
        "tf_sh_rotate.glsl",
        "tf_table.glsl",
        "tf_radiance_grid.glsl",  # empty without TF_RADIANCE_GRID
        "tf_shade.glsl",
    ]
    assert shaders.chunk_order(["tf_shade.glsl"]) == library
    assert shaders.chunk_order(["tf_lamps.glsl", "tf_main_frag.glsl"], done=library) == [
        "tf_brdf.glsl",
        "tf_lamps.glsl",
        "tf_display.glsl",
        "tf_main_frag.glsl",
    ]
    reference = shaders.chunk_order(
        [REFERENCE_ROTATION.name, "tf_shade.glsl"], (REFERENCE_ROTATION.parent, shaders.GLSL_DIR)
    )
    assert reference == library[:3] + [REFERENCE_ROTATION.name] + library[3:]
    assert "#include" not in shaders.shading_library(8) and "tf_apply_x90" not in shaders.shading_library(8)
    assert "tf_apply_x90" in shaders.shading_library(8, reference_rotation=REFERENCE_ROTATION)
    assert not list(shaders.GLSL_DIR.glob(REFERENCE_ROTATION.name))

    (tmp_path / "a.glsl").write_text('#include "b.glsl"\n\nvoid a() {}\n')
    (tmp_path / "b.glsl").write_text('#include "a.glsl"\nvoid b() {}\n')
    (tmp_path / "c.glsl").write_text('#include "missing.glsl"\nvoid c() {}\n')
    (tmp_path / "d.glsl").write_text('void d() {}\n#include "a.glsl"\n')
    with pytest.raises(shaders.ChunkError, match="cycle: a.glsl → b.glsl → a.glsl"):
        shaders.chunk_order(["a.glsl"], (tmp_path,))
    with pytest.raises(shaders.ChunkError, match="missing.glsl .included by c.glsl. not found"):
        shaders.chunk_order(["c.glsl"], (tmp_path,))
    with pytest.raises(shaders.ChunkError, match="at the top"):
        shaders.chunk_order(["d.glsl"], (tmp_path,))


# ----------------------------------------------------------------------------------------------
# Mesh arrays and batches
# ----------------------------------------------------------------------------------------------
def test_mesh_arrays_of_a_smooth_sphere_and_attributes(gd, bpy):
    mesh = uv_sphere_mesh(bpy, 16, 8, "tf_arrays")
    try:
        values = np.linspace(0.0, 1.0, len(mesh.vertices), dtype=np.float32)
        attr = mesh.attributes.new("film", "FLOAT", "POINT")
        attr.data.foreach_set("value", values)
        face = mesh.attributes.new("film_face", "FLOAT", "FACE")
        face.data.foreach_set("value", np.arange(len(mesh.polygons), dtype=np.float32))
        mesh.attributes.new("film_int", "INT", "POINT")
        positions, normals, tris, thickness = gd.mesh.mesh_arrays(mesh, "film")
        assert positions.dtype == normals.dtype == np.float32 and tris.dtype == np.int32
        assert positions.shape == normals.shape == (len(mesh.loops), 3)
        assert tris.shape == (len(mesh.loop_triangles), 3) and tris.max() < len(mesh.loops)
        assert np.allclose(np.linalg.norm(positions, axis=1), 1.0, atol=1e-5)
        assert np.all(np.sum(normals * positions, axis=1) > 0.98)  # smooth: close to radial
        loop_vert = np.array([loop.vertex_index for loop in mesh.loops])
        assert np.array_equal(thickness, values[loop_vert])
        face_values = gd.mesh.mesh_arrays(mesh, "film_face")[3]
        expected = np.concatenate([[i] * p.loop_total for i, p in enumerate(mesh.polygons)])
        assert np.array_equal(face_values, expected)
        assert gd.mesh.mesh_arrays(mesh, "film_int")[3] is None
        assert gd.mesh.mesh_arrays(mesh, "missing")[3] is None
        batch = gd.mesh.MeshBatch.from_arrays(positions, normals, tris, thickness)
        assert batch.has_thickness and batch.triangle_count == len(mesh.loop_triangles)
    finally:
        bpy.data.meshes.remove(mesh)
    empty = bpy.data.meshes.new("tf_empty")
    try:
        assert gd.mesh.mesh_arrays(empty) is None
    finally:
        bpy.data.meshes.remove(empty)
    assert gd.mesh.MeshBatch.from_arrays(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3))) is None
    with pytest.raises(ValueError):
        gd.mesh.MeshBatch.from_arrays(np.zeros((3, 3)), np.zeros((3, 3)), [[0, 1, 3]])


#: A 2 × 2 quad at the origin facing the camera (−y): corners, normals, triangles; with
#: orthographic(1.0) it fills the frame.
QUAD_POS = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], dtype=np.float32)
QUAD_NOR = np.tile([0.0, -1.0, 0.0], (4, 1))
QUAD_TRIS = [[0, 1, 2], [0, 2, 3]]


def facing_quad(gd, width, height, **batch_options):
    """(the :data:`QUAD_POS` quad's MeshBatch, its render (width × height, top row first) with a
    varying-thickness table, the numpy shading of thickness parameters t01 (N,) at normal
    incidence); ``batch_options``: ``thickness`` per corner and MeshBatch.from_arrays's others,
    ``noise`` the batch's Noise source (scale, seed)."""
    result = baked(2, "per_channel", True)
    table = gd.resources.TableTexture.from_result(result)
    world, _img = world_sh()
    lighting = gd.resources.Lighting.from_sh(world, 2, result.material.roughness)
    noise = batch_options.pop("noise", None)
    thickness = batch_options.pop("thickness")
    batch = gd.mesh.MeshBatch.from_arrays(QUAD_POS, QUAD_NOR, QUAD_TRIS, thickness, **batch_options)
    batch.noise = noise
    img = gd.draw.render_offscreen([Item(batch, table, lighting)], VIEW, orthographic(1.0), width, height)

    def expected(t01):
        thick_nm = THICKNESS_RANGE[0] + np.asarray(t01) * (THICKNESS_RANGE[1] - THICKNESS_RANGE[0])
        n = np.tile([0.0, -1.0, 0.0], (thick_nm.size, 1))
        return sh_sum.shade_sh(result, lighting.coefficients, n, n, thick_nm)

    return batch, img, expected


def test_varying_thickness_attribute_reaches_the_shader(gd, bpy):
    """A flat quad facing the camera whose thickness runs 0 → 1 left to right."""
    _, img, expected = facing_quad(gd, 32, 4, thickness=np.array([0.0, 1.0, 1.0, 0.0]))
    t01 = (np.arange(32) + 0.5) / 32
    want = expected(t01)
    assert np.max(np.abs(img[1, :, :3] - want)) / np.max(want) < 1e-4


@pytest.mark.parametrize("texels", [32, 8])
def test_thickness_map_is_read_per_pixel(gd, bpy, texels):
    """The same quad with a constant corner thickness and a thickness map over its UVs that runs
    up and down along u: each pixel shades the map's bilinear value at its UV (``TF_THICKNESS_MAP``),
    not the corners'. 32 texels: one per pixel, read at its centre; 8: four pixels per texel,
    between centres (the GPU's linear filter)."""
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    centres = (np.arange(texels) + 0.5) / texels
    row = 0.5 + 0.45 * np.sin(2 * np.pi * 2.5 * centres) * np.cos(2 * np.pi * 0.7 * centres)
    values = np.tile(row, (3, 1))  # three rows of v, all alike
    thickness = np.full(4, 0.5)
    batch, img, shade = facing_quad(gd, 32, 4, thickness=thickness, thickness_map=(uv, values, False))
    plain, flat, _ = facing_quad(gd, 32, 4, thickness=thickness)
    assert batch.thickness_map is not None and plain.thickness_map is None
    u = (np.arange(32) + 0.5) / 32
    expected = shade(np.interp(u, centres, row))  # bilinear along u, edges extended; v constant
    err = np.max(np.abs(img[1, :, :3] - expected)) / np.max(expected)
    # Measured on llvmpipe: 2.6e-7 (32 texels) and 2.5e-7 (8), float32 rounding: its linear
    # filter weighs in float. A GPU that weighs with 8 fractional bits errs by up to 1/256 of a
    # texel step in thickness; a wrong row, UV or channel shows up as ≥ 1e-2.
    assert err < 1e-4, err
    # the corners alone (0.5 everywhere) would draw one colour: the map is what varies it
    assert np.max(np.abs(flat[1, :, :3] - expected)) / np.max(expected) > 50 * max(err, 1e-4)


@pytest.mark.parametrize("stored", ["float", "srgb_bytes"])
def test_an_image_thickness_is_read_per_pixel_from_blenders_texture(gd, bpy, stored):
    """The *Image* source per pixel: the quad's UVs over an 8-texel image that the shader reads
    through Blender's own GPU texture of it (``ImageTexture``, ``gpu.texture.from_image``), which
    repeats as Image Texture does. A float image is kept in half floats there; an 8-bit sRGB one
    is decoded to linear before the filter, as Cycles' Image Texture reads it (and the corners:
    ``thickness._decoded``)."""
    centres = (np.arange(8) + 0.5) / 8
    row = 0.5 + 0.4 * np.sin(2 * np.pi * centres) * np.cos(2 * np.pi * 1.3 * centres)
    image = bpy.data.images.new(f"Thickness {stored}", 8, 3, float_buffer=stored == "float")
    pixels = np.ones((3, 8, 4), dtype=np.float32)
    pixels[..., 0] = row
    image.pixels.foreach_set(pixels.ravel())
    if stored == "float":
        texels = row.astype(np.float16).astype(np.float64)  # Blender's GPU copy: half floats
    else:
        assert image.colorspace_settings.name == "sRGB" and not image.is_float
        srgb_to_linear = importlib.import_module(f"{EXTENSION_ID}.addon.world.world_image").srgb_to_linear
        texels = srgb_to_linear(np.round(row * 255) / 255)
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    source = gd.mesh.ImageTexture.of(image)
    batch, img, shade = facing_quad(gd, 32, 4, thickness=np.full(4, 0.5), thickness_map=(uv, source, True))
    assert batch.map_texture() is not None
    x = (np.arange(32) + 0.5) / 32 * 8 - 0.5  # texel coordinates of the pixel centres' u
    expected = shade(np.interp(x, np.arange(8), texels, period=8))  # bilinear, repeating
    err = np.max(np.abs(img[1, :, :3] - expected)) / np.max(expected)
    # Measured on llvmpipe: 8.7e-8 (float) and 4.6e-3 (8-bit sRGB: its decode is a fitted curve,
    # within about one 8-bit step). The bytes filtered before their decode are 0.13 off, raw
    # bytes or a wrong texel far more.
    assert err < (1e-4 if stored == "float" else 1e-2), err
    bpy.data.images.remove(image)
    assert batch.map_texture() is None  # the image is gone: drawn per corner, nothing dangles


#: A linked Noise Texture as tf_perlin.glsl computes it: 3-D, Generated-like coordinates,
#: fractional Detail, a clamped Map Range folded into gain, bias, low and high.
LINKED_NOISE = NoiseSpec(3, 2.3, 0.0, 2.4, 0.6, 2.2, (0.5, 0.4, 0.6), (0.5, 0.5, 0.5), 1.6, -0.3, 0.1, 0.9)
_RAMP_AT = ramp.table_positions()
_SWINGS = np.clip((_RAMP_AT - 0.3) / 0.4, 0, 1)
#: Color Ramp tables (materials.ramp): a smooth one with two swings over Fac 0.3–0.7, read
#: interpolated, and four constant steps, read as a Constant ramp.
RAMPS = {
    "linked_ramp": (tuple(0.2 + 0.6 * np.sin(2.5 * np.pi * _SWINGS) ** 2), True),
    "linked_steps": (tuple(np.floor(np.clip(_RAMP_AT - 0.35, 0, 0.299) / 0.075) / 4 + 0.1), False),
}


#: A Mapping node folded into the linked noise's coordinates: a rotation and an uneven scale.
MAPPED = tuple((np.array([[0.8, -0.9, 0.3], [0.7, 0.5, -1.1], [0.2, 1.2, 0.6]]) * 1.3).ravel())


#: Where the quad's corners were before a deformation (``orco``): an affine map of QUAD_POS,
#: so the triangles interpolate it exactly, and nowhere near the positions.
ORCO_MAP = (np.array([[0.6, 0.2, 0.1], [-0.3, 0.9, 0.4], [0.2, -0.5, 1.1]]), np.array([0.35, -0.2, 0.45]))


@pytest.mark.parametrize(
    "kind",
    [
        "value",
        "blender",
        "linked",
        *RAMPS,
        "blender_distorted",
        "linked_distorted",
        "linked_mapped",
        "linked_orco",
    ],
)
def test_noise_thickness_is_computed_per_pixel(gd, bpy, kind):
    """The noise thicknesses per pixel (``TF_THICKNESS_NOISE``): a quad facing the camera filling
    a 32² orthographic frame, each pixel shaded at its object-space position's noise, where the
    corners alone would interpolate four values. *value*: the Noise source,
    materials.noise.value_noise (tf_noise.glsl); *blender*: the Blender Noise source,
    materials.perlin.blender_noise (tf_perlin.glsl), Blender's 4-D Noise Texture; *linked*: a
    linked 3-D Noise Texture (:data:`LINKED_NOISE`, materials.perlin.NoiseSpec.parameter);
    *linked_ramp*, *linked_steps*: the same through a Color Ramp's table (:data:`RAMPS`,
    ``TF_THICKNESS_RAMP``, materials.ramp.lookup), interpolated and Constant; *…_distorted*: the
    4-D and the 3-D noise with Distortion 0.8 (``TF_NOISE_DISTORT4``, ``TF_NOISE_DISTORT3``);
    *linked_mapped*: its coordinates through a full matrix (a Mapping node, :data:`MAPPED`);
    *linked_orco*: read at the batch's ``orco`` attribute, where a deformed mesh's vertices were
    before it (``TF_NOISE_ORCO``, :data:`ORCO_MAP`), not at the positions."""
    scale, seed, size = 3.7, 5, 32
    if kind == "value":
        spec, noise = (scale, seed), lambda p: value_noise(p, scale, seed)
    else:
        spec = NoiseSpec(4, scale, seed) if kind.startswith("blender") else LINKED_NOISE
        if kind.endswith("distorted"):  # 4-D and 3-D, materials.perlin.distortion_offsets
            spec = dataclasses.replace(spec, distortion=0.8)
        if kind == "linked_mapped":  # the coordinates through a full matrix (noise_space_x/y/z)
            spec = dataclasses.replace(spec, space_matrix=MAPPED)
        if kind in RAMPS:
            table, interpolate = RAMPS[kind]
            spec = dataclasses.replace(spec, gain=1.0, bias=0.0, ramp=table, ramp_interpolate=interpolate)
        noise = spec.parameter
    options = {}
    if kind == "linked_orco":
        spec = dataclasses.replace(spec, orco=True)
        options["orco"] = QUAD_POS @ ORCO_MAP[0].T + ORCO_MAP[1]
    _, img, shade = facing_quad(gd, size, size, thickness=noise(QUAD_POS), noise=spec, **options)
    centres = (np.arange(size) + 0.5) / size * 2 - 1
    z, x = np.meshgrid(-centres, centres, indexing="ij")  # top row first: z from +1 down
    points = np.stack([x, np.zeros_like(x), z], axis=-1).reshape(-1, 3)
    if kind == "linked_orco":  # read at orco; at the positions it would be another noise
        assert np.abs(noise(points @ ORCO_MAP[0].T + ORCO_MAP[1]) - noise(points)).max() > 0.2
        points = points @ ORCO_MAP[0].T + ORCO_MAP[1]
    t01 = np.clip(noise(points), 0.0, 1.0)
    expected = shade(t01)
    got = img[..., :3].reshape(-1, 3)
    per_pixel = np.max(np.abs(got - expected), axis=-1) / np.max(expected)
    # Measured on llvmpipe: value noise max 3.0e-6, median 3.4e-7; Blender's noise max 3.5e-7,
    # median 6.2e-8; the linked 3-D one max 1.9e-6, median 2.5e-7 (float32 positions and fades;
    # the hashes are exact integer arithmetic); through the ramps max 1.7e-5 and 1.6e-7 (the
    # smooth ramp multiplies Fac's float32 error by its slope, up to 12); at orco 5.6e-6 (the
    # positions read instead: 0.84). A wrong hash
    # constant, octave, seed or fade shows up as ≥ 1e-2 at most pixels; the ramp read without
    # its table, interpolated where Constant or one entry off, as ≥ 1e-2 at many.
    assert np.max(per_pixel) < 1e-4, np.max(per_pixel)
    assert np.ptp(t01) > 0.3  # the noise varies across the quad: the check has something to see
    if kind == "linked_steps":  # the steps: each of the four levels is drawn
        assert len(np.unique(np.round(t01, 6))) == 4, np.unique(np.round(t01, 6))


# ----------------------------------------------------------------------------------------------
# Context creation without gpu.init (fresh process)
# ----------------------------------------------------------------------------------------------
def test_workbench_render_creates_the_context_and_cleans_up(tmp_path):
    os.symlink(REPO, tmp_path / EXTENSION_ID, target_is_directory=True)
    script = textwrap.dedent(
        f"""
        import sys
        sys.path.insert(0, {str(tmp_path)!r})
        import bpy
        from {EXTENSION_ID}.addon.gpu import context
        counts = lambda: (len(bpy.data.scenes), len(bpy.data.objects), len(bpy.data.cameras))
        before = counts()
        assert not context.drawing_available()
        context._context_from_workbench_render()
        assert context.drawing_available()
        assert counts() == before, (counts(), before)
        bpy.ops.wm.read_factory_settings(use_empty=True)
        assert context.drawing_available()
        context.ensure_gpu_context()  # no-op now
        print("CONTEXT_OK")
        """
    )
    proc = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120, check=False
    )
    assert "CONTEXT_OK" in proc.stdout, proc.stdout + proc.stderr


def test_no_shader_of_ours_stays_bound_once_freed(tmp_path):
    """A frame drawn off-screen, the add-on unregistered (its shaders freed), then Blender making
    an image's GPU texture (its mipmaps bind a shader of Blender's): a fresh process, as a
    headless frame followed by disabling the add-on. With our shader left bound in Blender's
    context this aborted ("pure virtual method called"); the draws now unbind it."""
    os.symlink(REPO, tmp_path / EXTENSION_ID, target_is_directory=True)
    script = textwrap.dedent(
        f"""
        import gc, importlib, sys
        import numpy as np
        sys.path.insert(0, {str(tmp_path)!r})
        import bpy, gpu
        view = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, -4.0], [0, 0, 0, 1]], dtype=float)
        proj = np.array([[3.5, 0, 0, 0], [0, 3.5, 0, 0], [0, 0, -1.002, -0.2002], [0, 0, -1, 0]])
        for attempt in range(4):  # a freed shader is reused memory: not every round would crash
            ext = importlib.import_module("{EXTENSION_ID}")
            ext.register()
            bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
            ext.register()
            bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8)
            mat = bpy.data.materials.new("film")
            s = mat.thinfilm_sh
            s.preset, s.enabled, s.sh_order = "SOAP_FILM", True, "2"
            s.view_samples, s.wavelength_count = 4, 32
            bpy.context.active_object.data.materials.append(mat)
            bpy.context.view_layer.update()
            scene_draw = importlib.import_module("{EXTENSION_ID}.addon.drawing.scene_draw")
            items, _ = scene_draw.collect(bpy.context.evaluated_depsgraph_get())
            assert items
            draw = importlib.import_module("{EXTENSION_ID}.addon.gpu.draw")
            draw.render_offscreen(items, view, proj, 16, 16)
            del items, scene_draw, draw
            ext.unregister()
            for name in [n for n in sys.modules if n.startswith("{EXTENSION_ID}")]:
                del sys.modules[name]
            del ext
            gc.collect()
            image = bpy.data.images.new("after", 64, 64, float_buffer=True)
            print("TEXTURE", gpu.texture.from_image(image).format)
        """
    )
    proc = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=300, check=False
    )
    drawn = proc.stdout.count("TEXTURE RGBA16F")
    assert proc.returncode == 0 and drawn == 4, proc.stdout + proc.stderr[-2000:]


def tilted_quad_item(gd, table, lighting):
    """A 2×2 quad facing −y, tilted 35° about x and 25° about z: many view angles in one frame."""
    return Item(
        gd.mesh.MeshBatch.from_arrays(QUAD_POS, QUAD_NOR, QUAD_TRIS),
        table,
        lighting,
        rotation(0, 35.0) @ rotation(2, 25.0),
    )


def quad_local(model):
    """(the quad's own coordinates where each pixel's ray meets its plane (SIZE, SIZE, 3), the
    ray parameter, the ray hit points) of :func:`tilted_quad_item`'s quad."""
    rays = render.sphere_view(SIZE, SIZE, DISTANCE, FOV).rays
    cam = np.array([0.0, -DISTANCE, 0.0])
    normal = unit(np.linalg.inv(model[:3, :3]).T @ np.array([0.0, -1.0, 0.0]))
    t = ((model[:3, 3] - cam) @ normal) / (rays @ normal)
    hit = cam + t[..., None] * rays
    return (hit - model[:3, 3]) @ np.linalg.inv(model[:3, :3]).T, t, hit


def quad_pixels(model):
    """(inside mask, normals, views) of the pixels that see :func:`tilted_quad_item`'s quad
    (3 % from its edges), the normal flipped towards the viewer as the shader does."""
    cam = np.array([0.0, -DISTANCE, 0.0])
    normal = unit(np.linalg.inv(model[:3, :3]).T @ np.array([0.0, -1.0, 0.0]))
    local, t, hit = quad_local(model)
    inside = (np.abs(local[..., 0]) < 0.97) & (np.abs(local[..., 2]) < 0.97) & (t > 0)
    views = unit(cam - hit[inside])
    n = np.broadcast_to(normal, views.shape)
    n = np.where(np.sum(n * views, -1, keepdims=True) < 0, -n, n)
    return inside, n, views


@pytest.mark.parametrize(
    "colour_mode, with_moments, weight, l_max",
    [
        ("spectral", True, 0.5, 6),
        ("per_channel", True, 0.5, 6),
        ("per_channel", False, 0.5, 6),
        ("spectral", True, 0.5, 5),
        ("spectral", True, 0.0, 5),
    ],
)
def test_split_sum_variant_matches_numpy_per_pixel(gd, colour_mode, with_moments, weight, l_max):
    """tf_split_sum.glsl against split_sum.shade_combined on a flat quad, split/SH 50:50.

    With the direction moments the albedo is read at the lobe light's half-vector angle
    (split_sum.dominant_cosine); without them (zeros on the GPU, None in numpy) at the view angle.
    Below policy.MOMENT_MIN_L a film drawn by both halves does not read them (TF_MOMENT is
    not defined: policy.uses_moment), split-only films always do. SH weight 0 draws the
    split-only variant (TF_SPLIT_ONLY: no SH half), which must give the split sum alone.
    """
    from precompute.world import prefilter

    result = baked(l_max, colour_mode, False)
    table = gd.resources.TableTexture.from_result(result)
    world, img = world_sh()
    lighting = gd.resources.Lighting.from_sh(world, l_max, result.material.roughness)
    full = prefilter.prefilter(img, width=64)
    levels = full.resampled(64)
    moments = full.resampled_moments(64) if with_moments else None
    pre = prefilter.Prefiltered(
        tuple(levels),
        np.asarray(policy.ROUGHNESS_LEVELS),
        0,
        tuple(moments) if with_moments else None,
    )
    item = tilted_quad_item(gd, table, lighting)
    item.prefiltered = gd.resources.PrefilterTexture.from_levels(levels, moments)
    item.roughness, item.sh_weight = result.material.roughness, weight
    (group,) = gd.draw.prepare_draw([item], VIEW, PROJ, display_srgb=False).groups
    assert group.variant[4] and group.variant[6] == (weight == 0.0), group.variant
    image = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE)

    inside, n, views = quad_pixels(item.model_matrix)
    reads_moment = policy.uses_moment(l_max, weight == 0.0)
    assert reads_moment == (weight == 0.0 or l_max >= policy.MOMENT_MIN_L)
    used = pre if reads_moment else dataclasses.replace(pre, moments=None)
    sh_half = sh_sum.shade_sh(result, lighting.coefficients, n, views)
    expected = (1.0 - weight) * split_sum.shade_split_sum(result, used, n, views) + weight * sh_half
    err = np.max(np.abs(image[inside][:, :3] - expected)) / np.max(expected)
    # float32 shading plus hardware bilinear filtering of the prefiltered levels (llvmpipe's is
    # exact to 6e-8 in weights): 1e-4 of the peak, as for the SH path.
    assert inside.sum() > 300 and err < 1e-4, err
    if with_moments:  # the other choice of albedo angle is told apart at this tolerance
        other = pre if not reads_moment else dataclasses.replace(pre, moments=None)
        wrong = (1.0 - weight) * split_sum.shade_split_sum(result, other, n, views) + weight * sh_half
        assert np.max(np.abs(wrong - expected)) / np.max(expected) > 1e-3


@pytest.mark.parametrize(
    "colour_mode, weight, split, film_ubo",
    [
        ("spectral", 0.5, True, True),
        ("spectral", 0.5, True, False),
        ("per_channel", 0.0, True, True),
        ("spectral", 1.0, False, True),
        ("per_channel", 1.0, False, False),
    ],
)
def test_lamps_variant_matches_numpy_per_pixel(gd, colour_mode, weight, split, film_ubo):
    """tf_lamps.glsl against lamp_shading.shade with the weights of split_sum.shade_combined.

    The World gets two small suns (so precompute.world.lamps.extract finds lamps); the SH and the
    prefiltered levels are those of the World without them, the lamps are shaded per light
    direction with the film table (uniform buffer, or the texture). Split: the lamps' weight
    follows the level blend (split_sum.lamp_weight_at); SH alone (no prefiltered World): weight 1.
    """
    from precompute.sh import projection
    from precompute.world import lamps, prefilter

    result = baked(5, colour_mode, False)
    table = gd.resources.TableTexture.from_result(result)
    _world, img = world_sh()
    img = img.copy()
    img[6, 40] = (4e4, 3.8e4, 3e4)
    img[20, 10] = (1.5e4, 2e4, 2.6e4)
    found, mask = lamps.extract(img)
    assert found.count == 2
    rest_coeffs = projection.project_equirect(lamps.remove(img, mask), 12)
    lighting = gd.resources.Lighting.from_sh(rest_coeffs, 5, result.material.roughness, found)
    film = film_colour.film_table(result)
    full = prefilter.prefilter(img, width=64, lamp_mask=mask)
    levels, moments = full.resampled(64), full.resampled_moments(64)
    pre = prefilter.Prefiltered(
        tuple(levels), np.asarray(policy.ROUGHNESS_LEVELS), 0, tuple(moments), full.lamp_weights
    )
    item = tilted_quad_item(gd, table, lighting)
    item.prefiltered = gd.resources.PrefilterTexture.from_levels(levels, moments) if split else None
    item.roughness, item.sh_weight = result.material.roughness, weight
    item.film = gd.resources.FilmTexture.from_film(film)
    if not film_ubo:  # the texture path (tables too large for the uniform buffer)
        item.film = dataclasses.replace(item.film, ubo=None)
    (group,) = gd.draw.prepare_draw([item], VIEW, PROJ, display_srgb=False).groups
    assert group.variant[7] and group.variant[4] == split and group.variant[8] == film_ubo, group.variant
    image = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE)

    inside, n, views = quad_pixels(item.model_matrix)
    lit = lamp_shading.shade(film, found, result.material.roughness, n, views)
    expected = sh_sum.shade_sh(result, lighting.coefficients, n, views)
    if split:
        cos_o = np.clip(np.sum(n * views, -1), 0.0, 1.0)
        lamp_w = split_sum.lamp_weight_at(pre, policy.effective_roughness(result.material.roughness, cos_o))
        if not policy.uses_moment(5, weight == 0.0):  # l = 5 below MOMENT_MIN_L
            pre = dataclasses.replace(pre, moments=None)
        expected = (1.0 - weight) * split_sum.shade_split_sum(result, pre, n, views) + weight * expected
        lit = (weight + (1.0 - weight) * lamp_w)[:, None] * lit
    assert np.max(lit) > 0.05 * np.max(expected)  # the lamps show
    expected = expected + lit
    err = np.max(np.abs(image[inside][:, :3] - expected)) / np.max(expected)
    print(f"lamps variant {colour_mode} weight {weight} split {split} ubo {film_ubo}: {err:.1e} of the peak")
    assert inside.sum() > 300 and err < 1e-4, err


@pytest.mark.parametrize(
    "weight, l_max, angles, scale",
    [
        (0.0, 5, (0.0, 0.0, 40.0), 2.5),  # a Mapping rotation about z, Strength 2.5
        (0.5, 6, (20.0, -35.0, 70.0), 0.7),  # any rotation
    ],
)
def test_turned_and_scaled_prefilter_lookup_matches_numpy_per_pixel(gd, weight, l_max, angles, scale):
    """The World's rotation and strength applied at the lookup (tf_lighting.world: the levels of
    the content read at Q d, scaled; the moment turned back by Qᵀ) against
    split_sum.shade_split_sum with ``Prefiltered.transformed`` (issue 16: a Strength or rotation
    edit recomputes no prefilter)."""
    from precompute.world import prefilter

    result = baked(l_max, "spectral", False)
    table = gd.resources.TableTexture.from_result(result)
    world, img = world_sh()
    q = rotation(0, angles[0])[:3, :3] @ rotation(1, angles[1])[:3, :3] @ rotation(2, angles[2])[:3, :3]
    lighting = gd.resources.Lighting.from_sh(world, l_max, result.material.roughness, None, q, scale)
    full = prefilter.prefilter(img, width=64)
    levels, moments = full.resampled(64), full.resampled_moments(64)
    pre = prefilter.Prefiltered(tuple(levels), np.asarray(policy.ROUGHNESS_LEVELS), 0, tuple(moments))
    item = tilted_quad_item(gd, table, lighting)
    item.prefiltered = gd.resources.PrefilterTexture.from_levels(levels, moments)
    item.roughness, item.sh_weight = result.material.roughness, weight
    image = gd.draw.render_offscreen([item], VIEW, PROJ, SIZE, SIZE)
    inside, n, views = quad_pixels(item.model_matrix)
    used = pre if policy.uses_moment(l_max, weight == 0.0) else dataclasses.replace(pre, moments=None)
    sh_half = sh_sum.shade_sh(result, lighting.coefficients, n, views) if weight > 0.0 else 0.0
    turned = used.transformed(q, scale)
    expected = (1.0 - weight) * split_sum.shade_split_sum(result, turned, n, views) + weight * sh_half
    err = np.max(np.abs(image[inside][:, :3] - expected)) / np.max(expected)
    # as the unturned split sum, plus the turn in float32 before the lookup's atan/acos (whose
    # llvmpipe error, ≈ 1e-4 of the peak, lands on other texels once turned): 2e-4 of the peak
    assert inside.sum() > 300 and err < 2e-4, err
    unturned = (1.0 - weight) * split_sum.shade_split_sum(result, used, n, views) + weight * sh_half
    assert np.max(np.abs(unturned - expected)) / np.max(expected) > 1e-2  # the turn shows
