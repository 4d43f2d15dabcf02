"""Properties that keep the viewport's per-frame work small (never timings: those are in
benchmarks/viewport/ and docs/performance.md).

- Repeated frames with nothing changed allocate and upload no uniform buffer, compile no shader
  variant and rebuild no batch; an edit rebuilds exactly the edited object's batch.
- A moving view recycles uniform buffers instead of allocating one per frame.
- Draws are grouped by shader variant: one bind per variant, whatever the item order.
- Small tables drawn from a uniform buffer (TF_TABLE_UBO) shade like the texture and numpy.
- The cheaper rotation paths of the fast shading library (l ≤ 2 straight from the frame) give
  the z-y-z result (orders not covered by tests/drawing/test_gpu_draw.py).
"""

from __future__ import annotations

import types

import numpy as np
import pytest

pytestmark = pytest.mark.blender

from _extension import registered_extension  # noqa: E402

from precompute.bakes import bake  # noqa: E402
from precompute.materials.material import Layer, Material, Quality  # noqa: E402
from precompute.sh import projection  # noqa: E402
from precompute.shading import frame as shading_frame  # noqa: E402
from precompute.shading import sh_rotation, sh_sum  # noqa: E402
from precompute.shading.variant import Variant  # noqa: E402


@pytest.fixture(scope="module")
def tf(bpy, tmp_path_factory):
    """The extension, registered once for the module, with a private table cache."""
    root = tmp_path_factory.mktemp("extension")
    modules = (
        "addon",
        "addon.drawing.scene_draw",
        "addon.materials.props",
        "addon.materials.conversion",
        "addon.ui.prefs",
    )
    with registered_extension(bpy, root, modules, cache_preference=True, gpu=True) as ns:
        yield ns


FILM = Material(
    layers=(Layer(1.33, 400.0),),
    substrate=1.5,
    roughness=0.6,
    quality=Quality(sh_order=2, view_samples=8, wavelength_count=32),
)


def world_coefficients(l_max: int = 8) -> np.ndarray:
    """A smooth, mostly positive environment (sky gradient plus a soft sun), projected."""
    h, w = 32, 64
    el = np.pi * (0.5 - (np.arange(h) + 0.5) / h)
    phi = 2 * np.pi * (0.5 - (np.arange(w) + 0.5) / w)
    phi, el = np.meshgrid(phi, el)
    d = np.stack([np.cos(el) * np.cos(phi), np.cos(el) * np.sin(phi), np.sin(el)], -1)
    sun = np.exp(6.0 * (d @ np.array([0.48, -0.6, 0.64]) - 1.0))
    img = (
        0.3 + 0.2 * d[..., 2:3] * np.array([0.6, 0.8, 1.0]) + 3.0 * sun[..., None] * np.array([1.0, 0.9, 0.7])
    )
    return projection.project_equirect(img, l_max)


def look_at(eye, target=(0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0)) -> np.ndarray:
    eye, target, up = (np.asarray(x, dtype=float) for x in (eye, target, up))
    back = eye - target
    back /= np.linalg.norm(back)
    right = np.cross(up, back)
    right /= np.linalg.norm(right)
    world = np.eye(4)
    world[:3, 0], world[:3, 1], world[:3, 2], world[:3, 3] = right, np.cross(back, right), back, eye
    return np.linalg.inv(world)


def perspective(fov_deg=40.0, near=0.1, far=100.0) -> np.ndarray:
    f = 1.0 / np.tan(np.radians(fov_deg) / 2)
    return np.array(
        [
            [f, 0, 0, 0],
            [0, f, 0, 0],
            [0, 0, (far + near) / (near - far), 2 * far * near / (near - far)],
            [0, 0, -1, 0],
        ]
    )


VIEW = look_at((0.0, -5.0, 1.0))
PROJ = perspective()


