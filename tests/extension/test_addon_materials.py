"""The material bridge, settings, operators and registration in a real Blender session (bpy).

The repository is imported as the package ``thinfilm_sh`` through a symlink, as Blender names
the installed extension (see tests/extension/test_extension.py). Every test starts from
``read_factory_settings(use_empty=True)`` with the extension registered, and bakes at a tiny
explicit quality so that a bake takes a fraction of a second.
"""

import importlib
import math

import numpy as np
import pytest

pytestmark = pytest.mark.blender

from _extension import EXTENSION_ID  # noqa: E402
from _waits import EVENT_TIMEOUT_S  # noqa: E402

REGISTER_CYCLES = 10


# ----------------------------------------------------------------------------------------------
# Fixtures
# ----------------------------------------------------------------------------------------------
@pytest.fixture
def ext(bpy, package, tmp_path):
    """A fresh empty file, the extension registered and its preferences' cache in tmp_path."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    package.register()
    prefs = importlib.import_module(f"{EXTENSION_ID}.addon.ui.prefs")
    tables = importlib.import_module(f"{EXTENSION_ID}.addon.bakes.tables")
    tables.clear_memory_cache()
    entry = bpy.context.preferences.addons.new()
    entry.module = EXTENSION_ID
    prefs.preferences().cache_dir = str(tmp_path / "cache")
    try:
        yield package
    finally:
        bpy.context.preferences.addons.remove(entry)
        package.unregister()
        tables.clear_memory_cache()


def _module(name):
    return importlib.import_module(f"{EXTENSION_ID}.{name}")


@pytest.fixture
def description_mod(ext):
    """``thinfilm_sh.addon.materials.description``: what the preview shows for a Blender material."""
    return _module("addon.materials.description")


@pytest.fixture
def principled_mod(ext):
    """``thinfilm_sh.addon.materials.principled``: reading and writing the Principled BSDF."""
    return _module("addon.materials.principled")


@pytest.fixture
def tables_mod(ext):
    """``thinfilm_sh.addon.bakes.tables``: memory, disk cache, bake."""
    return _module("addon.bakes.tables")


@pytest.fixture
def thickness_mod(ext):
    """``thinfilm_sh.addon.thickness.thickness``: the thickness over a mesh."""
    return _module("addon.thickness.thickness")


@pytest.fixture
def conductors_mod(ext):
    """``thinfilm_sh.precompute.materials.conductors`` as the extension imported it."""
    return _module("precompute.materials.conductors")


@pytest.fixture
def noise_mod(ext):
    """``thinfilm_sh.precompute.materials.noise`` as the extension imported it."""
    return _module("precompute.materials.noise")


@pytest.fixture
def pre(ext):
    """``thinfilm_sh.precompute`` as the extension imported it (its classes, not tests' copies)."""
    return importlib.import_module(f"{EXTENSION_ID}.precompute")


def _material(pre):
    return importlib.import_module(f"{pre.__name__}.materials.material")


def _drawn(pre, material):
    """``material`` as the preview bakes it (policy.drawn_material, the extension's copy)."""
    return importlib.import_module(f"{pre.__name__}.shading.policy").drawn_material(material)


def _fast(settings):
    """A tiny explicit quality: a bake takes well under a second."""
    settings.sh_order = "2"
    settings.view_samples = 4
    settings.thickness_samples = 4
    settings.wavelength_count = 32


def _enabled(bpy, name="Film", preset="SOAP_FILM"):
    mat = bpy.data.materials.new(name)
    mat.thinfilm_sh.preset = preset
    mat.thinfilm_sh.enabled = True
    _fast(mat.thinfilm_sh)
    return mat


def _principled(bpy, name="Principled", **values):
    mat = bpy.data.materials.new(name)
    node = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    for socket, value in values.items():
        node.inputs[socket].default_value = value
    return mat, node


# ----------------------------------------------------------------------------------------------
# Settings ↔ description
# ----------------------------------------------------------------------------------------------
def test_enabling_a_new_material_fills_the_soap_film_default(bpy, description_mod, pre):
    mat = bpy.data.materials.new("Bubble")
    settings = mat.thinfilm_sh
    assert not settings.enabled and len(settings.layers) == 0 and settings.preset == "SOAP_FILM"
    assert description_mod.description(mat) is None  # disabled, and the default Principled has no film
    settings.enabled = True
    assert len(settings.layers) == 1
    # the preset as the preview bakes it: glossy, so drawn by the split sum alone at order 0
    drawn = _drawn(pre, _material(pre).PRESETS["soap_film"])
    assert drawn.quality.sh_order == 0 and description_mod.description(mat) == drawn


def test_each_preset_describes_exactly_the_precompute_preset(bpy, description_mod, pre):
    presets = _material(pre).PRESETS
    mat = bpy.data.materials.new("Preset")
    mat.thinfilm_sh.enabled = True
    for name, expected in presets.items():
        mat.thinfilm_sh.preset = name.upper()
        desc = description_mod.description(mat)
        # Float32 properties come back as the decimals typed in the preset, so the two are
        # equal and share one cache key with the CLI's bake of the same preset (the glossy ones
        # with the automatic order the preview bakes them at: policy.drawn_material).
        expected = _drawn(pre, expected)
        assert desc == expected, name
        assert description_mod.description_key(desc) == description_mod.description_key(expected), name
        assert mat.thinfilm_sh.preset == name.upper()
    # Editing a physical setting by hand leaves the preset; viewing settings do not.
    mat.thinfilm_sh.colour_mode = "PER_CHANNEL"
    assert mat.thinfilm_sh.preset == "COATED_CAR_WINDOW"
    mat.thinfilm_sh.layers[0].thickness_nm = 150.0
    assert mat.thinfilm_sh.preset == "CUSTOM"
    bpy.ops.thinfilm.apply_preset(material=mat.name, preset="HEAT_TINTED_STEEL")
    assert mat.thinfilm_sh.preset == "HEAT_TINTED_STEEL"
    steel = _drawn(pre, presets["heat_tinted_steel"])
    assert description_mod.description(mat).with_(colour_mode="spectral") == steel


def test_layer_operators_add_remove_and_move(bpy, description_mod):
    mat = _enabled(bpy, preset="OIL_ON_WATER")
    settings = mat.thinfilm_sh
    settings.layers[0].n = 1.5
    assert bpy.ops.thinfilm.layer_add(material=mat.name) == {"FINISHED"}
    assert len(settings.layers) == 2 and settings.active_layer_index == 1
    settings.layers[1].n, settings.layers[1].thickness_nm = 2.0, 100.0
    assert bpy.ops.thinfilm.layer_move(material=mat.name, direction="UP") == {"FINISHED"}
    assert [layer.n for layer in settings.layers] == pytest.approx([2.0, 1.5])
    assert settings.active_layer_index == 0
    desc = description_mod.description(mat)
    assert [layer.index for layer in desc.layers] == [2.0, 1.5]
    assert bpy.ops.thinfilm.layer_remove(material=mat.name) == {"FINISHED"}
    assert [layer.n for layer in settings.layers] == pytest.approx([1.5])
    assert settings.preset == "CUSTOM"


# ----------------------------------------------------------------------------------------------
# Principled BSDF interop
# ----------------------------------------------------------------------------------------------
def test_principled_thin_film_is_previewed_from_its_own_values(bpy, description_mod):
    mat, _ = _principled(
        bpy,
        **{"Thin Film Thickness": 500.0, "IOR": 1.45, "Thin Film IOR": 1.33, "Roughness": 0.4},
    )
    desc = description_mod.description(mat)
    assert desc is not None
    assert [(layer.index, layer.thickness_nm) for layer in desc.layers] == [(1.33, 500.0)]
    assert (desc.substrate, desc.roughness, desc.ambient) == (1.45, 0.4, 1.0)
    assert desc.colour_mode == "per_channel" and desc.thickness_range_nm is None
    # An opaque dielectric shows its Base Color as the diffuse base (Principled default 0.8).
    assert desc.base_color == (0.8, 0.8, 0.8)
    assert description_mod.warnings(mat) == []


def test_principled_black_base_color_has_no_diffuse_base_and_gets_world_lamps(bpy, description_mod):
    """Cycles gives a black Base Color no diffuse lobe: the preview shows the film alone, and
    with it the World's lamps (scene_draw.uses_lamps), as for the extension's own films."""
    scene_draw = _module("addon.drawing.scene_draw")
    mat, node = _principled(bpy, **{"Thin Film Thickness": 500.0, "Base Color": (0.0, 0.0, 0.0, 1.0)})
    desc = description_mod.description(mat)
    assert desc.base_color is None
    assert scene_draw.uses_lamps(mat, desc)
    node.inputs["Base Color"].default_value = (0.5, 0.5, 0.5, 1.0)
    grey = description_mod.description(mat)
    assert grey.base_color == (0.5, 0.5, 0.5)  # a diffuse base of that albedo
    assert not scene_draw.uses_lamps(mat, grey)  # under a diffuse base the lamps stay in the World
    node.inputs["Base Color"].default_value = (0.0, 0.0, 2e-6, 1.0)  # below Cycles' closure cutoff
    assert description_mod.description(mat).base_color is None
    node.inputs["Base Color"].default_value = (0.0, 0.0, 0.25, 1.0)  # only as much as it is not black
    assert description_mod.description(mat).base_color == (0.0, 0.0, 0.25)


def test_principled_zero_thickness_or_no_principled_is_not_previewed(bpy, description_mod):
    # Thickness 0 is the bare Principled BSDF, which Blender's viewport already shows.
    mat, node = _principled(bpy, **{"Thin Film Thickness": 0.0})
    assert description_mod.description(mat) is None
    mat.node_tree.nodes.remove(node)
    assert description_mod.description(mat) is None


def test_principled_linked_socket_without_users_uses_its_value_and_warns(bpy, description_mod):
    # No object uses the material, so the link has no surface to be evaluated on (issue 21:
    # tests/extension/test_linked_thickness.py evaluates it over the objects that use it).
    mat, node = _principled(bpy, **{"Thin Film Thickness": 320.0, "Transmission Weight": 1.0})
    value = mat.node_tree.nodes.new("ShaderNodeValue")
    mat.node_tree.links.new(value.outputs[0], node.inputs["Thin Film Thickness"])
    desc = description_mod.description(mat)
    assert desc.layers[0].thickness_nm == 320.0
    assert desc.base_color is None  # transmissive: the film alone
    notes = description_mod.warnings(mat)
    assert len(notes) == 1 and "Thin Film Thickness" in notes[0] and "320" in notes[0]


def test_principled_inputs_the_film_leaves_out_are_named(bpy, description_mod):
    """A coat, sheen, emission, specular level, alpha, anisotropy, a dielectric's specular tint
    and (under a diffuse base) subsurface and diffuse roughness: the film's preview and EEVEE
    output leave them out, and the panel's notes name each; Blender's defaults name none."""
    plain, _ = _principled(bpy, "plain", **{"Thin Film Thickness": 300.0})
    assert description_mod.warnings(plain) == []
    set_to = {
        "Coat Weight": 0.4,
        "Sheen Weight": 0.2,
        "Emission Strength": 3.0,
        "Anisotropic": 0.5,
        "Specular IOR Level": 0.8,
        "Alpha": 0.5,
        "Specular Tint": (1.0, 0.5, 0.5, 1.0),
        "Subsurface Weight": 0.3,
        "Diffuse Roughness": 0.6,
    }
    mat, node = _principled(bpy, "coated", **{"Thin Film Thickness": 300.0}, **set_to)
    notes = description_mod.warnings(mat)
    for name in set_to:
        assert sum(f"'{name}'" in note for note in notes) == 1, (name, notes)
    assert description_mod.description(mat).base_color is not None  # still previewed, with its base
    # a link counts as set; emission of a black colour is none; a metal's tint is its F82 tint
    mat2, node2 = _principled(
        bpy, "metal", **{"Thin Film Thickness": 300.0, "Metallic": 1.0, "Specular Tint": (1.0, 0.5, 0.5, 1.0)}
    )
    node2.inputs["Emission Strength"].default_value = 5.0
    node2.inputs["Emission Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    value = mat2.node_tree.nodes.new("ShaderNodeValue")
    mat2.node_tree.links.new(value.outputs[0], node2.inputs["Coat Weight"])
    notes = description_mod.warnings(mat2)
    assert [n for n in notes if "'" in n and "rendered by Cycles" in n] == [
        n for n in notes if "'Coat Weight'" in n
    ] and len([n for n in notes if "'Coat Weight'" in n and "linked" in n]) == 1, notes


def test_shading_path_names_the_path_the_roughness_selects(tables_mod):
    from precompute.shading import policy

    lo, hi = policy.SH_BLEND
    assert tables_mod.shading_path(0.0) == tables_mod.shading_path(lo) == "Shading: split sum (glossy)"
    assert (
        tables_mod.shading_path(hi) == tables_mod.shading_path(1.0) == "Shading: spherical harmonics (rough)"
    )
    mid = tables_mod.shading_path(0.5 * (lo + hi))  # smoothstep midpoint: half and half
    assert mid == "Shading: split sum 50 % + SH 50 %", mid
    w = policy.sh_weight(0.3)
    assert f"SH {100 * w:.0f} %" in tables_mod.shading_path(0.3) and 0.0 < w < 0.5


def test_gulbrandsen_fit_reproduces_normal_incidence_reflectivity(conductors_mod):
    r = np.linspace(0.0, 0.95, 20)[:, None]
    g = np.linspace(0.0, 1.0, 11)[None, :]
    n, k = conductors_mod.gulbrandsen_nk(r, g)
    f0 = ((n - 1) ** 2 + k**2) / ((n + 1) ** 2 + k**2)
    np.testing.assert_allclose(f0, np.broadcast_to(r, f0.shape), atol=1e-12)
    assert np.all(k >= 0) and np.all(n > 0)


def test_principled_metal_becomes_a_conductor_matching_base_color(bpy, description_mod, conductors_mod, pre):
    base = (0.9, 0.6, 0.3)
    mat, _ = _principled(bpy, **{"Thin Film Thickness": 200.0, "Metallic": 1.0, "Base Color": (*base, 1.0)})
    desc = description_mod.description(mat)
    # Blender's own F82-tint metal: what Cycles' per-channel film evaluates (precompute/
    # film_channels.py); spectrally the Gulbrandsen fit checked below.
    assert desc.base_color is None
    assert desc.substrate == {"f82_tint": {"f0": list(base), "tint": [1.0, 1.0, 1.0]}}
    optics = importlib.import_module(f"{pre.__name__}.optics")
    substrate = desc.indices()[-1]
    # R, G, B sit at RGB_WAVELENGTHS_NM (blue, green, red).
    f0 = optics.reflectance([1.0, substrate], [], list(conductors_mod.RGB_WAVELENGTHS_NM), [1.0])[0]
    np.testing.assert_allclose(f0[::-1], base, atol=1e-5)
    # Specular Tint white: the edge reflectance follows Schlick (Blender's F82 tint of 1) closely.
    f82 = optics.reflectance(
        [1.0, substrate], [], list(conductors_mod.RGB_WAVELENGTHS_NM), [conductors_mod.F82_COS]
    )[0]
    schlick = np.array(base) + (1 - np.array(base)) * (1 - conductors_mod.F82_COS) ** 5
    np.testing.assert_allclose(f82[::-1], schlick, atol=0.03)


# ----------------------------------------------------------------------------------------------
# Write-back
# ----------------------------------------------------------------------------------------------
def test_write_back_round_trips_through_the_principled_bsdf(bpy, principled_mod, description_mod):
    mat = _enabled(bpy, preset="COATED_CAR_WINDOW")
    settings = mat.thinfilm_sh
    settings.vary_thickness = False
    settings.roughness = 0.25
    settings.diffuse_base = True
    settings.diffuse_color = (0.1, 0.2, 0.3)
    # No Principled yet: write-back creates one and connects it to the output.
    for node in list(mat.node_tree.nodes):
        if node.bl_idname == "ShaderNodeBsdfPrincipled":
            mat.node_tree.nodes.remove(node)
    assert bpy.ops.thinfilm.write_to_principled(material=mat.name) == {"FINISHED"}
    node = principled_mod.principled_node(mat)
    assert node is not None and node.outputs["BSDF"].is_linked
    props_desc = description_mod.description(mat)
    settings.enabled = False
    back = description_mod.description(mat)
    assert back == props_desc.with_(
        colour_mode="per_channel", quality=back.quality, **principled_mod._CYCLES_PARITY
    )
    assert description_mod.warnings(mat) == []

    # Without the diffuse base the substrate transmits (glass), and the preview shows the film alone.
    settings.enabled = True
    settings.diffuse_base = False
    settings.vary_thickness = True
    notes = principled_mod.write_back_to_principled(mat)
    # The varying thickness is written as nodes (issue 21): the value noise becomes Blender's
    # Noise Texture, with a note; no object uses the material, so the socket's own value (the
    # middle) is what the description reads back.
    assert node.inputs["Thin Film Thickness"].is_linked
    assert any("Noise Texture" in note for note in notes)
    settings.enabled = False
    back = description_mod.description(mat)
    assert back.base_color is None and node.inputs["Transmission Weight"].default_value == 1.0
    # Cycles tints the transmission by Base Color: the diffuse base's (0.1, 0.2, 0.3) written
    # before (or Blender's default 0.8) would tint the glass the preview shows clear.
    assert tuple(node.inputs["Base Color"].default_value) == (1.0, 1.0, 1.0, 1.0)
    lo, hi = props_desc.thickness_range_nm or (settings.thickness_min_nm, settings.thickness_max_nm)
    assert back.layers[0].thickness_nm == pytest.approx(0.5 * (lo + hi))


def test_write_back_of_a_metal_substrate_and_a_multilayer(
    bpy, principled_mod, conductors_mod, description_mod, pre
):
    mat = _enabled(bpy, preset="ANODISED_TITANIUM")
    settings = mat.thinfilm_sh
    settings.substrate_metal = "GOLD"
    principled_mod.write_back_to_principled(mat)
    node = principled_mod.principled_node(mat)
    assert node.inputs["Metallic"].default_value == 1.0
    base = tuple(node.inputs["Base Color"].default_value)[:3]
    expected, _ = conductors_mod.metal_rgb({"metal": "gold"})
    assert base == pytest.approx(expected, abs=1e-6)
    assert base[0] > base[1] > base[2]  # gold is yellow
    # The film: Cauchy A + B/λ² at 550 nm.
    n550 = 2.30 + 0.045 / 0.55**2
    assert node.inputs["Thin Film IOR"].default_value == pytest.approx(n550, rel=1e-6)
    settings.enabled = False
    back = description_mod.description(mat)
    optics = importlib.import_module(f"{pre.__name__}.optics")
    f0 = optics.reflectance([1.0, back.indices()[-1]], [], list(conductors_mod.RGB_WAVELENGTHS_NM), [1.0])[0]
    np.testing.assert_allclose(f0[::-1], np.minimum(base, 0.99), atol=1e-5)

    beetle = _enabled(bpy, "Beetle", preset="BEETLE_MULTILAYER")
    notes = principled_mod.write_back_to_principled(beetle)
    assert any("single film" in note for note in notes)


# ----------------------------------------------------------------------------------------------
# Tables
# ----------------------------------------------------------------------------------------------
def test_equal_settings_share_one_bake_and_only_relevant_changes_rebake(
    bpy, tables_mod, description_mod, tmp_path
):
    cache = importlib.import_module(f"{EXTENSION_ID}.precompute.tables.table_cache").TableCache(tmp_path)
    a, b = _enabled(bpy, "A"), _enabled(bpy, "B")
    start = tables_mod.bake_count
    ta = tables_mod.get_table(description_mod.description(a), cache)
    tb = tables_mod.get_table(description_mod.description(b), cache)
    assert tables_mod.bake_count == start + 1 and tb is ta
    assert description_mod.description_key(description_mod.description(a)) == description_mod.description_key(
        description_mod.description(b)
    )

    # The soap film varies its thickness: the top layer's own thickness is unused (issue 24).
    assert b.thinfilm_sh.vary_thickness
    b.thinfilm_sh.layers[0].thickness_nm = 420.0
    assert tables_mod.get_table(description_mod.description(b), cache) is ta
    assert tables_mod.bake_count == start + 1
    b.thinfilm_sh.thickness_max_nm = 900.0
    tables_mod.get_table(description_mod.description(b), cache)
    assert tables_mod.bake_count == start + 2

    # Settings the film does not depend on: no bake.
    a.diffuse_color = (0.1, 0.9, 0.1, 1.0)
    mesh = bpy.data.meshes.new("m")
    obj = bpy.data.objects.new("o", mesh)
    obj.color = (1.0, 0.0, 0.0, 1.0)
    obj.active_material = a
    assert tables_mod.get_table(description_mod.description(a), cache) is ta
    assert tables_mod.bake_count == start + 2


def test_disk_cache_is_used_and_a_corrupt_entry_is_rebaked(bpy, description_mod, tables_mod, tmp_path):
    table_io = importlib.import_module(f"{EXTENSION_ID}.precompute.tables.table_io")
    table_cache = importlib.import_module(f"{EXTENSION_ID}.precompute.tables.table_cache")
    cache = table_cache.TableCache(tmp_path)
    desc = description_mod.description(_enabled(bpy))
    start = tables_mod.bake_count
    baked = tables_mod.get_table(desc, cache)
    path = cache.path_for(description_mod.description_key(desc))
    assert path.is_file() and tables_mod.bake_count == start + 1

    tables_mod.clear_memory_cache()
    loaded, source = tables_mod.get_table_with_source(desc, cache)
    assert source == "disk" and tables_mod.bake_count == start + 1
    np.testing.assert_allclose(loaded.data, baked.data, rtol=1e-6, atol=1e-7)  # float32 on disk
    planner = importlib.import_module(f"{EXTENSION_ID}.precompute.bakes.planner")
    assert loaded.sh_order == baked.sh_order and loaded.material == planner.table_material(desc)
    np.testing.assert_array_equal(loaded.thicknesses_nm, baked.thicknesses_nm)
    np.testing.assert_allclose(loaded.view_angles_rad, baked.view_angles_rad)
    assert tables_mod.format_plan(loaded) == tables_mod.format_plan(baked)

    tables_mod.clear_memory_cache()
    raw = bytearray(path.read_bytes())
    raw[len(raw) // 2] ^= 0xFF
    path.write_bytes(bytes(raw))
    again, source = tables_mod.get_table_with_source(desc, cache)
    assert source == "bake" and tables_mod.bake_count == start + 2
    np.testing.assert_allclose(again.data, baked.data)
    assert path.with_name(path.name + ".corrupt").is_file()
    assert table_io.read_table(path).content_hash  # the fresh table replaced it


def test_a_table_cached_by_an_older_planner_is_not_reused(
    bpy, description_mod, tables_mod, tmp_path, monkeypatch
):
    """After an upgrade that changes automatic choices (e.g. the SH order cap 8 → 12), a cached
    table is stale, not corrupt: the key carries bake.PLANNER_VERSION, so it is baked again."""
    table_cache = importlib.import_module(f"{EXTENSION_ID}.precompute.tables.table_cache")
    planner = importlib.import_module(f"{EXTENSION_ID}.precompute.bakes.planner")
    cache = table_cache.TableCache(tmp_path)
    desc = description_mod.description(_enabled(bpy))
    start = tables_mod.bake_count
    monkeypatch.setattr(planner, "PLANNER_VERSION", planner.PLANNER_VERSION - 1)
    old_key = description_mod.description_key(desc)
    tables_mod.get_table(desc, cache)
    assert cache.path_for(old_key).is_file() and tables_mod.bake_count == start + 1
    monkeypatch.undo()
    tables_mod.clear_memory_cache()
    new_key = description_mod.description_key(desc)
    assert new_key != old_key
    _table, source = tables_mod.get_table_with_source(desc, cache)
    assert source == "bake" and tables_mod.bake_count == start + 2 and cache.path_for(new_key).is_file()


def test_nan_thickness_is_a_clear_error_not_a_traceback(bpy, description_mod):
    mat = _enabled(bpy)
    mat.thinfilm_sh.layers[0].thickness_nm = math.nan
    with pytest.raises(ValueError, match="thickness"):
        description_mod.description(mat)
    with pytest.raises(RuntimeError) as caught:  # bpy.ops turns an ERROR report into RuntimeError
        bpy.ops.thinfilm.bake(material=mat.name)
    message = str(caught.value)
    assert "thickness" in message and "Traceback" not in message
    assert "thickness" in mat.thinfilm_sh.last_error
    with pytest.raises(RuntimeError) as caught:
        bpy.ops.thinfilm.bake("INVOKE_DEFAULT", material=mat.name)
    assert "Traceback" not in str(caught.value)


def test_bake_operator_runs_synchronously_in_background_mode(bpy, tables_mod, description_mod):
    assert bpy.app.background
    mat = _enabled(bpy)
    settings = mat.thinfilm_sh
    start = tables_mod.bake_count
    assert bpy.ops.thinfilm.bake("INVOKE_DEFAULT", material=mat.name) == {"FINISHED"}
    assert tables_mod.bake_count == start + 1
    assert settings.last_bake_ms > 0.0 and settings.last_error == ""
    plan = tables_mod.parse_plan(settings.last_plan)
    assert plan["sh_order"] == "2" and plan["view_samples"] == "4" and plan["source"] == "bake"
    assert int(plan["wavelength_count"]) >= 32
    assert bpy.ops.thinfilm.bake(material=mat.name) == {"FINISHED"}
    assert (
        tables_mod.parse_plan(settings.last_plan)["source"] == "memory" and tables_mod.bake_count == start + 1
    )
    assert tables_mod.peek_table(description_mod.description(mat)) is not None


def test_bake_job_runs_in_a_thread_and_cancel_discards_the_result(bpy, description_mod, tables_mod, tmp_path):
    ops = importlib.import_module(f"{EXTENSION_ID}.addon.ui.ops")
    cache = importlib.import_module(f"{EXTENSION_ID}.precompute.tables.table_cache").TableCache(tmp_path)
    desc = description_mod.description(_enabled(bpy))
    start = tables_mod.bake_count

    job = ops.BakeJob(desc, cache)
    job.cancel()
    job.start().join(EVENT_TIMEOUT_S)
    assert job.done.is_set(), f"a cancelled bake job did not end in {EVENT_TIMEOUT_S:.0f} s"
    assert job.cancelled and job.result is None and job.error is None
    assert (
        tables_mod.bake_count == start
        and tables_mod.peek_table(desc) is None
        and not list(tmp_path.iterdir())
    )

    job = ops.BakeJob(desc, cache).start()
    job.join(EVENT_TIMEOUT_S)
    assert job.done.is_set(), f"a bake job did not end in {EVENT_TIMEOUT_S:.0f} s"
    assert job.error is None and job.source == "bake"
    assert (
        job.fraction == 1.0
        and tables_mod.peek_table(desc) is job.result
        and tables_mod.bake_count == start + 1
    )


def test_clear_cache_operator_empties_memory_and_disk(bpy, tables_mod, description_mod):
    mat = _enabled(bpy)
    bpy.ops.thinfilm.bake(material=mat.name)
    cache = tables_mod.table_cache()
    assert list(cache.tables_dir.glob("*.exr"))
    assert bpy.ops.thinfilm.clear_cache() == {"FINISHED"}
    assert (
        not list(cache.tables_dir.glob("*.exr"))
        and tables_mod.peek_table(description_mod.description(mat)) is None
    )


def test_clear_cache_operator_leaves_foreign_exr_files_alone(bpy, tables_mod, description_mod):
    """Issue 24: the cache folder is a preference, so it may hold the user's HDRIs; clearing
    deletes only the tables the cache wrote (tagged, in its own subfolder)."""
    image_io = importlib.import_module(f"{EXTENSION_ID}.precompute.output.image_io")
    table_io = importlib.import_module(f"{EXTENSION_ID}.precompute.tables.table_io")
    cache = tables_mod.table_cache()
    hdri = cache.directory / "courtyard.exr"
    hdri.parent.mkdir(parents=True)
    image_io.write_exr(hdri, np.full((4, 8, 3), 0.5))
    mat = _enabled(bpy)
    assert bpy.ops.thinfilm.bake(material=mat.name) == {"FINISHED"}
    entry = cache.path_for(description_mod.description_key(description_mod.description(mat)))
    # A table the user wrote into the subfolder under a key-like name: valid, but not tagged.
    mine = table_io.write_table(cache.tables_dir / "0123456789abcdef.exr", np.ones((2, 3)))
    sidecar = cache.directory / "notes.exr.txt"
    sidecar.write_text("keep me")
    before = {p: p.read_bytes() for p in (hdri, mine, sidecar)}

    assert bpy.ops.thinfilm.clear_cache() == {"FINISHED"}
    assert not entry.exists()
    assert {p: p.read_bytes() for p in before} == before


def test_cache_location_env_preference_default_and_size_limit(bpy, ext, tables_mod, tmp_path, monkeypatch):
    """Issue 24: THINFILM_SH_CACHE wins inside Blender too; an empty preference means the private
    per-user default (never $TMPDIR); the size limit preference reaches the TableCache."""
    prefs = importlib.import_module(f"{EXTENSION_ID}.addon.ui.prefs")
    table_cache = importlib.import_module(f"{EXTENSION_ID}.precompute.tables.table_cache")
    monkeypatch.delenv("THINFILM_SH_CACHE", raising=False)
    monkeypatch.delenv("THINFILM_SH_CACHE_MAX_BYTES", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    settings = prefs.preferences()
    assert settings.cache_limit_mib == 2048

    chosen = tables_mod.table_cache()
    assert chosen.directory == tmp_path / "cache" and chosen.max_bytes == 2 * 1024**3
    settings.cache_limit_mib = 3
    assert tables_mod.table_cache().max_bytes == 3 * 1024**2

    settings.cache_dir = ""
    default = tables_mod.table_cache()
    assert default.directory == tmp_path / "xdg" / "thinfilm_sh" and default.private
    assert prefs.cache_dir() == str(default.directory)

    monkeypatch.setenv("THINFILM_SH_CACHE", str(tmp_path / "env"))
    settings.cache_dir = str(tmp_path / "pref")
    assert tables_mod.table_cache().directory == tmp_path / "env"
    assert prefs.cache_location() == (None, "THINFILM_SH_CACHE")
    monkeypatch.setenv("THINFILM_SH_CACHE_MAX_BYTES", "5M")
    assert tables_mod.table_cache().max_bytes == 5 * 1024**2
    with tables_mod.cache_dir_override(tmp_path / "flag"):  # the headless --cache-dir
        assert tables_mod.table_cache().directory == tmp_path / "flag"
    monkeypatch.delenv("THINFILM_SH_CACHE")

    settings.cache_dir = "//tables"  # relative to a .blend file that is not saved
    with pytest.raises(table_cache.CacheDirError, match="not saved"):
        tables_mod.table_cache()
    assert any("unusable" in line and "not saved" in line for line, _icon in prefs.cache_status())


def test_an_unusable_or_full_cache_keeps_the_table_in_memory_and_says_why(
    bpy, ext, tables_mod, description_mod, tmp_path, monkeypatch
):
    """Issue 24: a full cache disk (simulated ENOSPC) or an unsafe cache folder is a clear
    message in the operator and the panel, never a traceback; the baked table is kept."""
    import errno

    atomic_write = importlib.import_module(f"{EXTENSION_ID}.precompute.tables.atomic_write")
    table_cache = importlib.import_module(f"{EXTENSION_ID}.precompute.tables.table_cache")
    ui = importlib.import_module(f"{EXTENSION_ID}.addon.ui.ui")

    def full(self, key, *args, **kwargs):
        path = self.path_for(key)
        raise atomic_write.TableWriteError(
            path, f"could not write {str(path)!r}: No space left on device", errno.ENOSPC
        )

    monkeypatch.setattr(table_cache.TableCache, "store", full)
    mat = _enabled(bpy)
    desc = description_mod.description(mat)
    assert bpy.ops.thinfilm.bake(material=mat.name) == {"FINISHED"}
    assert tables_mod.peek_table(desc) is not None
    problem = tables_mod.cache_error(desc)
    assert "No space left on device" in problem and "kept in memory" in problem
    assert any("No space left" in line for line in ui.material_errors(mat))
    monkeypatch.undo()

    tables_mod.clear_memory_cache()
    link = tmp_path / "link"
    link.symlink_to(tmp_path / "cache", target_is_directory=True)
    importlib.import_module(f"{EXTENSION_ID}.addon.ui.prefs").preferences().cache_dir = str(link)
    other = _enabled(bpy, "Other")
    other.thinfilm_sh.roughness = 0.4
    assert bpy.ops.thinfilm.bake(material=other.name) == {"FINISHED"}
    problem = tables_mod.cache_error(description_mod.description(other))
    assert "symbolic link" in problem and "Traceback" not in problem
    assert any("symbolic link" in line for line in ui.material_errors(other))
    with pytest.raises(RuntimeError) as caught:  # an ERROR report, not a traceback
        bpy.ops.thinfilm.clear_cache()
    assert "symbolic link" in str(caught.value) and "Traceback" not in str(caught.value)


# ----------------------------------------------------------------------------------------------
# Thickness over the surface
# ----------------------------------------------------------------------------------------------
def _quad(bpy, name="Quad"):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [], [(0, 1, 2, 3)])
    obj = bpy.data.objects.new(name, mesh)
    return obj, mesh


def test_thickness_from_an_attribute_on_points_or_corners(bpy, thickness_mod):
    obj, mesh = _quad(bpy)
    settings = _enabled(bpy).thinfilm_sh
    settings.thickness_source = "ATTRIBUTE"
    settings.thickness_attribute = "film"
    with pytest.raises(ValueError, match="no attribute 'film'"):
        thickness_mod.thickness_per_vertex(obj, mesh, settings)

    attribute = mesh.attributes.new("film", "FLOAT", "POINT")
    attribute.data.foreach_set("value", [0.0, 0.25, 2.0, 0.75])
    values = thickness_mod.thickness_per_vertex(obj, mesh, settings)
    corner_vertices = [loop.vertex_index for loop in mesh.loops]
    np.testing.assert_allclose(values, np.array([0.0, 0.25, 1.0, 0.75])[corner_vertices])  # clipped

    mesh.attributes.remove(mesh.attributes["film"])
    attribute = mesh.attributes.new("film", "FLOAT", "CORNER")
    attribute.data.foreach_set("value", [0.1, 0.2, 0.3, 0.4])
    np.testing.assert_allclose(
        thickness_mod.thickness_per_vertex(obj, mesh, settings), [0.1, 0.2, 0.3, 0.4], rtol=1e-6
    )

    mesh.attributes.remove(mesh.attributes["film"])
    mesh.attributes.new("film", "FLOAT", "FACE").data.foreach_set("value", [0.6])
    np.testing.assert_allclose(thickness_mod.thickness_per_vertex(obj, mesh, settings), [0.6] * 4, rtol=1e-6)
    mesh.attributes.remove(mesh.attributes["film"])
    mesh.attributes.new("film", "FLOAT_VECTOR", "POINT")
    with pytest.raises(ValueError, match="FLOAT attribute"):
        thickness_mod.thickness_per_vertex(obj, mesh, settings)

    order = thickness_mod.corner_order(mesh)
    assert order.shape == (6,) and set(order.tolist()) == {0, 1, 2, 3}
    settings.vary_thickness = False
    assert thickness_mod.thickness_per_vertex(obj, mesh, settings) is None


def test_thickness_from_noise_is_deterministic_and_in_range(bpy, thickness_mod, noise_mod):
    mesh = bpy.data.meshes.new("Grid")
    grid = np.stack(np.meshgrid(np.linspace(-1, 1, 20), np.linspace(-1, 1, 20), [0.3]), -1).reshape(-1, 3)
    mesh.from_pydata(grid.tolist(), [], [(i, i + 1, i + 21, i + 20) for i in range(19)])
    obj = bpy.data.objects.new("Grid", mesh)
    settings = _enabled(bpy).thinfilm_sh
    settings.thickness_source = "NOISE"
    settings.noise_scale, settings.noise_seed = 3.0, 7
    first = thickness_mod.thickness_per_vertex(obj, mesh, settings)
    assert first.shape == (len(mesh.loops),)
    assert np.all((first >= 0) & (first <= 1)) and np.ptp(first) > 0.1
    np.testing.assert_array_equal(first, thickness_mod.thickness_per_vertex(obj, mesh, settings))
    settings.noise_seed = 8
    assert not np.allclose(first, thickness_mod.thickness_per_vertex(obj, mesh, settings))

    points = np.random.default_rng(0).uniform(-50, 50, (5000, 3))
    noise = noise_mod.value_noise(points, 1.7, 3)
    assert noise.min() >= 0 and noise.max() <= 1
    step = noise_mod.value_noise(points + 1e-4, 1.7, 3) - noise
    assert np.abs(step).max() < 1e-2  # continuous


def test_thickness_from_an_image_samples_bilinearly_at_uvs(bpy, thickness_mod):
    obj, mesh = _quad(bpy)
    uv = mesh.uv_layers.new(name="UVMap")
    image = bpy.data.images.new("Thickness", 4, 2, float_buffer=True)
    first = np.array([[0.0, 0.2, 0.4, 0.6], [0.1, 0.3, 0.5, 0.7]])  # row 0 is the bottom
    pixels = np.zeros((2, 4, 4), dtype=np.float32)
    pixels[:, :, 0] = first
    pixels[:, :, 1:] = 0.9
    image.pixels.foreach_set(pixels.ravel())
    # Corner 0 at pixel (0, 0)'s centre, corner 1 at (2, 1)'s, corner 2 between (1, 0) and (2, 0),
    # corner 3 in the middle of pixels (0..1, 0..1).
    uvs = [(0.125, 0.25), (0.625, 0.75), (0.5, 0.25), (0.25, 0.5)]
    uv.data.foreach_set("uv", np.array(uvs, dtype=np.float32).ravel())
    settings = _enabled(bpy).thinfilm_sh
    settings.thickness_source = "IMAGE"
    with pytest.raises(ValueError, match="needs an image"):
        thickness_mod.thickness_per_vertex(obj, mesh, settings)
    settings.thickness_image = image
    values = thickness_mod.thickness_per_vertex(obj, mesh, settings)
    np.testing.assert_allclose(values, [0.0, 0.5, 0.3, 0.15], atol=1e-6)
    # per pixel (TF_THICKNESS_MAP): the map is the first channel itself, read at the same UVs,
    # and repeats as Image Texture does; its bilinear read at the corners is the corners' value
    uv_out, values_map, repeat = thickness_mod.image_map(obj, mesh, settings)
    np.testing.assert_array_equal(values_map, first.astype(np.float32))
    np.testing.assert_allclose(uv_out, uvs, atol=1e-7)
    assert repeat
    maps = importlib.import_module(f"{EXTENSION_ID}.addon.thickness.maps")
    np.testing.assert_allclose(maps.sample_bilinear(values_map, uv_out, repeat), values, atol=1e-6)
    wide = bpy.data.images.new("Wide", 1100, 2, float_buffer=True)  # over MAP_MAX_SIZE (1024)
    ramp = np.zeros((2, 1100, 4), dtype=np.float32)
    ramp[..., 0] = np.arange(1100) / 1099.0
    wide.pixels.foreach_set(ramp.ravel())
    settings.thickness_image = wide
    _, resampled, _ = thickness_mod.image_map(obj, mesh, settings)
    u = (np.arange(1024) + 0.5) / 1024  # read at the 1024 texel centres, bilinearly
    inner = slice(1, -1)  # the end texels blend with the other end (the image repeats)
    assert resampled.shape == (2, 1024)
    np.testing.assert_allclose(resampled[0, inner], ((u * 1100 - 0.5) / 1099.0)[inner], atol=1e-6)
    double = bpy.data.images.new("Double", 2048, 2, float_buffer=True)  # 2:1, each pair averaged
    ramp = np.zeros((2, 2048, 4), dtype=np.float32)
    ramp[..., 0] = np.arange(2048) / 2047.0
    double.pixels.foreach_set(ramp.ravel())
    settings.thickness_image = double
    _, halved, _ = thickness_mod.image_map(obj, mesh, settings)
    np.testing.assert_allclose(halved[0], (2 * np.arange(1024) + 0.5) / 2047.0, atol=1e-6)
    settings.thickness_image = image
    srgb = bpy.data.images.new("Thickness sRGB", 4, 2)  # 8-bit, sRGB: decoded as Cycles reads it
    pixels[:, :, 0] = np.round(first * 255) / 255
    srgb.pixels.foreach_set(pixels.ravel())
    settings.thickness_image = srgb
    decoded = np.where(first <= 0.04045, first / 12.92, ((first + 0.055) / 1.055) ** 2.4)
    want = [decoded[0, 0], decoded[1, 2], np.mean(decoded[0, 1:3]), np.mean(decoded[:, :2])]
    np.testing.assert_allclose(thickness_mod.thickness_per_vertex(obj, mesh, settings), want, atol=2e-3)
    srgb.colorspace_settings.name = "Non-Color"  # data: as stored
    srgb.pixels.foreach_set(pixels.ravel())
    np.testing.assert_allclose(thickness_mod.thickness_per_vertex(obj, mesh, settings), values, atol=2e-3)
    settings.thickness_image = image
    settings.thickness_source = "ATTRIBUTE"
    assert thickness_mod.image_map(obj, mesh, settings) is None
    settings.thickness_source = "IMAGE"
    settings.thickness_uv_map = "Missing"
    with pytest.raises(ValueError, match="no UV map 'Missing'"):
        thickness_mod.thickness_per_vertex(obj, mesh, settings)


# ----------------------------------------------------------------------------------------------
# Registration
# ----------------------------------------------------------------------------------------------
def test_register_unregister_cycles_leave_no_property_or_class_behind(bpy, package):
    addon = importlib.import_module(f"{EXTENSION_ID}.addon")
    package.unregister()
    types_before = set(dir(bpy.types))
    assert not hasattr(bpy.types.Material, "thinfilm_sh")
    names = {cls.__name__ for cls in addon.classes}
    assert {"THINFILM_OT_bake", "THINFILM_PT_material", "ThinFilmMaterialSettings"} <= names
    for _ in range(REGISTER_CYCLES):
        package.register()
        package.register()
        assert hasattr(bpy.types.Material, "thinfilm_sh")
        assert all(cls.is_registered for cls in addon.classes)
        mat = bpy.data.materials.new("Cycle")
        mat.thinfilm_sh.enabled = True
        assert len(mat.thinfilm_sh.layers) == 1
        bpy.data.materials.remove(mat)
        package.unregister()
        package.unregister()
        assert not hasattr(bpy.types.Material, "thinfilm_sh")
        assert not any(cls.is_registered for cls in addon.classes)
        assert set(dir(bpy.types)) == types_before
    assert isinstance(addon.modules, tuple)
    panels = [cls for cls in addon.classes if issubclass(cls, bpy.types.Panel)]
    assert all(p.bl_context == "material" and p.bl_space_type == "PROPERTIES" for p in panels)
