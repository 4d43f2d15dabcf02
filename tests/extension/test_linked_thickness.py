"""A Principled BSDF whose Thin Film Thickness is linked (issue 21): evaluated over the surface.

Real bpy, the repository imported as the extension (tests/_extension.py). The direct numpy
evaluation (Value, Image Texture, Separate Color, Mix, Map Range, Math) is checked against the
image's own pixels and against Blender's Cycles bake of the same link; a Noise Texture is baked,
cached by the node tree's content, and re-baked when its scale changes.
"""

import importlib
import os
import pathlib
import tempfile

import numpy as np
import pytest

pytestmark = pytest.mark.blender

from _extension import EXTENSION_ID  # noqa: E402

#: Cycles bakes the Emission into a float colour attribute: float32 storage of values in nm.
BAKE_TOLERANCE_NM = 1e-3


@pytest.fixture
def tf(bpy, package, tmp_path):
    """A fresh empty file with the extension registered; its modules as attributes."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    package.register()
    names = (
        "addon.materials.description",
        "addon.thickness.linked",
        "addon.thickness.generated",
        "addon.drawing.scene_draw",
        "addon.bakes.tables",
        "addon.ui.prefs",
        "addon.headless.headless",
        "addon.materials.principled",
        "addon.ui.ui",
        "addon.gpu.mesh",
    )
    mods = {n.rpartition(".")[2]: importlib.import_module(f"{EXTENSION_ID}.{n}") for n in names}
    entry = bpy.context.preferences.addons.new()
    entry.module = EXTENSION_ID
    mods["prefs"].preferences().cache_dir = str(tmp_path / "cache")
    mods["tables"].clear_memory_cache()
    mods["linked"].FIELDS.clear()
    importlib.import_module(f"{EXTENSION_ID}.addon.thickness.maps").MAPS.clear()
    try:
        yield type("TF", (), mods)
    finally:
        bpy.context.preferences.addons.remove(entry)
        package.unregister()
        mods["tables"].clear_memory_cache()


def _fast(tf, mat):
    """A tiny table: the tests check thicknesses, not colours."""
    node = tf.principled.principled_node(mat)
    node.inputs["Roughness"].default_value = 0.5
    return node


def _sphere(bpy, mat, name="Sphere"):
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12)
    obj = bpy.context.active_object
    obj.name = name
    obj.data.materials.append(mat)
    return obj


def _principled(bpy, name="Linked"):
    mat = bpy.data.materials.new(name)
    node = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    node.inputs["Transmission Weight"].default_value = 1.0
    return mat, node


def _noise_material(bpy, scale=5.0):
    """Noise Texture (its hidden mapping moved) → Map Range 150–850 nm → Thin Film Thickness
    (socket value 0): a graph the direct evaluator does not mirror (a mapped noise), so Cycles
    bakes it."""
    mat, node = _principled(bpy, "Noise")
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    noise = nodes.new("ShaderNodeTexNoise")
    noise.name = "Noise"
    noise.inputs["Scale"].default_value = scale
    noise.texture_mapping.translation = (0.25, 0.0, 0.0)
    ranged = nodes.new("ShaderNodeMapRange")
    ranged.inputs["To Min"].default_value = 150.0
    ranged.inputs["To Max"].default_value = 850.0
    links.new(noise.outputs["Fac"], ranged.inputs["Value"])
    links.new(ranged.outputs["Result"], node.inputs["Thin Film Thickness"])
    node.inputs["Thin Film Thickness"].default_value = 0.0
    return mat


def _grid_with_pixel_centre_uvs(bpy, width, height):
    """A flat grid with one vertex per pixel, its UV at that pixel's centre ((i + ½)/W, (j + ½)/H)."""
    verts = [(i, j, 0.0) for j in range(height) for i in range(width)]
    faces = [
        (j * width + i, j * width + i + 1, (j + 1) * width + i + 1, (j + 1) * width + i)
        for j in range(height - 1)
        for i in range(width - 1)
    ]
    mesh = bpy.data.meshes.new("Grid")
    mesh.from_pydata(verts, [], faces)
    uv = mesh.uv_layers.new(name="UVMap")
    corner_vertex = np.array([loop.vertex_index for loop in mesh.loops])
    centres = np.array([((i + 0.5) / width, (j + 0.5) / height) for (i, j, _) in verts])
    uv.data.foreach_set("uv", centres[corner_vertex].ravel().astype(np.float32))
    obj = bpy.data.objects.new("Grid", mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj, corner_vertex


def _batch_thickness_nm(bpy, tf, obj_name):
    items, messages = tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())
    entry = tf.scene_draw.batch_entry(obj_name)
    assert entry is not None and entry.thickness is not None, messages
    return entry, messages


def test_linked_constant_equals_the_unlinked_value(bpy, tf):
    """A Value node of 420 nm into Thin Film Thickness describes exactly what 420 nm typed into
    the socket describes: the same table key, no range (a constant), the same panel line."""
    plain, plain_node = _principled(bpy, "Plain")
    plain_node.inputs["Thin Film Thickness"].default_value = 420.0
    mat, node = _principled(bpy, "Linked")
    node.inputs["Thin Film Thickness"].default_value = 0.0  # the link decides, not this
    value = mat.node_tree.nodes.new("ShaderNodeValue")
    value.outputs[0].default_value = 420.0
    mat.node_tree.links.new(value.outputs[0], node.inputs["Thin Film Thickness"])
    _sphere(bpy, mat)
    linked_desc = tf.description.description(mat)
    plain_desc = tf.description.description(plain)
    assert linked_desc is not None and linked_desc.thickness_range_nm is None
    assert linked_desc.layers[0].thickness_nm == pytest.approx(420.0, abs=0.01)
    assert tf.description.description_key(linked_desc) == tf.description.description_key(plain_desc)
    notes = tf.description.warnings(mat)
    assert any("evaluated directly" in n and "face corners" in n for n in notes), notes