class Item:
    def __init__(self, batch, table, lighting, offset=0.0):
        self.batch, self.table, self.lighting = batch, table, lighting
        self.model_matrix = np.eye(4)
        self.model_matrix[0, 3] = offset


def quad_batch(gd):
    pos = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], dtype=np.float32)
    nor = np.tile([0.0, -1.0, 0.0], (4, 1))
    return gd.mesh.MeshBatch.from_arrays(pos, nor, [[0, 1, 2], [0, 2, 3]])


@pytest.fixture(scope="module")
def drawn(tf):
    """Items of two shader variants (spectral l ≤ 2 and per-channel l ≤ 1) for the draw tests."""
    gd = tf.gpu
    world = world_coefficients()
    spectral = bake.bake(FILM)
    per_channel = bake.bake(
        FILM.with_(
            colour_mode="per_channel", quality=Quality(sh_order=1, view_samples=8, wavelength_count=32)
        )
    )
    tables = [gd.resources.TableTexture.from_result(r) for r in (spectral, per_channel)]
    lightings = [
        gd.resources.Lighting.from_sh(world, r.sh_order, r.material.roughness)
        for r in (spectral, per_channel)
    ]
    batch = quad_batch(gd)
    items = [Item(batch, tables[k % 2], lightings[k % 2], offset=0.5 * k) for k in range(6)]
    return types.SimpleNamespace(items=items, tables=tables, lightings=lightings)


def frame(gd, items, view=VIEW, **kwargs):
    import gpu

    offscreen = gpu.types.GPUOffScreen(32, 32)
    try:
        with offscreen.bind():
            gpu.state.active_framebuffer_get().clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            prepared = gd.draw.prepare_draw(items, view, PROJ, display_srgb=True, **kwargs)
            gd.draw.submit(prepared)
    finally:
        offscreen.free()
    return prepared


# ----------------------------------------------------------------------------------------------
# Uniform buffers, shader variants, grouping
# ----------------------------------------------------------------------------------------------
def test_unchanged_frames_allocate_and_upload_no_uniform_buffer(tf, drawn):
    gd = tf.gpu
    uniforms = gd.resources.UniformCache()
    shaders = gd.shaders.ShaderCache()
    frame(gd, drawn.items, uniforms=uniforms, shaders=shaders)
    after_first = dict(uniforms.stats)
    # One view buffer and one per distinct object matrix (the six items all differ).
    assert after_first["allocations"] == 1 + len(drawn.items) and after_first["uploads"] == 0
    compiled = shaders.compile_count
    assert compiled == 2  # the two variants, each compiled once
    for _ in range(5):
        frame(gd, drawn.items, uniforms=uniforms, shaders=shaders)
    assert uniforms.stats["allocations"] == after_first["allocations"]
    assert uniforms.stats["uploads"] == 0
    assert uniforms.stats["hits"] == after_first["hits"] + 5 * (1 + len(drawn.items))
    assert shaders.compile_count == compiled
    assert len(uniforms) == 1 + len(drawn.items)


def test_a_moving_view_recycles_uniform_buffers(tf, drawn):
    gd = tf.gpu
    uniforms = gd.resources.UniformCache(keep_frames=3)
    frames = 20
    for k in range(frames):
        frame(gd, drawn.items[:1], view=look_at((0.1 * k, -5.0, 1.0)), uniforms=uniforms)
    # The object buffer is made once; view buffers are allocated only until the first ones
    # have aged out (keep_frames), then recycled by updating them.
    allocations = uniforms.stats["allocations"]
    assert allocations <= 1 + uniforms.keep_frames + 1
    assert allocations + uniforms.stats["uploads"] == 1 + frames
    assert len(uniforms) <= 1 + uniforms.keep_frames + 1  # only recent entries are kept


