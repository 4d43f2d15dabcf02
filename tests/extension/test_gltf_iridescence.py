"""KHR_materials_iridescence through Blender's bundled glTF add-on, with the extension's hooks
(issue 21): an imported file is previewed with its range, and export → import keeps factor, IOR,
minimum, maximum and the thickness texture.

The test file is written by Blender's own exporter (a plane with an image as its base colour),
then its JSON is edited to carry the iridescence extension as the spec writes it
(``iridescenceThicknessMaximum``, which Blender's importer alone reads as the draft's
``iridescenceThickness`` and so loses).
"""

import importlib
import json

import numpy as np
import pytest

pytestmark = pytest.mark.blender

from _extension import EXTENSION_ID  # noqa: E402

FILE_VALUES = {
    "iridescenceFactor": 0.8,
    "iridescenceIor": 1.45,
    "iridescenceThicknessMinimum": 150.0,
    "iridescenceThicknessMaximum": 820.0,
}
#: 8-bit PNG storage of the green channel: one step of 1/255 of the 670 nm range is 2.6 nm.
PNG_STEP_NM = (820.0 - 150.0) / 255.0


@pytest.fixture
def tf(bpy, package, tmp_path):
    """A fresh file, the extension registered as an enabled add-on (so the glTF add-on finds its
    hooks) and the glTF add-on enabled; the extension's modules as attributes."""
    import addon_utils

    bpy.ops.wm.read_factory_settings(use_empty=True)
    package.register()
    names = (
        "addon.materials.description",
        "addon.materials.gltf",
        "addon.thickness.linked",
        "addon.drawing.scene_draw",
        "addon.bakes.tables",
        "addon.ui.prefs",
    )
    mods = {n.rpartition(".")[2]: importlib.import_module(f"{EXTENSION_ID}.{n}") for n in names}
    entry = bpy.context.preferences.addons.new()
    entry.module = EXTENSION_ID
    mods["prefs"].preferences().cache_dir = str(tmp_path / "cache")
    addon_utils.enable("io_scene_gltf2", default_set=True)
    try:
        yield type("TF", (), mods)
    finally:
        bpy.context.preferences.addons.remove(entry)
        package.unregister()
        mods["tables"].clear_memory_cache()


def _write_source_gltf(bpy, folder):
    """A plane whose iridescence thickness texture's green channel is a known ramp."""
    size = 8
    image = bpy.data.images.new("thickness", size, size)
    rgba = np.zeros((size, size, 4), dtype=np.float32)
    ramp = np.linspace(0.0, 1.0, size * size).reshape(size, size)
    rgba[..., 1], rgba[..., 3] = ramp, 1.0
    image.pixels.foreach_set(rgba.ravel())
    image.filepath_raw = str(folder / "thickness.png")
    image.file_format = "PNG"
    image.save()
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=8, y_subdivisions=8)
    obj = bpy.context.active_object
    mat = bpy.data.materials.new("Iridescent")
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    principled = mat.node_tree.nodes["Principled BSDF"]
    mat.node_tree.links.new(tex.outputs["Color"], principled.inputs["Base Color"])
    obj.data.materials.append(mat)
    path = folder / "source.gltf"
    bpy.ops.export_scene.gltf(filepath=str(path), export_format="GLTF_SEPARATE")
    data = json.loads(path.read_text())
    material = data["materials"][0]
    texture = material["pbrMetallicRoughness"].pop("baseColorTexture")
    material["extensions"] = {
        "KHR_materials_iridescence": {**FILE_VALUES, "iridescenceThicknessTexture": texture}
    }
    data.setdefault("extensionsUsed", []).append("KHR_materials_iridescence")
    path.write_text(json.dumps(data))
    return path


def _clear(bpy):
    """Empty the file's data (factory settings would also reset the add-ons the hooks need)."""
    for collection in (bpy.data.objects, bpy.data.meshes, bpy.data.materials, bpy.data.images):
        for item in list(collection):
            collection.remove(item)
    for group in [g for g in bpy.data.node_groups if g.users == 0]:
        bpy.data.node_groups.remove(group)