def test_image_driven_thickness_reproduces_the_image_at_the_vertices(bpy, tf):
    """Blender's glTF import graph (Image → Separate Color G → Mix(min, max)): the thickness at
    each vertex is min + G·(max − min) of the pixel the vertex's UV sits on; Cycles' bake of the
    same link agrees with the direct evaluation."""
    width, height, lo, hi = 6, 5, 120.0, 780.0
    rng = np.random.default_rng(3)
    green = rng.uniform(0.0, 1.0, (height, width))
    image = bpy.data.images.new("thick", width, height, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    rgba = np.zeros((height, width, 4), dtype=np.float32)
    rgba[..., 1], rgba[..., 0], rgba[..., 3] = green, 1.0 - green, 1.0  # red must not leak in
    image.pixels.foreach_set(rgba.ravel())
    image.pack()
    mat, node = _principled(bpy, "Image")
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = image
    sep = nodes.new("ShaderNodeSeparateColor")
    mix = nodes.new("ShaderNodeMix")
    vmin, vmax = nodes.new("ShaderNodeValue"), nodes.new("ShaderNodeValue")
    vmin.outputs[0].default_value, vmax.outputs[0].default_value = lo, hi
    links.new(tex.outputs["Color"], sep.inputs["Color"])
    links.new(sep.outputs["Green"], mix.inputs["Factor"])
    links.new(vmin.outputs[0], mix.inputs["A"])
    links.new(vmax.outputs[0], mix.inputs["B"])
    links.new(mix.outputs["Result"], node.inputs["Thin Film Thickness"])
    node.inputs["Thin Film Thickness"].default_value = 0.0
    obj, corner_vertex = _grid_with_pixel_centre_uvs(bpy, width, height)
    obj.data.materials.append(mat)

    desc = tf.description.description(mat)
    assert desc.thickness_range_nm is not None
    t0, t1 = desc.thickness_range_nm
    assert t0 == pytest.approx(lo + (hi - lo) * green.min(), abs=0.02)
    assert t1 == pytest.approx(hi - (hi - lo) * (1 - green.max()), abs=0.02)
    entry, _ = _batch_thickness_nm(bpy, tf, "Grid")
    drawn = t0 + entry.thickness.astype(np.float64) * (t1 - t0)
    expected = (lo + (hi - lo) * green.ravel())[corner_vertex]
    assert np.max(np.abs(drawn - expected)) < 0.05  # float32 parameter over a 660 nm range

    socket = node.inputs["Thin Film Thickness"]
    baked = tf.linked._bake(obj, mat, socket)
    direct = tf.linked.evaluate(obj, obj.data, mat, socket)
    assert not direct.baked and baked.baked
    assert np.max(np.abs(baked.values - direct.values)) < BAKE_TOLERANCE_NM * hi
    assert np.max(np.abs(direct.values - expected)) < 1e-4
    assert "6×5" in direct.how
    # per pixel: the map holds the graph at the image's pixels (its own size), at the grid's UVs
    found, why, waiting = tf.linked.linked_map(obj, obj.data, mat, socket)
    assert found is not None and why is None and not waiting
    assert found.values.shape == (height, width) and "6×5 map" in found.how
    assert np.max(np.abs(found.values - (lo + (hi - lo) * green))) < 1e-3
    assert entry.batch.thickness_map is not None


def test_a_noise_thickness_map_holds_the_noise_between_the_corners(bpy, tf):
    """On a coarse sphere (24 × 12) the Noise Texture is also baked into a map at the UVs: read
    at the corners of the same sphere subdivided twice (flat: the same surface, UVs interpolated),
    it gives what Cycles bakes at those corners, where the coarse corners alone cannot."""
    import bmesh  # Blender's mesh editing module

    mat = _noise_material(bpy, scale=5.0)
    coarse = _sphere(bpy, mat)
    bm = bmesh.new()  # triangles: subdividing one keeps its UV → surface map affine (a quad's
    bm.from_mesh(coarse.data)  # bilinear patch would put a UV elsewhere than its two triangles)
    bmesh.ops.triangulate(bm, faces=bm.faces[:])
    bm.to_mesh(coarse.data)
    bm.free()
    fine = coarse.copy()
    fine.data = coarse.data.copy()
    fine.name = "Fine"
    bpy.context.scene.collection.objects.link(fine)
    modifier = fine.modifiers.new("subdivide", "SUBSURF")
    modifier.subdivision_type, modifier.levels, modifier.render_levels = "SIMPLE", 2, 2
    socket = tf.principled.principled_node(mat).inputs["Thin Film Thickness"]
    depsgraph = bpy.context.evaluated_depsgraph_get()
    found, why, _ = tf.linked.linked_map(coarse, coarse.evaluated_get(depsgraph).data, mat, socket)
    assert found is not None, why
    assert "1024² Cycles bake" in found.how
    fine_mesh = fine.evaluated_get(depsgraph).data
    truth = tf.linked._bake(fine, mat, socket).values
    uv = tf.linked.linked_nodes.corner_uv(fine_mesh, fine_mesh.uv_layers.active)
    maps = importlib.import_module(f"{EXTENSION_ID}.addon.thickness.maps")
    read = maps.sample_bilinear(found.values, uv)
    span = np.ptp(truth)
    error = np.abs(read - truth)
    assert np.percentile(error, 99) < 0.01 * span, np.percentile(error, 99) / span
    assert found.lo <= truth.min() + 0.01 * span and found.hi >= truth.max() - 0.01 * span
    lo, hi = tf.description.description(mat).thickness_range_nm  # the table spans the map's peaks
    assert lo <= found.lo and hi >= found.hi
    entry, _ = _batch_thickness_nm(bpy, tf, "Sphere")
    assert entry.batch.thickness_map is not None


def test_the_draw_draws_the_corners_and_the_timer_makes_the_map_once_edits_settle(bpy, tf, monkeypatch):
    """Inside the draw a map is never made: the film is drawn per corner at once and the map is
    queued; the timer leaves it queued until the key has waited SETTLE_S (a slider being
    dragged: a newer field's map replaces the queued one), then makes it (a 1024² bake: ≈ 0.5 s
    of the main thread), and the next frame has it."""
    mat = _noise_material(bpy, scale=5.0)
    _sphere(bpy, mat)
    before = tf.linked.STATS["image_bakes"]
    with tf.linked.deferring():
        assert tf.description.description(mat) is None  # the corners' bake is queued first
    assert tf.linked.baking()
    tf.linked.run_pending()  # the corners (a bake per corner: ms)
    with tf.linked.deferring():
        assert tf.description.description(mat).varies
        tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())
    entry = tf.scene_draw.batch_entry("Sphere")
    assert entry.batch is not None and entry.batch.thickness_map is None  # per corner meanwhile
    assert tf.linked.has_pending() and not tf.linked.baking()
    monkeypatch.setattr(tf.linked.maps, "SETTLE_S", 3600.0)
    tf.linked.run_pending()
    assert tf.linked.STATS["image_bakes"] == before and tf.linked.has_pending(), "not settled: kept"
    for scale in (5.5, 6.0):  # a slider dragged on: each step's corners, the maps still unsettled
        mat.node_tree.nodes["Noise"].inputs["Scale"].default_value = scale
        for _ in range(2):  # the corners' bake is queued, then run; the next frame queues the map
            with tf.linked.deferring():
                tf.description.description(mat)
                tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())
            tf.linked.run_pending()
    assert tf.linked.STATS["image_bakes"] == before and tf.linked.pending_count() == 1, "one map queued"
    monkeypatch.setattr(tf.linked.maps, "SETTLE_S", 0.0)
    assert tf.linked.run_pending() == []
    assert tf.linked.STATS["image_bakes"] == before + 1 and not tf.linked.has_pending()
    with tf.linked.deferring():
        tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())
    assert tf.scene_draw.batch_entry("Sphere").batch.thickness_map is not None


def test_overlapping_uvs_keep_the_thickness_per_corner(bpy, tf):
    """UV islands folded onto each other (the sphere's two halves mirrored in u): a bake writes
    each texel once, so the map would give one half the other's noise; it disagrees with the
    per-corner bake, is dropped, and the panel says why."""
    mat = _noise_material(bpy, scale=5.0)
    obj = _sphere(bpy, mat)
    layer = obj.data.uv_layers.active
    uv = np.empty(2 * len(obj.data.loops), dtype=np.float32)
    layer.data.foreach_get("uv", uv)
    uv = uv.reshape(-1, 2)
    uv[:, 0] = np.minimum(uv[:, 0], 1.0 - uv[:, 0])
    layer.data.foreach_set("uv", uv.ravel())
    socket = tf.principled.principled_node(mat).inputs["Thin Film Thickness"]
    mesh = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    found, why, waiting = tf.linked.linked_map(obj, mesh, mat, socket)
    assert found is None and not waiting and "overlaps itself" in why and "per corner" in why
    assert any("overlaps itself" in n for n in tf.description.warnings(mat))
    entry, _ = _batch_thickness_nm(bpy, tf, "Sphere")
    assert entry.batch.thickness_map is None


def test_a_coarse_sphere_keeps_the_map_of_a_steep_texture(bpy, tf):
    """A 16 × 8 UV sphere with a baked noise of scale 6: the corners at its poles sit on the
    map's edge row, which only the poles' slivers reach, and the noise changes by several per
    cent of its range across one texel there, so the bilinear read at 1.0 % of the corners
    missed them by more than 2 % and the map was dropped as if its UVs overlapped. The texels
    around each corner hold its value: the map is kept, and still matches the corners' bake."""
    mat = _noise_material(bpy, scale=6.0)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8)
    obj = bpy.context.active_object
    obj.data.materials.append(mat)
    socket = tf.principled.principled_node(mat).inputs["Thin Film Thickness"]
    field = tf.linked.evaluate(obj, obj.data, mat, socket)
    found, why, _ = tf.linked.linked_map(obj, obj.data, mat, socket)
    assert found is not None, why
    at_corners = tf.linked.maps.sample_bilinear(found.values, found.uv, found.repeat)
    error = np.abs(at_corners - field.values) / np.ptp(field.values)
    assert np.median(error) < 0.005 and np.mean(error > 0.02) < 0.02, (
        np.median(error),
        np.mean(error > 0.02),
    )


def test_noise_thickness_is_baked_once_and_rebaked_when_its_scale_changes(bpy, tf):
    """A Noise Texture is baked with Cycles; asking again (the description, the warnings, a
    frame) reuses the bake; a new noise scale bakes again and the field changes."""
    mat = _noise_material(bpy, scale=5.0)
    _sphere(bpy, mat)
    stats = tf.linked.STATS
    before = stats["bakes"]
    desc = tf.description.description(mat)
    assert stats["bakes"] == before + 1
    lo, hi = desc.thickness_range_nm
    assert 150.0 <= lo < hi <= 850.0 and hi - lo > 100.0  # Blender's noise spans much of [0, 1]
    tf.description.description(mat)
    notes = tf.description.warnings(mat)
    entry, _ = _batch_thickness_nm(bpy, tf, "Sphere")
    first = entry.thickness.copy()
    assert stats["bakes"] == before + 1, "cached: the same tree and mesh bake once"
    assert any("baked with Cycles" in n for n in notes), notes

    mat.node_tree.nodes["Noise"].inputs["Scale"].default_value = 9.0
    desc2 = tf.description.description(mat)
    assert stats["bakes"] == before + 2, "a new noise scale re-bakes"
    entry2, _ = _batch_thickness_nm(bpy, tf, "Sphere")
    assert entry2.thickness.shape == first.shape and not np.allclose(entry2.thickness, first, atol=1e-3)
    assert desc2.thickness_range_nm != desc.thickness_range_nm
    assert stats["bakes"] == before + 2


def test_the_draw_callback_never_bakes_it_queues(bpy, tf):
    """Inside ``deferring`` (the viewport's draw) a field that needs a bake is queued and the
    material is not drawn yet, with a message; ``run_pending`` (the timer) bakes it."""
    mat = _noise_material(bpy)
    _sphere(bpy, mat)
    before = tf.linked.STATS["bakes"]
    with tf.linked.deferring():
        assert tf.description.description(mat) is None
        notes = tf.description.warnings(mat)
    assert tf.linked.STATS["bakes"] == before and tf.linked.has_pending()
    assert any("being baked" in n for n in notes), notes
    assert tf.linked.run_pending() == []
    assert tf.linked.STATS["bakes"] == before + 1 and not tf.linked.has_pending()
    with tf.linked.deferring():
        assert tf.description.description(mat).varies


def test_the_material_panel_never_bakes_it_queues(bpy, tf):
    """The panel's lines (drawn inside Blender's draw) queue a needed bake, like the viewport."""
    mat = _noise_material(bpy)
    _sphere(bpy, mat)
    before = tf.linked.STATS["bakes"]
    notes = tf.ui.warnings(mat)
    assert tf.ui.description(mat) is None and tf.linked.STATS["bakes"] == before
    assert tf.linked.has_pending() and any("being baked" in n for n in notes), notes
    tf.linked.run_pending()
    assert any("baked with Cycles" in n for n in tf.ui.warnings(mat))