def test_an_unused_entry_is_dropped_and_its_buffer_reused(tf):
    gd = tf.gpu
    uniforms = gd.resources.UniformCache(keep_frames=1)
    data = np.arange(8, dtype=np.float32)
    first = uniforms.get("a", lambda: data)
    uniforms.next_frame()
    assert uniforms.get("a", lambda: data + 1) is first  # still cached: made once
    uniforms.next_frame()
    uniforms.next_frame()
    assert len(uniforms) == 0
    assert uniforms.get("b", lambda: data + 2) is first  # recycled, updated in place
    assert uniforms.stats == {"allocations": 1, "uploads": 1, "hits": 1}


def test_draws_are_grouped_by_variant_in_item_order(tf, drawn):
    gd = tf.gpu
    items = drawn.items  # variants alternate A, B, A, B, A, B
    prepared = frame(gd, items, uniforms=gd.resources.UniformCache())
    assert prepared.draw_count == len(items)
    assert len(prepared.groups) == 2 and prepared.shader_binds == 2
    first, second = prepared.groups
    assert first.table is drawn.tables[0].ubo and second.table is drawn.tables[1].ubo  # small: UBO tables
    assert [b for b, *_ in first.draws] == [items[k].batch.batch for k in (0, 2, 4)]
    # An empty list prepares nothing and submits nothing.
    assert gd.draw.prepare_draw([], VIEW, PROJ, display_srgb=True).groups == []


def test_grouping_does_not_change_the_image(tf, drawn):
    """Items drawn in groups give the image of drawing them one call each (apart from the order
    of coplanar overlaps, which grouping may change: these quads do not overlap)."""
    import gpu

    gd = tf.gpu
    items = [Item(it.batch, it.table, it.lighting, offset=2.2 * k - 5.5) for k, it in enumerate(drawn.items)]
    view = look_at((0.0, -20.0, 2.0))
    images = []
    for batches in ([items], [[it] for it in items]):
        offscreen = gpu.types.GPUOffScreen(48, 48, format="RGBA32F")
        try:
            with offscreen.bind():
                fb = gpu.state.active_framebuffer_get()
                fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
                for group in batches:
                    gd.draw.draw_items(group, view, PROJ, display_srgb=False)
                images.append(gd.draw.read_framebuffer(fb, 48, 48))
        finally:
            offscreen.free()
    assert np.mean(images[0][..., 3] > 0.5) > 0.05  # all six quads are in view
    # The same shader on the same inputs: float32 rounding at most on any GPU; a film drawn with
    # another's table or lighting differs by ≫ 1e-6.
    np.testing.assert_allclose(
        images[1], images[0], rtol=0, atol=1e-6, err_msg="grouped draws against one draw call per item"
    )


# ----------------------------------------------------------------------------------------------
# Batches through scene_draw.collect
# ----------------------------------------------------------------------------------------------
def test_collect_rebuilds_no_batch_until_the_mesh_changes(tf, bpy):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    tf.package.register()
    tf.prefs.preferences().cache_dir = tf.cache_dir
    scene = bpy.context.scene  # no World: lit by nothing, no panorama to render
    meshes = []
    for k in range(3):
        mesh = bpy.data.meshes.new(f"film{k}")
        mesh.from_pydata([(-1, 0, -1), (1, 0, -1), (1, 0, 1), (-1, 0, 1)], [], [(0, 1, 2, 3)])
        mat = bpy.data.materials.new(f"film{k}")
        tf.conversion.fill_from_material(mat.thinfilm_sh, FILM)
        mat.thinfilm_sh.sh_order = "2"
        mat.thinfilm_sh.view_samples = 8
        mat.thinfilm_sh.wavelength_count = 32
        mat.thinfilm_sh.enabled = True
        mesh.materials.append(mat)
        obj = bpy.data.objects.new(f"film{k}", mesh)
        obj.location.x = 2.5 * k
        scene.collection.objects.link(obj)
        meshes.append(mesh)
    bpy.context.view_layer.update()
    sd = tf.scene_draw
    stats = sd.CACHES.stats

    def collect():
        items = sd.collect(bpy.context.evaluated_depsgraph_get())[0]
        return {item.name.split("/")[0]: item for item in items}

    builds = stats["batch_builds"]
    items = collect()
    assert sorted(items) == ["film0", "film1", "film2"] and stats["batch_builds"] == builds + 3
    builds = stats["batch_builds"]
    for _ in range(5):
        again = collect()
    assert stats["batch_builds"] == builds
    assert all(again[name].batch is items[name].batch for name in items)  # the same MeshBatch objects

    # Moving an object changes only its matrix: no rebuild.
    scene.objects["film1"].location.z = 0.3
    bpy.context.view_layer.update()
    moved = collect()
    assert stats["batch_builds"] == builds
    assert moved["film1"].model_matrix[2, 3] == pytest.approx(0.3)
    assert moved["film1"].batch is items["film1"].batch

    # Editing a mesh rebuilds that object's batch, once.
    meshes[2].vertices[0].co.y = 0.2
    meshes[2].update()
    bpy.context.view_layer.update()
    edited = collect()
    assert stats["batch_builds"] == builds + 1
    assert edited["film2"].batch is not items["film2"].batch
    assert edited["film0"].batch is items["film0"].batch
    collect()
    assert stats["batch_builds"] == builds + 1