def _import(bpy, path):
    _clear(bpy)
    bpy.ops.import_scene.gltf(filepath=str(path))
    return next(m for m in bpy.data.materials if m.node_tree and "Principled BSDF" in m.node_tree.nodes)


def _iridescence(path):
    data = json.loads(path.read_text())
    return data["materials"][0]["extensions"]["KHR_materials_iridescence"], data


def test_imported_iridescence_is_previewed_with_the_files_range(bpy, tf, tmp_path):
    source = _write_source_gltf(bpy, tmp_path)
    mat = _import(bpy, source)
    desc = tf.description.description(mat)
    assert desc is not None and desc.thickness_range_nm is not None
    lo, hi = desc.thickness_range_nm
    # The grid's inner vertices sample the ramp from near its start to near its end.
    assert 150.0 - 0.01 <= lo < 300.0 and 700.0 < hi <= 820.0 + 0.01, (lo, hi)
    assert desc.layers[0].index == pytest.approx(1.45)
    kept = json.loads(mat["KHR_materials_iridescence"])
    assert kept["iridescenceThicknessMaximum"] == 820.0 and kept["hasThicknessTexture"]
    notes = tf.description.warnings(mat)
    assert any("evaluated directly from image 'thickness' 8×8" in n for n in notes), notes
    assert any("iridescence factor 0.8" in n for n in notes), notes


def test_export_then_import_keeps_factor_ior_min_max_and_texture(bpy, tf, tmp_path):
    source = _write_source_gltf(bpy, tmp_path)
    _import(bpy, source)
    out = tmp_path / "round" / "trip.gltf"
    out.parent.mkdir()
    bpy.ops.export_scene.gltf(filepath=str(out), export_format="GLTF_SEPARATE")
    ext, data = _iridescence(out)
    for key, value in FILE_VALUES.items():
        assert ext.get(key) == pytest.approx(value, abs=1e-4), (key, ext)
    assert "KHR_materials_iridescence" in data["extensionsUsed"]
    texture = data["textures"][ext["iridescenceThicknessTexture"]["index"]]
    exported = out.parent / data["images"][texture["source"]]["uri"]
    assert exported.is_file()

    again = _import(bpy, out)
    ext2, _ = _iridescence(out)
    assert ext2 == ext
    desc = tf.description.description(again)
    lo, hi = desc.thickness_range_nm
    assert 150.0 - 0.01 <= lo < 300.0 and 700.0 < hi <= 820.0 + 0.01
    pixels = np.empty(8 * 8 * 4, dtype=np.float32)
    image = next(i for i in bpy.data.images if i.size[0] == 8)
    image.pixels.foreach_get(pixels)
    ramp = np.linspace(0.0, 1.0, 64)
    assert np.max(np.abs(pixels.reshape(-1, 4)[:, 1] - ramp)) <= 0.5 / 255 + 1e-6


def test_a_film_material_exports_iridescence_and_warns_what_gltf_cannot_carry(bpy, tf, tmp_path):
    bpy.ops.mesh.primitive_plane_add()
    obj = bpy.context.active_object
    film = bpy.data.materials.new("Constant")
    node = film.node_tree.nodes["Principled BSDF"]
    node.inputs["Thin Film Thickness"].default_value = 510.0
    node.inputs["Thin Film IOR"].default_value = 1.38
    beetle = bpy.data.materials.new("Beetle")
    beetle.thinfilm_sh.preset = "BEETLE_MULTILAYER"
    beetle.thinfilm_sh.enabled = True
    titanium = bpy.data.materials.new("Titanium")
    titanium.thinfilm_sh.preset = "ANODISED_TITANIUM"
    titanium.thinfilm_sh.enabled = True
    obj.data.materials.append(film)
    for x, mat in ((3, beetle), (6, titanium)):
        bpy.ops.mesh.primitive_plane_add(location=(x, 0, 0))
        bpy.context.active_object.data.materials.append(mat)
    out = tmp_path / "films.gltf"
    bpy.ops.export_scene.gltf(filepath=str(out), export_format="GLTF_SEPARATE")
    data = json.loads(out.read_text())
    by_name = {m["name"]: m.get("extensions", {}).get("KHR_materials_iridescence") for m in data["materials"]}
    assert by_name["Constant"]["iridescenceThicknessMaximum"] == pytest.approx(510.0)
    assert by_name["Constant"]["iridescenceIor"] == pytest.approx(1.38, abs=1e-6)
    assert by_name["Constant"]["iridescenceFactor"] == 1.0
    assert by_name["Beetle"] is not None
    warned = [w for w in tf.gltf.LAST_EXPORT_WARNINGS if "Beetle" in w]
    assert any("film layers" in w for w in warned), tf.gltf.LAST_EXPORT_WARNINGS
    assert by_name["Titanium"] is not None
    assert any("Titanium" in w and "n + ik" in w for w in tf.gltf.LAST_EXPORT_WARNINGS)
    assert not any("Constant" in w for w in tf.gltf.LAST_EXPORT_WARNINGS)

    imported = _import(bpy, out)  # our import hook reads the spec's maximum back
    assert imported is not None
    constant = bpy.data.materials["Constant"]
    assert constant.node_tree.nodes["Principled BSDF"].inputs["Thin Film Thickness"].default_value == 510.0