def test_a_thickness_that_cannot_be_evaluated_says_so_in_panel_and_plan(bpy, tf, capsys):
    """An image at a UV map the mesh lacks: the material is drawn as the magenta fallback with
    the reason in the panel's warnings and as an ``error:`` of ``plan``, never silently nothing."""
    mat, node = _principled(bpy, "NoUV")
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.new("t", 4, 4, float_buffer=True)
    tex.image.colorspace_settings.name = "Non-Color"
    uvmap = mat.node_tree.nodes.new("ShaderNodeUVMap")
    uvmap.uv_map = "Missing"
    mat.node_tree.links.new(uvmap.outputs["UV"], tex.inputs["Vector"])
    mat.node_tree.links.new(tex.outputs["Alpha"], node.inputs["Thin Film Thickness"])
    _sphere(bpy, mat)
    with pytest.raises(ValueError, match="no UV map"):
        tf.description.description(mat)
    notes = tf.description.warnings(mat)
    assert any("no UV map" in n and "magenta" in n for n in notes), notes
    items, messages = tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())
    assert any(item.fallback for item in items) and any("no UV map" in m for m in messages)
    tf.headless.main(["plan"])
    captured = capsys.readouterr()
    assert "error:" in captured.err and "no UV map" in captured.err


def test_plan_says_what_drives_a_linked_thickness(bpy, tf, capsys):
    mat = _noise_material(bpy)
    _sphere(bpy, mat)
    assert tf.headless.main(["plan"]) == 0
    out = capsys.readouterr().out
    assert "baked with Cycles at" in out and "face corners" in out and "Noise" in out


# ----------------------------------------------------------------------------------------------
# The extension's Blender Noise source, written back to the Principled BSDF as nodes
# ----------------------------------------------------------------------------------------------
def _blender_noise_material(bpy, lo=200.0, hi=700.0):
    mat = bpy.data.materials.new("Oil")
    settings = mat.thinfilm_sh
    settings.preset = "SOAP_FILM"
    settings.enabled = True
    settings.vary_thickness = True
    settings.thickness_min_nm, settings.thickness_max_nm = lo, hi
    settings.thickness_source = "BLENDER_NOISE"
    settings.noise_scale, settings.noise_seed = 4.0, 3
    settings.sh_order, settings.view_samples, settings.wavelength_count = "2", 4, 32
    settings.thickness_samples = 4
    return mat


def test_write_back_of_blender_noise_is_the_node_graph_the_preview_draws(bpy, tf):
    """The Blender Noise source is previewed from Blender's Noise Texture computed as Cycles does
    (precompute.materials.perlin); write-back links that graph (Noise Texture → Map Range
    min–max) into Thin Film Thickness, and Cycles' bake of the written material at the corners
    is the preview's thickness to within the bake's own spread (Cycles shades each corner a
    little off its face, so two faces' corners at one vertex differ by as much)."""
    lo, hi = 200.0, 700.0
    mat = _blender_noise_material(bpy, lo, hi)
    _sphere(bpy, mat)
    entry, messages = _batch_thickness_nm(bpy, tf, "Sphere")
    preview_nm = lo + entry.thickness.astype(np.float64) * (hi - lo)
    assert np.ptp(preview_nm) > 100.0, messages  # it varies

    notes = tf.principled.write_back_to_principled(mat)
    node = tf.principled.principled_node(mat)
    socket = node.inputs["Thin Film Thickness"]
    assert socket.is_linked and socket.links[0].from_node.bl_idname == "ShaderNodeMapRange"
    ranged = socket.links[0].from_node
    assert (ranged.inputs["To Min"].default_value, ranged.inputs["To Max"].default_value) == (lo, hi)
    noise = ranged.inputs["Value"].links[0].from_node
    assert noise.bl_idname == "ShaderNodeTexNoise" and noise.inputs["Scale"].default_value == 4.0
    assert not any("middle" in n for n in notes), notes
    tf.principled.write_back_to_principled(mat)  # writing again replaces, never duplicates
    assert sum(n.bl_idname == "ShaderNodeTexNoise" for n in mat.node_tree.nodes) == 1

    mat.thinfilm_sh.enabled = False
    sphere = bpy.data.objects["Sphere"]
    field = tf.linked._bake(sphere, mat, socket)  # Cycles' values (the preview's are numpy's)
    assert field.baked
    error = np.abs(field.values - preview_nm)
    vertex = np.array([loop.vertex_index for loop in sphere.data.loops])
    spread = max(np.ptp(field.values[vertex == v]) for v in np.unique(vertex))  # Cycles vs itself
    # Measured: max 0.20 nm, median 0.042 nm of 500; Cycles' own corners at one vertex differ
    # by up to 0.36 nm. One octave fewer is 34 nm off, another hash or gradient 170 nm.
    assert error.max() < 0.0015 * (hi - lo) and error.max() <= spread, (error.max(), spread)
    assert np.median(error) < 3e-4 * (hi - lo), np.median(error)


def _against_cycles_bake(tf, obj, mat, socket, source: str):
    """(the link into ``socket`` evaluated directly, which must name ``source``; its difference
    from Cycles' bake of the link at each corner; Cycles' own spread: the largest difference
    between its corners at one vertex, since it shades each corner a little off its face)."""
    direct = tf.linked.evaluate(obj, obj.data, mat, socket)
    baked = tf.linked._bake(obj, mat, socket)
    assert not direct.baked and source in direct.how, direct.how
    vertex = np.array([loop.vertex_index for loop in obj.data.loops])
    spread = max(np.ptp(baked.values[vertex == v]) for v in np.unique(vertex))
    return direct, np.abs(direct.values - baked.values), spread


@pytest.mark.parametrize(
    "graph",
    [
        "noise_3d_generated",
        "noise_4d_object",
        "noise_3d_fractional",
        "noise_3d_distorted",
        "noise_4d_object_distorted",
        "noise_3d_mapped_point",
        "noise_4d_object_mapped_texture",
    ],
)
def test_a_noise_texture_is_evaluated_directly_as_cycles_computes_it(bpy, tf, graph):
    """A Noise Texture (fBm, normalized; 3-D at Generated coordinates, the node's default, or
    4-D at Object coordinates; Detail 3 or 2.4, Roughness 0.6, Lacunarity 2.2; Distortion 0 or
    0.8; through a Mapping node, Point at the default coordinates or Texture at Object ones,
    each with a location, a rotation about all three axes and an uneven scale) → Map Range →
    Thin Film Thickness is evaluated in numpy at the corners, with no Cycles bake, to within the
    bake's own spread: Cycles shades each corner a little off its face, so two faces' corners at
    one vertex differ by as much. The per-pixel noise the link is recognised as
    (``noise_graph``: the Mapping folded into a matrix) gives the same corners."""
    mat, node = _principled(bpy, graph)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    noise = nodes.new("ShaderNodeTexNoise")
    noise.noise_dimensions = "4D" if "4d" in graph else "3D"
    values = {"Scale": 3.7, "Detail": 2.4 if "fractional" in graph else 3.0, "Roughness": 0.6}
    values["Lacunarity"] = 2.2
    if "distorted" in graph:
        values["Distortion"] = 0.8
    if "4d" in graph:
        values["W"] = 1.7
    for name, value in values.items():
        noise.inputs[name].default_value = value
    vector = None
    if "object" in graph:
        vector = nodes.new("ShaderNodeTexCoord").outputs["Object"]
    elif "mapped" in graph:
        vector = nodes.new("ShaderNodeTexCoord").outputs["Generated"]
    if "mapped" in graph:
        mapping = nodes.new("ShaderNodeMapping")
        mapping.vector_type = "TEXTURE" if graph.endswith("texture") else "POINT"
        mapping.inputs["Location"].default_value = (0.3, -0.7, 1.1)
        mapping.inputs["Rotation"].default_value = (0.4, -0.9, 1.3)
        mapping.inputs["Scale"].default_value = (1.5, 0.6, 2.2)
        links.new(vector, mapping.inputs["Vector"])
        vector = mapping.outputs["Vector"]
    if vector is not None:
        links.new(vector, noise.inputs["Vector"])
    ranged = nodes.new("ShaderNodeMapRange")
    ranged.inputs["To Min"].default_value, ranged.inputs["To Max"].default_value = 100.0, 900.0
    links.new(noise.outputs["Fac"], ranged.inputs["Value"])
    links.new(ranged.outputs["Result"], node.inputs["Thin Film Thickness"])
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12, radius=1.3, location=(0.3, -0.2, 0.1))
    obj = bpy.context.active_object
    obj.scale = (1.0, 0.7, 1.2)
    obj.data.materials.append(mat)
    direct, error, spread = _against_cycles_bake(
        tf, obj, mat, node.inputs["Thin Film Thickness"], "Noise Texture"
    )
    # Measured: max 0.34, 0.69, 0.29, 0.41, 0.95, 0.41, 0.99 nm (median 0.054–0.14) of 800,
    # where Cycles' own corners at one vertex differ by 0.57, 1.25, 0.53, 0.76, 1.77, 0.76, 1.93
    # nm; one octave fewer, another hash or a wrong texture space, distortion offset or Euler
    # order is tens of nm.
    assert error.max() <= max(spread, 1e-3 * 800.0), (error.max(), spread)
    assert np.median(error) < 3e-4 * 800.0, np.median(error)
    assert np.ptp(direct.values) > 200.0  # the noise varies: the check has something to see
    graph_found = tf.linked.noise_graph_of(obj, node.inputs["Thin Film Thickness"])
    corners = np.array([obj.data.vertices[loop.vertex_index].co for loop in obj.data.loops])
    folded = np.clip(
        graph_found.a * graph_found.noise.fac(corners) + graph_found.b, graph_found.low, graph_found.high
    )
    np.testing.assert_allclose(folded, direct.values, atol=1e-3)  # nm: float32 coordinates