def test_collect_splits_a_mesh_by_material_slot(tf, bpy):
    """Two film materials on one mesh: one batch each, with that slot's faces only (the faces'
    material indices and the triangles' faces are read as arrays, not item by item)."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    tf.package.register()
    tf.prefs.preferences().cache_dir = tf.cache_dir
    scene = bpy.context.scene
    mesh = bpy.data.meshes.new("two slots")
    verts = [(x, 0.0, z) for z in (0.0, 1.0) for x in (0.0, 1.0, 2.0, 3.0)]
    mesh.from_pydata(verts, [], [(0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6)])  # three quads
    for k in range(2):
        mat = bpy.data.materials.new(f"slot{k}")
        tf.conversion.fill_from_material(mat.thinfilm_sh, FILM.with_(roughness=0.6 + 0.1 * k))
        mat.thinfilm_sh.sh_order = "2"
        mat.thinfilm_sh.view_samples = 8
        mat.thinfilm_sh.wavelength_count = 32
        mat.thinfilm_sh.enabled = True
        mesh.materials.append(mat)
    mesh.polygons[1].material_index = 1
    scene.collection.objects.link(bpy.data.objects.new("two slots", mesh))
    bpy.context.view_layer.update()
    items = tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())[0]
    by_slot = {item.name.split("/")[1]: item for item in items}
    assert sorted(by_slot) == ["slot0", "slot1"]
    assert by_slot["slot0"].batch.triangle_count == 4 and by_slot["slot1"].batch.triangle_count == 2
    assert by_slot["slot0"].roughness != by_slot["slot1"].roughness


def test_a_smooth_constant_film_is_batched_per_vertex(tf, bpy):
    """A film of constant thickness on a mesh shaded smooth is batched one row per vertex (its
    corners share them: a quarter of the rows of a quad mesh to read and upload); shaded flat it
    is batched per corner again, after the depsgraph update rebuilds it."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    tf.package.register()
    tf.prefs.preferences().cache_dir = tf.cache_dir
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16)
    obj = bpy.context.active_object
    mat = bpy.data.materials.new("smooth film")
    tf.conversion.fill_from_material(mat.thinfilm_sh, FILM)
    mat.thinfilm_sh.sh_order, mat.thinfilm_sh.view_samples, mat.thinfilm_sh.wavelength_count = "2", 8, 32
    mat.thinfilm_sh.enabled = True
    obj.data.materials.append(mat)
    obj.data.shade_smooth()
    bpy.context.view_layer.update()

    def batch():
        items = tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())[0]
        assert len(items) == 1
        return items[0].batch

    smooth = batch()
    assert smooth.vertex_count == len(obj.data.vertices) == 32 * 15 + 2
    assert smooth.triangle_count == len(obj.data.loop_triangles) == 32 * 14 * 2 + 64
    obj.data.shade_flat()
    bpy.context.view_layer.update()
    flat = batch()
    assert flat is not smooth and flat.vertex_count == len(obj.data.loops)
    assert flat.triangle_count == smooth.triangle_count