def test_a_noise_driven_thickness_exports_a_baked_thickness_texture(bpy, tf, tmp_path):
    """Noise Texture → Map Range → Thin Film Thickness has no image: export bakes the thickness
    (Cycles, at the object's UVs) into iridescenceThicknessTexture with the evaluated range, and
    the re-imported material's thickness per corner matches the original to 8-bit steps."""
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16)
    obj = bpy.context.active_object
    mat = bpy.data.materials.new("Oil")
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    bsdf = nodes["Principled BSDF"]
    noise = nodes.new("ShaderNodeTexNoise")
    ranged = nodes.new("ShaderNodeMapRange")
    ranged.inputs["To Min"].default_value, ranged.inputs["To Max"].default_value = 150.0, 850.0
    links.new(noise.outputs["Fac"], ranged.inputs["Value"])
    links.new(ranged.outputs["Result"], bsdf.inputs["Thin Film Thickness"])
    obj.data.materials.append(mat)
    lo, hi = tf.description.description(mat).thickness_range_nm
    socket = bsdf.inputs["Thin Film Thickness"]
    original = tf.linked.evaluate(obj, obj.data, mat, socket).values
    original_keys = _by_position(obj, original, True)
    original_values = _by_position(obj, original)
    out = tmp_path / "oil.gltf"
    bpy.ops.export_scene.gltf(filepath=str(out), export_format="GLTF_SEPARATE")
    ext, data = _iridescence(out)
    assert "iridescenceThicknessTexture" in ext, (ext, tf.gltf.LAST_EXPORT_WARNINGS)
    assert ext["iridescenceThicknessMinimum"] == pytest.approx(lo) and ext[
        "iridescenceThicknessMaximum"
    ] == pytest.approx(hi)

    again = _import(bpy, out)
    imported = next(o for o in bpy.data.objects if o.type == "MESH")
    node = next(n for n in again.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    back = tf.linked.evaluate(imported, imported.data, again, node.inputs["Thin Film Thickness"]).values
    # The importer's mesh has other corners (triangles): compare at equal vertex positions.
    step = (hi - lo) / 255.0
    assert _by_position(imported, back, True) == original_keys
    drift = np.abs(_by_position(imported, back) - original_values)
    assert np.median(drift) < 2 * step, (np.median(drift), step)


def _by_position(obj, values, return_keys=False, keys=None):
    """Mean value per vertex position (rounded to 1e-4), in the order of ``keys``."""
    mesh = obj.data
    co = np.array([v.co[:] for v in mesh.vertices]) @ np.array(obj.matrix_world)[:3, :3].T
    corner_vertex = np.array([loop.vertex_index for loop in mesh.loops])
    found: dict = {}
    for key, value in zip(map(tuple, np.round(co[corner_vertex], 4)), values, strict=True):
        found.setdefault(key, []).append(value)
    if return_keys:
        return sorted(found)
    return np.array([np.mean(found[k]) for k in (keys or sorted(found))])