def _mapped_noise(bpy, name: str, scale: float, nm: tuple):
    """(material, its Principled BSDF, the Noise Texture) of Noise Texture (at its default
    coordinates, ``scale``) → Map Range to ``nm`` → Thin Film Thickness."""
    mat, node = _principled(bpy, name)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    noise = nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = scale
    ranged = nodes.new("ShaderNodeMapRange")
    ranged.inputs["To Min"].default_value, ranged.inputs["To Max"].default_value = nm
    links.new(noise.outputs["Fac"], ranged.inputs["Value"])
    links.new(ranged.outputs["Result"], node.inputs["Thin Film Thickness"])
    return mat, node, noise


def _modified(obj, kind: str):
    """Give ``obj`` modifiers of ``kind``: *build*, a Subdivision Surface (its mesh shrinks inside
    its cage) and an Array; *deform*, a Simple Deform's twist; *build_then_deform*, all three;
    *keyed_then_build*, a shape key (a bend: not affine, so no bounds can stand for it) then
    the Subdivision Surface."""
    if kind.startswith("keyed"):
        obj.shape_key_add(name="Basis")
        key = obj.shape_key_add(name="Bend")
        co = np.array([v.co for v in obj.data.vertices])
        co[:, 0] += 0.4 * co[:, 2] ** 2
        key.data.foreach_set("co", co.ravel())
        key.value = 1.0
    if kind.startswith("build") or kind.endswith("build"):
        subdivide = obj.modifiers.new("subdivide", "SUBSURF")
        subdivide.levels = subdivide.render_levels = 2
    if kind.startswith("build"):
        obj.modifiers.new("array", "ARRAY").relative_offset_displace = (1.2, 0.0, 0.0)
    if kind.endswith("deform"):
        twist = obj.modifiers.new("twist", "SIMPLE_DEFORM")
        twist.deform_method, twist.deform_axis, twist.angle = "TWIST", "Z", 1.2
    return obj