@pytest.mark.parametrize("shape", ["jittered_subdivided", "mixed", "uv_sphere", "ngons"])
def test_triangle_corners_are_blenders_loop_triangles(tf, bpy, shape):
    """``mesh.triangle_corners`` (worked out from the faces, 145 → 80 ms at 1.6 M triangles)
    equals ``loop_triangles.foreach_get("loops")`` corner for corner: quads only (a Subdivision
    Surface over a grid jittered so that quads fold: Blender splits them along their other
    diagonal), triangles and quads with folded ones among them, a UV sphere (triangles at its
    poles), and n-gons (read from Blender). Every mesh's batch draws those triangles."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    rng = np.random.default_rng(7)
    if shape == "jittered_subdivided":
        bpy.ops.mesh.primitive_grid_add(x_subdivisions=40, y_subdivisions=40, size=2.0)
        obj = bpy.context.active_object
        co = np.empty(3 * len(obj.data.vertices), dtype=np.float32)
        obj.data.vertices.foreach_get("co", co)
        co += rng.normal(0.0, 0.02, co.size).astype(np.float32)  # about half a cell
        obj.data.vertices.foreach_set("co", co)
        obj.modifiers.new("subdivide", "SUBSURF").levels = 1
    elif shape == "mixed":
        verts = [(x, y, 0.3 * rng.random()) for y in range(6) for x in range(6)]
        faces = []
        for y in range(5):
            for x in range(5):
                a, b, c, d = 6 * y + x, 6 * y + x + 1, 6 * y + x + 7, 6 * y + x + 6
                faces += [(a, b, c), (a, c, d)] if x == 0 or y == 4 else [(a, b, c, d)]
        verts[14] = (2.6, 1.4, 0.0)  # inside the quad of 8, 9, 15: concave there, so it folds
        mesh = bpy.data.meshes.new("mixed")
        mesh.from_pydata(verts, [], faces)
        obj = bpy.data.objects.new("mixed", mesh)
        bpy.context.scene.collection.objects.link(obj)
    elif shape == "uv_sphere":
        bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16)
        obj = bpy.context.active_object
    else:
        bpy.ops.mesh.primitive_cylinder_add(vertices=12)  # 12-sided caps
        obj = bpy.context.active_object
    mesh = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    mesh.calc_loop_triangles()
    blender = np.empty(3 * len(mesh.loop_triangles), dtype=np.int32)
    mesh.loop_triangles.foreach_get("loops", blender)
    ours = tf.gpu.mesh.triangle_corners(mesh)
    assert ours.dtype == np.int32 and ours.shape == (len(mesh.loop_triangles), 3)
    np.testing.assert_array_equal(ours.ravel(), blender)
    np.testing.assert_array_equal(tf.gpu.mesh.mesh_arrays(mesh)[2], ours)
    if shape in ("jittered_subdivided", "mixed"):  # the other diagonal was taken, and matched
        loops = np.sort(ours, axis=1)
        flipped = (loops[:, 2] - loops[:, 0] == 3) & (loops[:, 1] - loops[:, 0] == 1)
        assert flipped.sum() >= 1, flipped.sum()  # measured: 3 (subdivided) and 1 (mixed)


# ----------------------------------------------------------------------------------------------
# The cheaper rotation of the fast library against numpy (l = 1, 2)
# ----------------------------------------------------------------------------------------------
LOCAL_FRAGMENT = """
void main()
{
  ivec2 p = ivec2(gl_FragCoord.xy);
  int i = p.x / 4; /* kept coefficient */
  int px = p.x % 4 + 4 * p.y;
  vec3 n = normalize(texelFetch(tf_test_normal, ivec2(px, 0), 0).xyz);
  vec3 v = normalize(texelFetch(tf_test_view, ivec2(px, 0), 0).xyz);
  TFFrame f = tf_view_aligned_frame(n, v);
  tf_local_coefficients_direct(f);
  vec3 c = tf_c[0];
  if (i == 1) { c = tf_c[2]; }
  if (i == 2) { c = tf_c[3]; }
#if TF_L_MAX >= 2
  if (i == 3) { c = tf_c[6]; }
  if (i == 4) { c = tf_c[7]; }
  if (i == 5) { c = tf_c[8]; }
#endif
  tf_frag_color = vec4(c, 1.0);
}
"""


@pytest.mark.parametrize("l_max", [1, 2])
def test_direct_low_band_rotation_matches_numpy(tf, l_max):
    """tf_local_coefficients_direct gives render.local_coefficients' kept coefficients (float32)."""
    import gpu

    gd = tf.gpu
    rng = np.random.default_rng(7 + l_max)
    count = 64  # 4 × 16 pixels per coefficient column block
    n = rng.normal(size=(count, 3))
    v = rng.normal(size=(count, 3))
    # Poles (and next to one: the z-y-z angles' gimbal case), and v = n exactly (both take the
    # fallback tangent; for v nearly ∥ n float32 and float64 may pick different, equally valid
    # tangents, which changes the m > 0 coefficients but not the shading).
    n[:5] = [[0, 0, 1], [0, 0, -1], [1e-8, 0, 1], [0.6, 0.0, 0.8], [0, 0, -1]]
    v[:5] = [[0.3, 0.4, 0.9], [0.2, -0.1, -0.9], [0.3, 0.2, 0.9], [0.6, 0.0, 0.8], [0, 0, -1]]
    n = (n / np.linalg.norm(n, axis=-1, keepdims=True)).astype(np.float32)
    v = (v / np.linalg.norm(v, axis=-1, keepdims=True)).astype(np.float32)
    v = np.where(np.sum(n * v, -1, keepdims=True) < 0, -v, v)
    world = world_coefficients(l_max)
    lighting = gd.resources.Lighting.from_sh(world, l_max, 0.6)

    info = gpu.types.GPUShaderCreateInfo()
    gd.shaders.declare_shading_resources(info, Variant(l_max, True, False, False))
    info.sampler(1, "FLOAT_2D", "tf_test_normal")
    info.sampler(2, "FLOAT_2D", "tf_test_view")
    info.vertex_in(0, "VEC2", "pos")
    info.fragment_out(0, "VEC4", "tf_frag_color")
    info.vertex_source("void main() { gl_Position = vec4(pos, 0.0, 1.0); }")
    info.fragment_source(gd.shaders.shading_library(l_max) + LOCAL_FRAGMENT)
    shader = gpu.shader.create_from_info(info)

    def texture(vectors):
        data = np.zeros((1, count, 4), dtype=np.float32)
        data[0, :, :3] = vectors
        return gpu.types.GPUTexture((count, 1), format="RGBA32F", data=gd.resources.float_buffer(data))

    kept = [0, 2, 3, 6, 7, 8][: (l_max + 1) * (l_max + 2) // 2]
    width, height = 4 * len(kept), count // 4
    tex_n, tex_v = texture(n), texture(v)
    offscreen = gpu.types.GPUOffScreen(width, height, format="RGBA32F")
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0.0, 0.0, 0.0, 0.0))
            shader.bind()
            shader.uniform_block("tf_lighting", lighting.ubo)
            shader.uniform_sampler("tf_test_normal", tex_n)
            shader.uniform_sampler("tf_test_view", tex_v)
            gd.draw._fullscreen_triangle().draw(shader)
            out = gd.draw.read_framebuffer(fb, width, height)[::-1]  # row 0 = gl_FragCoord.y 0
    finally:
        offscreen.free()
    got = out[..., :3].reshape(height, len(kept), 4, 3).transpose(0, 2, 1, 3).reshape(count, len(kept), 3)
    frames = shading_frame.view_aligned_frame(n.astype(float), v.astype(float))
    expected = sh_rotation.local_coefficients(lighting.coefficients, frames, l_max)[:, kept]
    scale = np.max(np.abs(expected))
    # float32 maths of the same rotation: a few ulps of the largest coefficient.
    assert np.max(np.abs(got - expected)) / scale < 2e-6