def _coordinates_material(bpy, output: str, texspace=None, name: str = "Coordinates"):
    """A material emitting the Texture Coordinate ``output`` (or the vector attribute of that
    name), mapped by the shader into ``texspace`` ((location, size): 0–1 across it; an Emission
    clamps negative values) if given."""
    mat = bpy.data.materials.get(name) or bpy.data.materials.new(name)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    emission = nodes.new("ShaderNodeEmission")
    coordinates = nodes.new("ShaderNodeTexCoord")
    if output in coordinates.outputs:
        value = coordinates.outputs[output]
    else:  # a vector attribute of the mesh
        attribute = nodes.new("ShaderNodeAttribute")
        attribute.attribute_name = output
        value = attribute.outputs["Vector"]
    if texspace is not None:
        location, extent = (np.asarray(v) for v in texspace)
        for operation, constant in (("SUBTRACT", location - extent), ("DIVIDE", 2.0 * extent)):
            step = nodes.new("ShaderNodeVectorMath")
            step.operation, step.inputs[1].default_value = operation, tuple(constant)
            links.new(value, step.inputs[0])
            value = step.outputs["Vector"]
    links.new(value, emission.inputs["Color"])
    links.new(emission.outputs[0], nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    return mat


def _render(bpy, obj, mat, size: int = 48) -> np.ndarray:
    """Cycles' render (RGBA, one sample, no pixel filter, orthographic from above) of the scene
    with ``obj`` wearing ``mat``."""
    obj.data.materials.clear()
    obj.data.materials.append(mat)
    scene = bpy.context.scene
    if scene.camera is None:
        camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
        camera.data.type, camera.data.ortho_scale = "ORTHO", 5.0
        camera.location = (1.0, 0.0, 6.0)
        scene.collection.objects.link(camera)
        scene.camera = camera
    scene.render.engine = "CYCLES"
    scene.cycles.device, scene.cycles.samples, scene.cycles.filter_width = "CPU", 1, 0.01
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.render.film_transparent = True
    scene.view_settings.view_transform = "Standard"  # the values as they are
    scene.render.image_settings.file_format = "OPEN_EXR"
    return _rendered_pixels(bpy, scene, "tfsh_coordinates_render.exr", size)


def _rendered_pixels(bpy, scene, name: str, size: int) -> np.ndarray:
    """``scene`` rendered to a file ``name`` of this process's own, read back and removed: RGBA
    (size, size, 4), bottom row first. (A fixed path in /tmp let two workers on this file,
    ``-n 2`` without ``--dist loadfile``, read each other's renders.)"""
    path = pathlib.Path(tempfile.gettempdir()) / f"tfsh_{os.getpid()}_{name}"
    scene.render.filepath = str(path)
    try:
        bpy.ops.render.render(write_still=True)
        image = bpy.data.images.load(str(path), check_existing=False)
        pixels = np.empty(size * size * 4, dtype=np.float32)
        image.pixels.foreach_get(pixels)
        bpy.data.images.remove(image)
    finally:
        path.unlink(missing_ok=True)
    return pixels.reshape(size, size, 4)


def _render_coordinates(bpy, obj, output: str, texspace=None) -> np.ndarray:
    """:func:`_render` of ``obj`` emitting :func:`_coordinates_material`'s coordinates."""
    return _render(bpy, obj, _coordinates_material(bpy, output, texspace))


def _render_bake_copy(bpy, tf, obj) -> np.ndarray:
    """Cycles' render of what a corner bake of ``obj`` sees: a mesh made from its evaluated one
    (``bpy.data.meshes.new_from_object``), given its Generated coordinates by
    ``generated.carry_generated`` for a material emitting them, in ``obj``'s place."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    mesh = bpy.data.meshes.new_from_object(obj.evaluated_get(depsgraph), depsgraph=depsgraph)
    copy = bpy.data.objects.new("BakeCopy", mesh)
    copy.matrix_world = obj.matrix_world
    bpy.context.scene.collection.objects.link(copy)
    mat = _coordinates_material(bpy, "Generated", name="BakeCopy")
    tf.generated.carry_generated(obj, mesh, mat)
    obj.hide_render = True
    try:
        return _render(bpy, copy, mat)
    finally:
        obj.hide_render = False
        bpy.data.objects.remove(copy)


def _generated_mapped_copied(bpy, tf, obj, texspace):
    """Cycles' renders of ``obj``'s Generated coordinates, of its Object coordinates mapped by
    ``texspace``, and of the corner bake's copy's (:func:`_render_bake_copy`): (N, 3) each, at
    the pixels all three cover (more than 200)."""
    generated = _render_coordinates(bpy, obj, "Generated")
    mapped = _render_coordinates(bpy, obj, "Object", texspace)
    copied = _render_bake_copy(bpy, tf, obj)
    inside = (generated[..., 3] > 0.999) & (mapped[..., 3] > 0.999) & (copied[..., 3] > 0.999)
    assert inside.sum() > 200, inside.sum()
    return tuple(image[..., :3][inside] for image in (generated, mapped, copied))


@pytest.mark.parametrize("kind", ["build", "deform", "build_then_deform", "keyed_then_build"])
def test_generated_coordinates_are_the_positions_in_the_originals_texture_space(bpy, tf, kind):
    """What Cycles renders as Generated on a subdivided, arrayed cube is its evaluated (Object)
    position in the original mesh's texture space, which ``generated.generated_space`` gives the
    per-pixel noise; the evaluated mesh's own bounds, what the corner bake's copy used, are 0.1
    off. After a Displace or a shape key, Generated stays where the vertices were before them:
    ``kind`` is not POSITIONS and ``generated_space`` gives those positions (the original vertices',
    or the object evaluated again without them where a Subdivision Surface comes after). In every
    case the corner bake's copy, given them by ``carry_generated``, renders the same Generated
    coordinates as the object."""
    bpy.ops.mesh.primitive_cube_add(size=2.0, rotation=(0.5, 0.3, 0.2))
    obj = _modified(bpy.context.active_object, kind)
    texspace = tf.generated.original_texspace(obj)
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    space, orco = tf.generated.generated_space(obj, evaluated)
    corners = np.array([v.co for v in evaluated.vertices])  # (the renders free the evaluated mesh)
    generated, mapped, copied = _generated_mapped_copied(bpy, tf, obj, texspace)
    # Measured: 3.2e-6 to 6.8e-6 in each case; before, the copy's own bounds (and for the
    # deformed ones its deformed positions) were 0.1–0.4 off in the median.
    assert np.abs(generated - copied).max() < 1e-3, np.abs(generated - copied).max()
    error = np.abs(generated - mapped).max(axis=1)
    assert space == texspace
    if kind != "build":
        assert tf.generated.kind(obj) != tf.generated.POSITIONS and orco is not None
        assert np.median(error) > 0.05, np.median(error)  # measured 0.11–0.20
        return
    assert tf.generated.kind(obj) == tf.generated.POSITIONS and texspace is not None and orco is None
    assert error.max() < 1e-3, error.max()  # measured 7.9e-6
    location, extent = (np.asarray(v) for v in texspace)
    low, high = corners.min(axis=0), corners.max(axis=0)
    own = (mapped * 2.0 * extent + location - extent - low) / (high - low)
    assert np.median(np.abs(generated - own).max(axis=1)) > 0.05  # measured 0.38: the Array


@pytest.mark.parametrize("modifier", ["BOOLEAN", "SCREW", "SKIN"])
def test_generated_coordinates_after_a_boolean_screw_or_skin_are_the_positions(bpy, tf, modifier):
    """After a Boolean, a Screw or a Skin (no deformation) Cycles renders Generated as the
    evaluated (Object) position in the original mesh's texture space, which ``generated_space``
    gives the per-pixel noise and the corner bake's copy (before, such a link was always baked).
    With a twist as well the link stays baked: their faces follow the deformed positions, so the
    mesh evaluated without the twist would not match it vertex for vertex."""
    bpy.ops.mesh.primitive_cube_add(size=2.0, rotation=(0.5, 0.3, 0.2))
    obj = bpy.context.active_object
    if modifier == "BOOLEAN":
        bpy.ops.mesh.primitive_uv_sphere_add(radius=1.2, location=(0.8, 0.5, 0.6))
        cutter = bpy.context.active_object
        cutter.hide_render = True
        cut = obj.modifiers.new("cut", "BOOLEAN")
        cut.object, cut.operation = cutter, "DIFFERENCE"
    elif modifier == "SCREW":
        screw = obj.modifiers.new("screw", "SCREW")
        screw.angle, screw.screw_offset, screw.steps, screw.render_steps = 1.0, 0.5, 8, 8
    else:
        obj.modifiers.new("skin", "SKIN")
    assert tf.generated.kind(obj) == tf.generated.POSITIONS
    texspace = tf.generated.original_texspace(obj)
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    assert tf.generated.generated_space(obj, evaluated) == (texspace, None)
    generated, mapped, copied = _generated_mapped_copied(bpy, tf, obj, texspace)
    # Measured: 4.4e-6, 6.1e-6, 7.3e-6 (max over the object).
    assert np.abs(generated - mapped).max() < 1e-3, np.abs(generated - mapped).max()
    assert np.abs(generated - copied).max() < 1e-3, np.abs(generated - copied).max()
    _modified(obj, "deform")
    assert tf.generated.kind(obj) is None


@pytest.mark.parametrize("physics", ["CLOTH", "SOFT_BODY"])
def test_generated_coordinates_under_cloth_or_soft_body_stay_where_the_vertices_were(bpy, tf, physics):
    """A grid falling as Cloth or a Soft Body for ten frames: Cycles renders its Generated
    coordinates where the vertices were before the simulation, as after a Deform modifier, and
    the corner bake's copy (given them by ``carry_generated``) renders the same; the simulated
    positions are 0.2 away (before, such a link was baked at them)."""
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=12, y_subdivisions=12, size=2.0, location=(0.0, 0.0, 1.0))
    obj = bpy.context.active_object
    obj.modifiers.new("physics", physics)
    if physics == "SOFT_BODY":
        obj.modifiers["physics"].settings.use_goal = False  # free to fall
    for frame in range(1, 12):
        bpy.context.scene.frame_set(frame)
    assert tf.generated.kind(obj) == tf.generated.ORIGINAL
    generated, simulated, copied = _generated_mapped_copied(bpy, tf, obj, tf.generated.original_texspace(obj))
    assert np.abs(generated - copied).max() < 1e-3, np.abs(generated - copied).max()  # measured 0
    moved = np.median(np.abs(generated - simulated).max(axis=1))
    assert moved > 0.1, moved  # measured 0.22 and 0.24


def test_the_positions_before_a_deformation_leave_nothing_behind(bpy, tf, monkeypatch):
    """``generated.evaluate_orco`` removes its temporary scene, object and mesh, and leaves the
    object's shape keys and modifiers as they were; it is cached until what it depends on
    changes (a Subdivision Surface's level), not when the deformation does; a failure leaves
    nothing behind either, and is remembered: no positions (the link is baked), not retried."""
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    obj = _modified(bpy.context.active_object, "keyed_then_build")
    counts = lambda: (len(bpy.data.scenes), len(bpy.data.objects), len(bpy.data.meshes))  # noqa: E731
    before = counts()
    assert tf.generated.needs_evaluation(obj)
    orco = tf.generated.evaluate_orco(obj)
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    assert counts() == before and len(orco) == len(evaluated.vertices)
    bend = obj.data.shape_keys.key_blocks["Bend"]
    assert bend.value == 1.0 and [m.type for m in obj.modifiers] == ["SUBSURF"]
    bend.value = 0.5  # the deformation: the positions before it hold
    assert not tf.generated.needs_evaluation(obj)
    obj.modifiers["subdivide"].levels = 1  # what they depend on
    assert tf.generated.needs_evaluation(obj)

    class _Failing:
        def __getattr__(self, name):
            return getattr(bpy.context, name)

        def temp_override(self, **_):
            raise RuntimeError("no depsgraph here")

    monkeypatch.setattr(tf.generated, "bpy", type("bpy", (), {"data": bpy.data, "context": _Failing()}))
    with pytest.raises(RuntimeError, match="no depsgraph"):
        tf.generated.evaluate_orco(obj)
    monkeypatch.undo()
    assert counts() == before and not tf.generated.needs_evaluation(obj)
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    assert tf.generated.generated_space(obj, evaluated) == (None, None)


@pytest.mark.parametrize("kind", ["subdivided", "twisted", "shape_key", "subdivided_then_twisted"])
def test_a_noise_on_a_modified_mesh_is_drawn_per_pixel_as_cycles_bakes_it(bpy, tf, kind):
    """A Noise Texture at Generated coordinates (the node's default) on a sphere under a
    Subdivision Surface is drawn per pixel and evaluated at the corners with no bake, in the
    original's texture space (before, it was baked, in the subdivided mesh's own smaller bounds).
    Under a Displace or a shape key it is drawn per pixel and evaluated at the corners from where
    the vertices were before them (the batch's ``orco``; after a Subdivision Surface, the object
    evaluated again without the Displace, which the draw leaves to the timer), and Cycles' bake
    of the link reads them there too (an attribute of the bake's copy). Either way Cycles' bake
    agrees within its own spread."""
    mat, node, _ = _mapped_noise(bpy, "ModifiedNoise", 3.7, (100.0, 900.0))
    socket = node.inputs["Thin Film Thickness"]
    obj = _sphere(bpy, mat)
    if kind == "subdivided":
        obj.modifiers.new("subdivide", "SUBSURF").levels = 1
    elif kind == "twisted":
        _modified(obj, "deform")
    elif kind == "subdivided_then_twisted":  # evaluated again without the twist, in the timer
        _modified(obj, "build_then_deform")
    else:
        _modified(obj, "keyed")
    depsgraph = bpy.context.evaluated_depsgraph_get()
    mesh = obj.evaluated_get(depsgraph).data
    graph = tf.linked.noise_graph_of(obj, socket)  # drawn per pixel, at orco where deformed
    assert graph is not None and graph.noise.orco == (kind != "subdivided")
    tf.linked.PENDING.clear()  # what earlier tests left queued
    tf.linked.maps.PENDING.clear()
    with tf.linked.deferring():
        tf.description.description(mat)
        tf.scene_draw.collect(depsgraph)
    if kind == "subdivided_then_twisted":  # computed by the timer, not the draw
        assert tf.linked.has_pending() and tf.generated.needs_evaluation(obj)
        assert tf.scene_draw.batch_entry("Sphere").batch.noise is None  # no noise without orco
        assert not tf.linked.run_pending()
        assert not tf.generated.needs_evaluation(obj)
        for _ in range(2):  # then the corners (8 836 vertices: the timer's too)
            with tf.linked.deferring():
                tf.scene_draw.collect(depsgraph)
            assert not tf.linked.run_pending()
    entry = tf.scene_draw.batch_entry("Sphere")
    direct = tf.linked.evaluate(obj, mesh, mat, socket)
    assert not direct.baked and "Noise Texture" in direct.how, direct.how
    assert entry.batch.noise is not None and entry.batch.noise.orco == graph.noise.orco
    corners = tf.generated.orco_corners(obj.evaluated_get(depsgraph), mesh)
    if corners is None:
        corners = np.array([v.co for v in mesh.vertices])[[loop.vertex_index for loop in mesh.loops]]
    np.testing.assert_allclose(entry.thickness, entry.batch.noise.parameter(corners), atol=1e-5)
    baked = tf.linked._bake(obj, mat, socket)
    vertex = np.array([loop.vertex_index for loop in mesh.loops])
    spread = max(np.ptp(baked.values[vertex == v]) for v in np.unique(vertex))
    error = np.abs(direct.values - baked.values)
    # Measured: max 0.20, 0.16, 0.17, 1.01 nm (median 0.032–0.046) of 800 where Cycles' own
    # corners at one vertex differ by 0.34, 0.31, 0.32, 1.23 (the twisted array). With the bake's
    # copy as before (its own bounds, its deformed positions): 38.9, 236, 234, 330 nm.
    assert error.max() <= max(spread, 1e-3 * 800.0), (error.max(), spread)
    assert np.ptp(direct.values) > 200.0


def test_a_rebuild_hashes_the_positions_before_a_deformation_once(bpy, tf, monkeypatch):
    """A deformed and subdivided mesh's batch is rebuilt with its orco key (a hash of the
    original positions, 8.8 ms at 203 401 vertices) read once per collect: the link's
    evaluation and the batch's corners asked it three times before. Outside a collect every
    call reads the positions again, so an edit of the original mesh between two collects is
    seen (the key changes and the positions before the deformation are computed again)."""
    mat, _, _ = _mapped_noise(bpy, "HashedOnce", 3.7, (100.0, 900.0))
    obj = _modified(_sphere(bpy, mat), "build_then_deform")
    depsgraph = bpy.context.evaluated_depsgraph_get()
    tf.linked.PENDING.clear()
    tf.linked.maps.PENDING.clear()
    tf.description.description(mat)
    for _ in range(3):  # the positions before the twist, then the corners, in the timer
        with tf.linked.deferring():
            tf.scene_draw.collect(depsgraph)
        tf.linked.run_pending()
    reads = []
    hashed = tf.generated._orco_key
    monkeypatch.setattr(tf.generated, "_orco_key", lambda original: reads.append(1) or hashed(original))
    tf.linked.mark_geometry("Sphere")  # what a depsgraph geometry update does
    tf.scene_draw.CACHES.dirty.add("Sphere")
    with tf.linked.deferring():
        tf.scene_draw.collect(depsgraph)
    entry = tf.scene_draw.batch_entry("Sphere")
    assert entry.batch.noise is not None and entry.batch.noise.orco  # rebuilt at orco
    assert len(reads) == 1, len(reads)  # 3 before (2 in the link's evaluation, 1 in the batch)
    key = tf.generated.orco_key(obj)
    obj.data.vertices[0].co.x += 0.25  # an edit of the original mesh
    assert tf.generated.orco_key(obj) != key and tf.generated.needs_evaluation(obj)
    assert len(reads) == 4


def test_a_smooth_mesh_with_a_noise_is_batched_per_vertex(bpy, tf):
    """A Noise Texture at Generated coordinates on a twisted sphere shaded smooth: each vertex's
    corners have the same thickness and the same position before the twist, so the batch holds
    one row per vertex (its thickness and ``orco`` too), a quarter of the per-corner rows; the
    entry keeps the thickness per corner, the noise at those positions. Shaded flat, the
    corners keep their own normals: one row per corner again. ``vertex_values`` gives None where
    two corners of a vertex differ."""
    mat, _, _ = _mapped_noise(bpy, "SmoothNoise", 3.7, (100.0, 900.0))
    obj = _modified(_sphere(bpy, mat), "deform")
    obj.data.shade_smooth()
    tf.linked.PENDING.clear()
    tf.linked.maps.PENDING.clear()
    tf.description.description(mat)

    def entry():
        depsgraph = bpy.context.evaluated_depsgraph_get()
        with tf.linked.deferring():
            tf.scene_draw.collect(depsgraph)
        return tf.scene_draw.batch_entry("Sphere"), obj.evaluated_get(depsgraph)

    smooth, obj_eval = entry()
    mesh = obj_eval.data
    assert smooth.batch.vertex_count == len(mesh.vertices) == 24 * 11 + 2
    assert smooth.batch.noise is not None and smooth.batch.noise.orco
    corners = tf.generated.orco_corners(obj_eval, mesh)
    np.testing.assert_allclose(smooth.thickness, smooth.batch.noise.parameter(corners), atol=1e-6)
    loops = np.array([loop.vertex_index for loop in mesh.loops])
    per_vertex = tf.mesh.vertex_values(smooth.thickness, loops, len(mesh.vertices))
    np.testing.assert_array_equal(per_vertex[loops], smooth.thickness)
    split = smooth.thickness.copy()
    split[np.flatnonzero(loops == loops[0])[1]] += 0.25  # one corner of vertex 0 differs
    assert tf.mesh.vertex_values(split, loops, len(mesh.vertices)) is None
    obj.data.shade_flat()
    bpy.context.view_layer.update()
    flat, obj_eval = entry()
    assert flat.batch is not smooth.batch and flat.batch.vertex_count == len(obj_eval.data.loops)
    np.testing.assert_array_equal(flat.thickness, smooth.thickness)


def _grouped_noise(bpy, name: str, scale: float, nm: tuple):
    """(material, its Principled BSDF) of a group holding a group of Noise Texture (at its
    default coordinates, ``scale``) → Map Range to ``nm``, linked into Thin Film Thickness."""
    mat, node = _principled(bpy, name)
    inner = bpy.data.node_groups.new(f"{name} inner", "ShaderNodeTree")
    outer = bpy.data.node_groups.new(f"{name} outer", "ShaderNodeTree")
    for group in (inner, outer):
        group.interface.new_socket("Thickness", in_out="OUTPUT", socket_type="NodeSocketFloat")
    noise = inner.nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = scale
    ranged = inner.nodes.new("ShaderNodeMapRange")
    ranged.inputs["To Min"].default_value, ranged.inputs["To Max"].default_value = nm
    inner.links.new(noise.outputs["Fac"], ranged.inputs["Value"])
    inner.links.new(ranged.outputs["Result"], inner.nodes.new("NodeGroupOutput").inputs[0])
    held = outer.nodes.new("ShaderNodeGroup")
    held.node_tree = inner
    outer.links.new(held.outputs[0], outer.nodes.new("NodeGroupOutput").inputs[0])
    used = mat.node_tree.nodes.new("ShaderNodeGroup")
    used.node_tree = outer
    mat.node_tree.links.new(used.outputs[0], node.inputs["Thin Film Thickness"])
    return mat, node


def test_a_noise_in_a_node_group_is_baked_where_the_vertices_were(bpy, tf):
    """A Noise Texture at Generated coordinates inside a group inside a group, on a twisted
    sphere: numpy does not read groups, so Cycles bakes the link, and its bake reads the
    positions before the twist inside the groups too (copies of both, rewired; removed with the
    bake, the groups themselves untouched). It agrees with the same noise outside any group,
    evaluated directly at those positions, within Cycles' own spread at one vertex."""
    grouped, node = _grouped_noise(bpy, "GroupedNoise", 3.7, (100.0, 900.0))
    plain, plain_node, _ = _mapped_noise(bpy, "PlainNoise", 3.7, (100.0, 900.0))
    obj = _modified(_sphere(bpy, grouped), "deform")
    depsgraph = bpy.context.evaluated_depsgraph_get()
    mesh = obj.evaluated_get(depsgraph).data
    groups = sorted(g.name for g in bpy.data.node_groups)
    baked = tf.linked._bake(obj, grouped, node.inputs["Thin Film Thickness"])
    assert sorted(g.name for g in bpy.data.node_groups) == groups  # the copies removed
    inner = bpy.data.node_groups["GroupedNoise inner"]
    assert not any(n.bl_idname == "ShaderNodeAttribute" for n in inner.nodes)  # untouched
    direct = tf.linked._direct(
        mesh, plain_node.inputs["Thin Film Thickness"], *tf.generated.generated_space(obj, mesh)
    )
    vertex = np.array([loop.vertex_index for loop in mesh.loops])
    spread = max(np.ptp(baked.values[vertex == v]) for v in np.unique(vertex))
    error = np.abs(direct.values - baked.values)
    # Measured: 0.16 nm (median 0.032; Cycles' spread 0.31); with the groups not rewired, 236.
    assert error.max() <= max(spread, 1e-3 * 800.0), (error.max(), spread)
    assert np.ptp(direct.values) > 200.0


def test_a_linked_noise_texture_is_drawn_per_pixel_with_no_bake(bpy, tf, monkeypatch):
    """Noise Texture → Map Range → Thin Film Thickness (the usual procedural film): the batch
    carries the Noise Texture for the shader (tf_perlin.glsl) and no map; nothing is baked or
    queued; the table's range covers the Map Range's whole output, the noise's peaks between the
    corners included. A distorted noise is drawn per pixel too; a mapped one, which the shader
    does not compute, keeps its map."""
    mat, node, noise = _mapped_noise(bpy, "Plain noise", 4.0, (150.0, 850.0))
    _sphere(bpy, mat)
    bakes, images = tf.linked.STATS["bakes"], tf.linked.STATS["image_bakes"]
    tf.linked.PENDING.clear()  # what earlier tests left queued
    tf.linked.maps.PENDING.clear()
    with tf.linked.deferring():
        desc = tf.description.description(mat)
        tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())
    assert desc.thickness_range_nm == (150.0, 850.0)  # the Map Range's ends, clamped or not
    entry = tf.scene_draw.batch_entry("Sphere")
    assert entry.batch.thickness_map is None and hasattr(entry.batch.noise, "uniforms")
    assert entry.batch.noise.dimensions == 3 and entry.batch.noise.scale == 4.0
    assert not tf.linked.has_pending()
    assert (tf.linked.STATS["bakes"], tf.linked.STATS["image_bakes"]) == (bakes, images)
    sphere = bpy.data.objects["Sphere"]
    corners = np.array([sphere.data.vertices[loop.vertex_index].co for loop in sphere.data.loops])
    np.testing.assert_allclose(entry.thickness, entry.batch.noise.parameter(corners), atol=1e-6)

    # a mesh past linked_nodes.INLINE_VERTICES: its corners are computed by the timer, not the
    # draw, which draws the new noise per pixel at once (no frame without the film meanwhile)
    monkeypatch.setattr(tf.linked.linked_nodes, "INLINE_VERTICES", 10)
    noise.inputs["Scale"].default_value = 4.5
    with tf.linked.deferring():
        assert tf.description.description(mat) is not None
        tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())
    waiting = tf.scene_draw.batch_entry("Sphere")
    assert waiting.batch.noise.scale == 4.5 and tf.linked.baking()
    np.testing.assert_allclose(waiting.thickness, 0.5)  # the corners: the range's middle meanwhile
    tf.linked.run_pending()
    with tf.linked.deferring():
        tf.description.description(mat)
        tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())
    entry = tf.scene_draw.batch_entry("Sphere")
    assert entry.batch.noise.scale == 4.5 and not tf.linked.has_pending()
    np.testing.assert_allclose(entry.thickness, entry.batch.noise.parameter(corners), atol=1e-6)
    assert (tf.linked.STATS["bakes"], tf.linked.STATS["image_bakes"]) == (bakes, images)

    noise.inputs["Distortion"].default_value = 0.3  # distorted: per pixel too, nothing baked
    with tf.linked.deferring():
        tf.description.description(mat)
        tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())
    tf.linked.run_pending()  # the corners (past the inline limit still)
    with tf.linked.deferring():
        tf.description.description(mat)
        tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())
    entry = tf.scene_draw.batch_entry("Sphere")
    assert entry.batch.noise.distortion == pytest.approx(0.3) and not tf.linked.has_pending()
    np.testing.assert_allclose(entry.thickness, entry.batch.noise.parameter(corners), atol=1e-6)
    assert (tf.linked.STATS["bakes"], tf.linked.STATS["image_bakes"]) == (bakes, images)

    noise.texture_mapping.translation = (0.25, 0.0, 0.0)  # mapped: not mirrored, Cycles bakes it
    with tf.linked.deferring():  # the corners' bake queued, the film as last drawn meanwhile
        assert tf.description.description(mat) is None and tf.linked.baking()
        items, _ = tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())
    assert [item.batch.noise.distortion for item in items if item.name.startswith("Sphere")] == [
        pytest.approx(0.3)
    ]
    tf.linked.run_pending()
    with tf.linked.deferring():  # the corners drawn; the map queued
        tf.description.description(mat)
        tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())
    assert tf.scene_draw.batch_entry("Sphere").batch.noise is None and tf.linked.has_pending()