# ----------------------------------------------------------------------------------------------
# The table as a uniform buffer (TF_TABLE_UBO) against numpy and against the texture
# ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def gpu_helpers(tf):
    """tests/drawing/test_gpu_draw.py's bakes, World and shading inputs (no tests are imported)."""
    import test_gpu_draw

    return test_gpu_draw


def test_uniform_table_layout_and_size_limit(tf, gpu_helpers):
    gd = tf.gpu
    result = gpu_helpers.baked(2, "per_channel", True)  # 8 rows × 16 views × 6 layers: fits
    layers = gd.resources.TableTexture.layer_array(result.data)
    packed = gd.resources.TableTexture.uniform_array(layers)
    n_layers, t, a = layers.shape[:3]
    assert packed.shape == (1024, 4) and packed.nbytes == gd.layout.UBO_LIMIT_BYTES
    assert tuple(packed[0, :3]) == (a, t, n_layers)
    row, column, layer = 5, 7, 4
    assert np.array_equal(packed[1 + (row * a + column) * n_layers + layer], layers[layer, row, column])
    assert np.all(packed[1 + n_layers * t * a :] == 0)
    table = gd.resources.TableTexture.from_result(result, uniform=True)
    assert table.ubo is not None
    assert gd.resources.TableTexture.from_result(result, uniform=False).ubo is None
    big = gpu_helpers.baked(8, "spectral", False)  # 135 layers × 16 views > 1023 texels
    assert gd.resources.TableTexture.uniform_array(gd.resources.TableTexture.layer_array(big.data)) is None
    assert gd.resources.TableTexture.from_result(big).ubo is None


def test_table_uniform_buffer_only_on_software_rasterisers(tf, gpu_helpers):
    # policy.TABLE_UBO_DEVICES: the per-pixel-indexed uniform buffer was measured faster than
    # the texture on llvmpipe and 2-4x slower on an NVIDIA H100 (docs/gpu-frame.md); GPUs not
    # measured get the texture. The default of from_result follows the device Blender draws with.
    import gpu

    gd = tf.gpu
    assert gd.resources.uses_table_ubo("SOFTWARE") and gd.resources.uses_table_ubo("software")
    for device in ("NVIDIA", "AMD", "INTEL", "APPLE", "UNKNOWN"):
        assert not gd.resources.uses_table_ubo(device)
    device = gpu.platform.device_type_get()
    assert gd.resources.table_ubo_preferred() == gd.resources.uses_table_ubo(device)
    result = gpu_helpers.baked(2, "per_channel", True)  # fits the uniform buffer
    assert (gd.resources.TableTexture.from_result(result).ubo is not None) == gd.resources.uses_table_ubo(
        device
    )


@pytest.mark.parametrize(
    "l_max, colour_mode, thickness",
    [(2, "spectral", "constant"), (2, "per_channel", "varying"), (5, "spectral", "constant")],
)
def test_uniform_table_shading_matches_numpy(tf, gpu_helpers, l_max, colour_mode, thickness):
    """tf_shade with TF_TABLE_UBO against sh_sum.shade_sh, as tests/drawing/test_gpu_draw.py does for the
    texture (same bounds: float32 maths of the same interpolation)."""
    import gpu

    gd, h = tf.gpu, gpu_helpers
    vary = thickness == "varying"
    result = h.baked(l_max, colour_mode, vary)
    table = gd.resources.TableTexture.from_result(result)
    assert table.ubo is not None
    world, _img = h.world_sh()
    lighting = gd.resources.Lighting.from_sh(world, l_max, result.material.roughness)
    width, height = 32, 16
    n, v, t01 = h.shading_inputs(width * height, seed=l_max)

    info = gpu.types.GPUShaderCreateInfo()
    gd.shaders.declare_shading_resources(info, Variant(l_max, table.spectral, vary, False, table_ubo=True))
    info.sampler(1, "FLOAT_2D", "tf_test_normal")
    info.sampler(2, "FLOAT_2D", "tf_test_view")
    info.vertex_in(0, "VEC2", "pos")
    info.fragment_out(0, "VEC4", "tf_frag_color")
    info.vertex_source(h.TEST_VERTEX)
    info.fragment_source(gd.shaders.shading_library(l_max) + h.TEST_FRAGMENT)
    shader = gpu.shader.create_from_info(info)

    def texture(rgb, w):
        data = np.zeros((height, width, 4), dtype=np.float32)
        data[..., :3] = rgb.reshape(height, width, 3)
        data[..., 3] = w.reshape(height, width)
        return gpu.types.GPUTexture((width, height), format="RGBA32F", data=gd.resources.float_buffer(data))

    tex_n, tex_v = texture(n, t01), texture(v, np.zeros(width * height))
    offscreen = gpu.types.GPUOffScreen(width, height, format="RGBA32F")
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0.0, 0.0, 0.0, 0.0))
            shader.bind()
            shader.uniform_block("tf_lighting", lighting.ubo)
            shader.uniform_block("tf_table_data", table.ubo)
            shader.uniform_sampler("tf_test_normal", tex_n)
            shader.uniform_sampler("tf_test_view", tex_v)
            gd.draw._fullscreen_triangle().draw(shader)
            got = gd.draw.read_framebuffer(fb, width, height)[::-1].reshape(-1, 4)[:, :3]
    finally:
        offscreen.free()
    lo, hi = h.THICKNESS_RANGE
    expected = sh_sum.shade_sh(result, lighting.coefficients, n, v, lo + t01 * (hi - lo) if vary else None)
    per_pixel = np.max(np.abs(got - expected), axis=-1) / np.max(np.abs(expected))
    assert per_pixel.max() <= 1e-4 and np.median(per_pixel) <= 2e-6, (per_pixel.max(), np.median(per_pixel))