def _drawn_with_no_bake(bpy, tf, mat):
    """(the description, the batch entry, the sphere, its corners' positions) of a sphere with
    ``mat`` after one frame's collection in the viewport's deferring mode, the queues emptied
    of what earlier tests left first; asserts that nothing was baked or queued."""
    sphere = _sphere(bpy, mat)
    bakes = (tf.linked.STATS["bakes"], tf.linked.STATS["image_bakes"])
    tf.linked.PENDING.clear()
    tf.linked.maps.PENDING.clear()
    with tf.linked.deferring():
        desc = tf.description.description(mat)
        tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())
    assert not tf.linked.has_pending()
    assert (tf.linked.STATS["bakes"], tf.linked.STATS["image_bakes"]) == bakes
    corners = np.array([sphere.data.vertices[loop.vertex_index].co for loop in sphere.data.loops])
    return desc, tf.scene_draw.batch_entry("Sphere"), sphere, corners


def _math(nodes, links, operation, value, *constants, clamp=False):
    """A Math node of ``operation`` reading ``value`` in its first input, ``constants`` after."""
    node = nodes.new("ShaderNodeMath")
    node.operation, node.use_clamp = operation, clamp
    for socket, constant in zip(list(node.inputs)[1:], constants, strict=False):
        socket.default_value = constant
    links.new(value, node.inputs[0])
    return node.outputs[0]


@pytest.mark.parametrize("chain", ["multiply_add", "ramp_multiply_add", "clamped_map_range", "divide"])
def test_linear_nodes_after_the_noise_are_folded_into_the_per_pixel_noise(bpy, tf, chain):
    """Artists scale a noise or a ramp into nanometres with Math nodes as often as with a Map
    Range: Multiply then Add, Multiply Add, a clamped Math into a Map Range, Divide by a
    constant. Any such chain is folded into the per-pixel noise's gain, bias and clamp: the
    batch computes the noise per pixel with no bake, its corners (numpy's evaluation of the
    graph, node by node) equal the folded noise's, and the table's range holds them."""
    mat, node = _principled(bpy, chain)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    noise = nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = 3.0
    value = noise.outputs["Fac"]
    if chain == "multiply_add":
        value = _math(nodes, links, "ADD", _math(nodes, links, "MULTIPLY", value, 700.0), 150.0)
    elif chain == "ramp_multiply_add":
        ramp = _colour_ramp(nodes)
        links.new(value, ramp.inputs["Fac"])
        value = _math(nodes, links, "MULTIPLY_ADD", ramp.outputs["Color"], 900.0, 120.0)
    elif chain == "clamped_map_range":  # 3 · Fac − 1 clamped to [0, 1], then 200–800 nm
        value = _math(nodes, links, "SUBTRACT", _math(nodes, links, "MULTIPLY", value, 3.0), 1.0, clamp=True)
        ranged = nodes.new("ShaderNodeMapRange")
        ranged.inputs["To Min"].default_value, ranged.inputs["To Max"].default_value = 200.0, 800.0
        links.new(value, ranged.inputs["Value"])
        value = ranged.outputs["Result"]
    else:
        value = _math(nodes, links, "DIVIDE", value, 0.002)
    links.new(value, node.inputs["Thin Film Thickness"])
    desc, entry, sphere, corners = _drawn_with_no_bake(bpy, tf, mat)
    spec = entry.batch.noise
    assert spec is not None and hasattr(spec, "uniforms"), "not computed per pixel"
    np.testing.assert_allclose(entry.thickness, spec.parameter(corners), atol=1e-6)
    field = tf.linked.evaluate(sphere, sphere.data, mat, node.inputs["Thin Film Thickness"])
    lo, hi = desc.thickness_range_nm
    assert lo - 0.01 <= field.lo and field.hi <= hi + 0.01 and np.ptp(field.values) > 100.0
    if chain == "clamped_map_range":  # the clamp reached: the corners touch its ends
        assert (lo, hi) == (200.0, 800.0) and np.isclose(field.values, 200.0).any()


def test_a_constant_colour_ramp_steps_where_cycles_table_does(bpy, tf):
    """Cycles reads a Color Ramp from a table of 257 entries at 0, 1/256, …, 1 (a Constant
    ramp: the entry at ⌊256 · Fac⌋), so a stop at 0.45 steps at 116/256 = 0.453125, not at
    0.45; the direct evaluation (materials.ramp) steps where Cycles' bake does across a sweep of
    Fac through it (a table of 256 at i/255 would step at 0.45098: 13 of these 48 values off)."""
    width = 48
    fac = np.linspace(0.4480, 0.4560, width)
    image = bpy.data.images.new("sweep", width, 2, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    pixels = np.zeros((2, width, 4), dtype=np.float32)
    pixels[..., 2], pixels[..., 3] = fac, 1.0
    image.pixels.foreach_set(pixels.ravel())
    mat, node = _principled(bpy, "Steps")
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    tex = nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = image, "Closest"
    sep = nodes.new("ShaderNodeSeparateColor")
    links.new(tex.outputs["Color"], sep.inputs["Color"])
    ramp = nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.interpolation = "CONSTANT"
    ramp.color_ramp.elements[0].color = (0.0, 0.0, 0.0, 0.2)
    ramp.color_ramp.elements[1].position = 0.45
    links.new(sep.outputs["Blue"], ramp.inputs["Fac"])
    ranged = nodes.new("ShaderNodeMapRange")
    ranged.inputs["To Min"].default_value, ranged.inputs["To Max"].default_value = 100.0, 900.0
    links.new(ramp.outputs["Alpha"], ranged.inputs["Value"])
    links.new(ranged.outputs["Result"], node.inputs["Thin Film Thickness"])
    obj, corner_vertex = _grid_with_pixel_centre_uvs(bpy, width, 2)
    obj.data.materials.append(mat)
    socket = node.inputs["Thin Film Thickness"]
    direct = tf.linked.evaluate(obj, obj.data, mat, socket)
    baked = tf.linked._bake(obj, mat, socket)
    expected = np.where(fac[corner_vertex % width] >= 116 / 256, 900.0, 260.0)
    np.testing.assert_allclose(baked.values, expected, atol=1e-3)  # Cycles: the table's step
    np.testing.assert_allclose(direct.values, baked.values, atol=1e-3)


@pytest.mark.parametrize("output", ["Color", "Alpha"])
def test_a_noise_texture_through_a_colour_ramp_is_drawn_per_pixel(bpy, tf, output):
    """Noise Texture → Color Ramp (three coloured stops, Ease) → Map Range → Thin Film Thickness,
    a film artists shape with a ramp: the batch carries the Noise Texture and the ramp's table
    for the shader (``TF_THICKNESS_RAMP``) and no map, nothing is baked; the corners equal
    Cycles' bake of the link to within its own spread; the table's range is the Map Range of the
    ramp's values (its Color's luminance or its Alpha). Moving a stop redraws with the new
    ramp (the node tree's key holds the stops)."""
    mat, node = _principled(bpy, "Ramped noise")
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    noise = nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = 3.0
    ramp = _colour_ramp(nodes)
    ranged = nodes.new("ShaderNodeMapRange")
    ranged.inputs["To Min"].default_value, ranged.inputs["To Max"].default_value = 150.0, 850.0
    links.new(noise.outputs["Fac"], ramp.inputs["Fac"])
    links.new(ramp.outputs[output], ranged.inputs["Value"])
    links.new(ranged.outputs["Result"], node.inputs["Thin Film Thickness"])
    desc, entry, sphere, corners = _drawn_with_no_bake(bpy, tf, mat)
    spec = entry.batch.noise
    assert entry.batch.thickness_map is None and len(spec.ramp) == 257 and spec.ramp_interpolate
    stops = np.array([tuple(e.color) for e in ramp.color_ramp.elements])
    ends = stops[:, 3] if output == "Alpha" else stops[:, :3] @ tf.linked.linked_nodes.luminance_weights()
    expected_nm = 150.0 + 700.0 * np.array([ends.min(), ends.max()])
    np.testing.assert_allclose(desc.thickness_range_nm, expected_nm, atol=0.01)  # shown to 0.01 nm
    np.testing.assert_allclose(entry.thickness, spec.parameter(corners), atol=1e-6)

    direct, error, spread = _against_cycles_bake(
        tf, sphere, mat, node.inputs["Thin Film Thickness"], "Color Ramp"
    )
    # Measured: max 0.15 nm (Color) and 0.19 (Alpha) of 700, Cycles' own corners at one vertex
    # differing by 0.31 and 0.37; the red channel for the luminance is 100s of nm off.
    assert error.max() <= max(spread, 1e-3 * 700.0), (error.max(), spread)
    assert np.ptp(direct.values) > 150.0  # the ramp varies: the check has something to see

    ramp.color_ramp.elements[1].position = 0.6  # an edit of a stop: a new table, drawn at once
    with tf.linked.deferring():
        tf.description.description(mat)
        tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())
    entry = tf.scene_draw.batch_entry("Sphere")
    assert entry.batch.noise.ramp != spec.ramp and not tf.linked.has_pending()
    np.testing.assert_allclose(entry.thickness, entry.batch.noise.parameter(corners), atol=1e-6)