def test_uniform_table_draws_the_image_of_the_texture(tf, gpu_helpers):
    """draw_items with the table in a uniform buffer and in the texture: the same pixels."""
    gd, h = tf.gpu, gpu_helpers
    result = h.baked(5, "spectral", False)
    world, _img = h.world_sh()
    lighting = gd.resources.Lighting.from_sh(world, 5, result.material.roughness)
    mesh_batch = quad_batch(gd)
    images = []
    for uniform in (True, False):
        table = gd.resources.TableTexture.from_result(result, uniform=uniform)
        assert (table.ubo is not None) == uniform
        item = Item(mesh_batch, table, lighting)
        item.model_matrix = np.array(
            [[1.0, 0.0, 0.0, 0.0], [0.0, 0.6, -0.8, 0.0], [0.0, 0.8, 0.6, 0.0], [0.0, 0.0, 0.0, 1.0]]
        )
        images.append(gd.draw.render_offscreen([item], VIEW, PROJ, 48, 48))
    assert np.mean(images[0][..., 3] > 0.5) > 0.1
    # Two shader variants (uniform buffer, texture) reading the same float32 values: rounding only.
    np.testing.assert_allclose(
        images[1],
        images[0],
        rtol=0,
        atol=1e-6,
        err_msg="the table read from its texture against its uniform buffer",
    )