def _render_centre(bpy, mat, size=48, samples=8):
    """Cycles render of a sphere with ``mat`` under a white World; the central pixels (near
    normal incidence, where a constant film has one colour)."""
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.render.image_settings.file_format = "OPEN_EXR"
    if scene.world is None:
        scene.world = bpy.data.worlds.new("white")
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (1, 1, 1, 1)
    if scene.camera is None:
        camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
        scene.collection.objects.link(camera)
        camera.location = (0.0, -4.0, 0.0)
        camera.rotation_euler = (np.pi / 2, 0.0, 0.0)
        camera.data.angle = np.radians(32.0)
        scene.camera = camera
    sphere = bpy.data.objects["Sphere"]
    sphere.data.materials[0] = mat
    rgb = _rendered_pixels(bpy, scene, "tfsh_write_back_render.exr", size)[..., :3]
    c = size // 2
    return rgb[c - 6 : c + 6, c - 6 : c + 6].reshape(-1, 3)


def test_cycles_render_of_the_written_back_noise_varies(bpy, tf):
    """Cycles renders the written-back graph with a varying colour where a film of one thickness
    (the same material with the link removed) has one colour."""
    mat = _blender_noise_material(bpy)
    _sphere(bpy, mat)
    tf.principled.write_back_to_principled(mat)
    mat.thinfilm_sh.enabled = False
    node = tf.principled.principled_node(mat)
    node.inputs["Transmission Weight"].default_value = 0.0  # opaque, black base: the film alone
    node.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    node.inputs["Roughness"].default_value = 0.0
    constant = mat.copy()
    socket = tf.principled.principled_node(constant).inputs["Thin Film Thickness"]
    constant.node_tree.links.remove(socket.links[0])
    chroma = [np.std(np.diff(_render_centre(bpy, m), axis=1), axis=0).max() for m in (mat, constant)]
    assert chroma[0] > 4 * chroma[1], chroma


def _colour_ramp(nodes, mode="RGB", interpolation="EASE"):
    """A Color Ramp of three coloured stops (and alphas), ``mode`` and ``interpolation``."""
    node = nodes.new("ShaderNodeValToRGB")
    ramp = node.color_ramp
    ramp.color_mode, ramp.interpolation = mode, interpolation
    ramp.elements[0].position, ramp.elements[0].color = 0.15, (0.9, 0.1, 0.2, 0.3)
    ramp.elements[1].position, ramp.elements[1].color = 0.8, (0.1, 0.7, 0.95, 1.0)
    middle = ramp.elements.new(0.45)
    middle.color = (0.2, 0.3, 0.05, 0.6)
    return node


@pytest.mark.parametrize(
    "graph",
    [
        "map_range",
        "map_range_clamped",
        "math_chain",
        "mix_colour",
        "reroute_value",
        "colour_to_thickness",
        "image_colour",
        "colour_ramp",
        "colour_ramp_hsv",
        "colour_ramp_constant_alpha",
    ],
)
def test_direct_evaluation_equals_cycles_bake_of_the_same_link(bpy, tf, graph):
    """Each node the direct evaluator mirrors gives what Cycles computes for the same link. A
    colour reaching a float input (the thickness, Map Range's Value) is its luminance there, in
    the bake too (*colour_to_thickness*, *image_colour*: the red channel was baked before); a
    Color Ramp is read from Cycles' 256-entry table of it (Ease, HSV with B-Spline, Constant)."""
    width, height = 5, 4
    rng = np.random.default_rng(7)
    image = bpy.data.images.new("img", width, height, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    image.pixels.foreach_set(rng.uniform(-0.2, 1.2, width * height * 4).astype(np.float32))
    mat, node = _principled(bpy, graph)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = image
    sep = nodes.new("ShaderNodeSeparateColor")
    links.new(tex.outputs["Color"], sep.inputs["Color"])
    value = sep.outputs["Blue"]
    if graph.startswith("map_range"):
        ranged = nodes.new("ShaderNodeMapRange")
        ranged.clamp = graph.endswith("clamped")
        for name, v in (("From Min", 0.1), ("From Max", 0.9), ("To Min", 100.0), ("To Max", 900.0)):
            ranged.inputs[name].default_value = v
        links.new(value, ranged.inputs["Value"])
        value = ranged.outputs["Result"]
    elif graph == "math_chain":
        for op, b in (("MULTIPLY", 300.0), ("ADD", 200.0), ("MAXIMUM", 150.0), ("DIVIDE", 0.5)):
            math_node = nodes.new("ShaderNodeMath")
            math_node.operation = op
            math_node.inputs[1].default_value = b
            links.new(value, math_node.inputs[0])
            value = math_node.outputs[0]
    elif graph in ("mix_colour", "colour_to_thickness"):  # the Mix's colour: its Green, or itself
        mix = nodes.new("ShaderNodeMix")
        mix.data_type = "RGBA"
        by_id = {s.identifier: s for s in (*mix.inputs, *mix.outputs)}
        by_id["A_Color"].default_value = (100.0, 700.0, 300.0, 1.0)
        by_id["B_Color"].default_value = (800.0, 200.0, 900.0, 1.0)
        links.new(sep.outputs["Red"], by_id["Factor_Float"])
        value = by_id["Result_Color"]
        if graph == "mix_colour":
            sep2 = nodes.new("ShaderNodeSeparateColor")
            links.new(value, sep2.inputs["Color"])
            value = sep2.outputs["Green"]
    elif graph == "reroute_value":
        constant = nodes.new("ShaderNodeValue")
        constant.outputs[0].default_value = 333.0
        reroute = nodes.new("NodeReroute")
        links.new(constant.outputs[0], reroute.inputs[0])
        value = reroute.outputs[0]
    else:
        colour = tex.outputs["Color"]
        if graph.startswith("colour_ramp"):
            mode, interpolation = {
                "colour_ramp": ("RGB", "EASE"),
                "colour_ramp_hsv": ("HSV", "B_SPLINE"),
                "colour_ramp_constant_alpha": ("RGB", "CONSTANT"),
            }[graph]
            ramp = _colour_ramp(nodes, mode, interpolation)
            links.new(sep.outputs["Blue"], ramp.inputs["Fac"])
            colour = ramp.outputs["Alpha" if graph.endswith("alpha") else "Color"]
        ranged = nodes.new("ShaderNodeMapRange")
        for name, v in (("From Min", 0.0), ("From Max", 1.0), ("To Min", 100.0), ("To Max", 900.0)):
            ranged.inputs[name].default_value = v
        links.new(colour, ranged.inputs["Value"])
        value = ranged.outputs["Result"]
    links.new(value, node.inputs["Thin Film Thickness"])
    obj, _ = _grid_with_pixel_centre_uvs(bpy, width, height)
    obj.data.materials.append(mat)
    socket = node.inputs["Thin Film Thickness"]
    direct = tf.linked.evaluate(obj, obj.data, mat, socket)
    baked = tf.linked._bake(obj, mat, socket)
    assert not direct.baked
    np.testing.assert_allclose(direct.values, baked.values, atol=BAKE_TOLERANCE_NM * 1000)
    if graph in ("colour_to_thickness", "image_colour"):  # the conversion has something to show
        red = tf.linked.linked_nodes.luminance_weights() * [1, 0, 0]
        assert not np.allclose(red, tf.linked.linked_nodes.luminance_weights())
        assert np.ptp(direct.values) > 50.0
