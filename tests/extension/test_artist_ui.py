"""What an artist touches (issue 20), through the real bpy module.

- Every RNA property and operator of the extension has a tooltip written for artists (no code
  paths, US English), names that read well out of context, and every operator has a poll().
- The Bake button's outputs are neither saved in the file nor animatable.
- A linked material (from a library .blend) is not modified by any operator.
- The overlay switch (the preference, a viewport's own toggle) stops the viewport draw and the
  headless render; a Principled film's preview can be switched off per material.
- Viewport bakes show their progress and can be cancelled; a cancelled modal bake's worker stops.
"""

from __future__ import annotations

import importlib
import math
import re

import numpy as np
import pytest

pytestmark = pytest.mark.blender

from _extension import EXTENSION_ID, registered_extension  # noqa: E402
from _waits import EVENT_TIMEOUT_S, CueRecorder, HeldCall, RedrawLog, viewport_lanes_idle, wait_for  # noqa: E402

#: Longest wait for a worker thread to stop (a safety net, not a timing: the tests assert that it
#: stopped, and precompute's tests that it stops at its next checkpoint).
#: Words of British spelling that must not reach the UI (Blender's UI is US English).
BRITISH = re.compile(r"colou?r(?<=colour)|nanometre|anodis|analys|behaviour|grey", re.IGNORECASE)
#: What a tooltip must not show: code paths, module names, Python spellings.
CODE = re.compile(r"precompute|addon/|\.py\b|/data/|PRESETS|bpy\.|\w\(\)")
#: Names that say nothing out of their panel (F-curve, driver and keymap lists show them alone).
BARE_NAMES = {
    "Min",
    "Max",
    "Source",
    "Scale",
    "Seed",
    "Image",
    "Attribute",
    "UV Map",
    "IOR",
    "Colour",
    "Model",
}


@pytest.fixture(scope="module")
def tf(bpy, tmp_path_factory):
    """The extension registered once for the module, with a private table cache."""
    root = tmp_path_factory.mktemp("extension")
    modules = (
        "addon",
        "addon.materials.props",
        "addon.ui.prefs",
        "addon.ui.ops",
        "addon.ui.ui",
        "addon.bakes.tables",
        "addon.drawing.viewport",
        "addon.headless.headless",
        "addon.headless.render",
        "addon.drawing.scene_draw",
        "addon.bakes.bake_jobs",
        "addon.world.world_state",
    )
    with registered_extension(bpy, root, modules, cache_preference=False, gpu=True) as ns:
        ns.root = root
        yield ns


@pytest.fixture
def scene(bpy, tf):
    """The factory start-up file (a window with a 3D viewport), the extension registered."""
    bpy.ops.wm.read_homefile(use_factory_startup=True)
    tf.package.register()
    prefs = tf.prefs.preferences()
    prefs.cache_dir = tf.cache_dir
    prefs.show_overlay = True
    tf.tables.clear_caches()
    tf.scene_draw.CACHES.clear()
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    return bpy.context.scene


def film(bpy, name: str = "Film"):
    """A material previewed by the extension at a tiny bake quality."""
    mat = bpy.data.materials.new(name)
    s = mat.thinfilm_sh
    s.preset = "SOAP_FILM"
    s.enabled = True
    s.vary_thickness = False
    s.roughness = 0.5
    s.sh_order = "2"
    s.view_samples = 4
    s.thickness_samples = 4
    s.wavelength_count = 32
    return mat


def sheet(bpy, scene, material, name: str = "Sheet"):
    """A 2 × 2 quad facing −y at the origin."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([(-1, 0, -1), (1, 0, -1), (1, 0, 1), (-1, 0, 1)], [], [(0, 1, 2, 3)])
    mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(obj)
    return obj


# ----------------------------------------------------------------------------------------------
# Tooltips, names, poll
# ----------------------------------------------------------------------------------------------
def _structs(bpy, tf):
    """(label, bl_rna) of every struct the extension registers, and the Material pointer."""
    out = []
    for cls in tf.addon.classes:
        rna = getattr(cls, "bl_rna", None)
        if rna is not None and issubclass(
            cls, (bpy.types.PropertyGroup, bpy.types.Operator, bpy.types.AddonPreferences)
        ):
            out.append((cls.__name__, rna))
    return out


def _own_properties(bpy, rna):
    builtin = {"rna_type"}
    if isinstance(rna, bpy.types.Struct) and rna.base is not None:
        builtin |= {p.identifier for p in rna.base.properties}  # PropertyGroup's name, ...
    return [p for p in rna.properties if p.identifier not in builtin]


def test_every_property_enum_item_and_operator_has_an_artist_tooltip(bpy, tf):
    """Fails on any missing description, a code path or a British spelling in the UI."""
    problems = []
    structs = _structs(bpy, tf)
    assert len(structs) >= 10  # two property groups, the preferences and the operators
    assert any(label.startswith("THINFILM_OT") for label, _ in structs)
    pointer = bpy.types.Material.bl_rna.properties["thinfilm_sh"]
    checked = [("Material.thinfilm_sh", pointer)]
    for label, rna in structs:
        if label.startswith("THINFILM_OT"):  # the operator's tooltip (docstring) and parameters
            module, name = getattr(tf.addon.ui.ops, label).bl_idname.split(".")
            op_rna = getattr(getattr(bpy.ops, module), name).get_rna_type()
            checked.append((label, op_rna))
            checked += [
                (f"{label}.{p.identifier}", p) for p in op_rna.properties if p.identifier != "rna_type"
            ]
        else:
            checked += [(f"{label}.{p.identifier}", p) for p in _own_properties(bpy, rna)]
    for where, item in checked:
        text = item.description.strip()
        name = getattr(item, "name", "")
        if not text:
            problems.append(f"{where}: no description")
        if CODE.search(text):
            problems.append(f"{where}: code in the tooltip: {text!r}")
        if BRITISH.search(text) or BRITISH.search(name):
            problems.append(f"{where}: British spelling: {name!r} / {text!r}")
        if getattr(item, "type", "") == "ENUM":
            for enum in item.enum_items:
                if not enum.description.strip() or CODE.search(enum.description):
                    problems.append(f"{where}[{enum.identifier}]: enum tooltip {enum.description!r}")
                if BRITISH.search(enum.name) or BRITISH.search(enum.description):
                    problems.append(f"{where}[{enum.identifier}]: British spelling {enum.name!r}")
    assert not problems, "\n".join(problems)


def test_property_names_read_well_out_of_context(bpy, tf):
    """F-curve and driver lists show a property's name alone: no bare "Min" or "Source"."""
    bad = [
        f"{label}.{p.identifier} is named {p.name!r}"
        for label, rna in _structs(bpy, tf)
        if not label.startswith("THINFILM_OT")
        for p in _own_properties(bpy, rna)
        if p.name in BARE_NAMES or not p.name
    ]
    assert not bad, "\n".join(bad)


def test_every_operator_has_a_poll(bpy, tf):
    """Each operator class defines poll() itself or in an add-on base, not Blender's default."""
    operators = [cls for cls in tf.addon.classes if issubclass(cls, bpy.types.Operator)]
    assert len(operators) == len(tf.ops.classes) >= 9
    missing = [
        cls.__name__
        for cls in operators
        if not any("poll" in vars(base) for base in cls.__mro__ if base.__module__.startswith(EXTENSION_ID))
    ]
    assert not missing, f"operators without poll(): {missing}"


def test_remove_greys_out_on_an_empty_layer_list_with_the_reason(bpy, tf, scene):
    """poll() is False for Remove and Move on an empty list, and calling it says why."""
    mat = film(bpy)
    mat.thinfilm_sh.layers.clear()
    with bpy.context.temp_override(material=mat):
        assert not bpy.ops.thinfilm.layer_remove.poll()
        assert not bpy.ops.thinfilm.layer_move.poll()
        assert bpy.ops.thinfilm.layer_add.poll()
        with pytest.raises(RuntimeError, match="no film layer to remove"):
            bpy.ops.thinfilm.layer_remove()


# ----------------------------------------------------------------------------------------------
# Outputs are runtime only
# ----------------------------------------------------------------------------------------------
def test_bake_outputs_are_neither_saved_nor_animatable(bpy, tf, scene, tmp_path):
    """last_bake_ms, last_plan, last_error: not animatable, hidden, and gone after save + load."""
    rna = tf.props.ThinFilmMaterialSettings.bl_rna
    for name in ("last_bake_ms", "last_plan", "last_error"):
        prop = rna.properties[name]
        assert not prop.is_animatable and prop.is_hidden, name
    mat = film(bpy)
    mat.use_fake_user = True  # saved although no object uses it
    assert bpy.ops.thinfilm.bake(material=mat.name) == {"FINISHED"}
    assert mat.thinfilm_sh.last_plan and mat.thinfilm_sh.last_bake_ms > 0.0
    assert not any(key.startswith("last_") for key in mat.thinfilm_sh.keys())  # no ID property
    with pytest.raises(TypeError):
        mat.thinfilm_sh.keyframe_insert("last_bake_ms")
    path = str(tmp_path / "saved.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    loaded = bpy.data.materials["Film"].thinfilm_sh
    assert loaded.last_plan == "" and loaded.last_bake_ms == 0.0 and loaded.last_error == ""


# ----------------------------------------------------------------------------------------------
# Linked materials are read-only
# ----------------------------------------------------------------------------------------------
def _snapshot(mat) -> dict:
    """Every RNA value of a material that an operator could change: its settings, layers, nodes
    (not the hidden runtime outputs of the Bake button, which are not material data)."""
    out = {}

    def walk(prefix, struct):
        for prop in struct.bl_rna.properties:
            if prop.identifier == "rna_type" or prop.type in {"POINTER", "COLLECTION"} or prop.is_hidden:
                continue
            value = getattr(struct, prop.identifier)
            out[f"{prefix}.{prop.identifier}"] = (
                tuple(value) if hasattr(value, "__len__") and not isinstance(value, str) else value
            )

    walk("settings", mat.thinfilm_sh)
    for i, layer in enumerate(mat.thinfilm_sh.layers):
        walk(f"layer{i}", layer)
    out["layers"] = len(mat.thinfilm_sh.layers)
    for node in mat.node_tree.nodes:
        for sock in node.inputs:
            if hasattr(sock, "default_value"):
                v = sock.default_value
                out[f"{node.name}.{sock.identifier}"] = tuple(v) if hasattr(v, "__len__") else v
    out["nodes"] = sorted(n.name for n in mat.node_tree.nodes)
    out["links"] = len(mat.node_tree.links)
    return out


def test_a_linked_material_is_not_modified_by_any_operator(bpy, tf, scene, tmp_path):
    """Every operator, called with the linked material named or in the context: the material is
    unchanged, the editing operators refuse with a message naming the library, and their poll
    greys them out."""
    mat = film(bpy, "Library Film")
    mat.thinfilm_sh.layers.add()  # two layers: Move and Remove have something to do
    library = tmp_path / "library.blend"
    bpy.data.libraries.write(str(library), {mat})
    bpy.ops.wm.read_homefile(use_factory_startup=True)
    tf.package.register()
    tf.prefs.preferences().cache_dir = tf.cache_dir
    with bpy.data.libraries.load(str(library), link=True) as (_src, dst):
        dst.materials = ["Library Film"]
    linked = bpy.data.materials["Library Film"]
    assert linked.library is not None and not linked.is_editable
    before = _snapshot(linked)
    editing = [
        ("apply_preset", {"preset": "HEAT_TINTED_STEEL"}),
        ("layer_add", {}),
        ("layer_remove", {}),
        ("layer_move", {"direction": "DOWN"}),
        ("write_to_principled", {}),
    ]
    for name, kwargs in editing:
        op = getattr(bpy.ops.thinfilm, name)
        with pytest.raises(RuntimeError, match="linked from"):
            op(material=linked.name, **kwargs)
        with bpy.context.temp_override(material=linked):
            assert not op.poll(), name
    assert bpy.ops.thinfilm.bake(material=linked.name) == {"FINISHED"}  # baking changes no data
    assert linked.thinfilm_sh.last_plan  # its outputs live in memory
    assert bpy.ops.thinfilm.clear_cache() == {"FINISHED"}
    with bpy.context.temp_override(material=linked):
        assert not bpy.ops.thinfilm.preset_add.poll()  # saving a preset reads the context's material
    covered = {name for name, _ in editing} | {
        "bake",
        "clear_cache",
        "toggle_overlay",
        "cancel_bakes",
        "preset_add",
    }
    assert covered == {cls.bl_idname.split(".")[1] for cls in tf.ops.classes}
    assert _snapshot(linked) == before


# ----------------------------------------------------------------------------------------------
# The overlay switch
# ----------------------------------------------------------------------------------------------
def _viewport(bpy):
    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    region = next(r for r in area.regions if r.type == "WINDOW")
    return window, area, region


def _drawn(bpy, tf, monkeypatch) -> list:
    """Run the viewport's draw callback in the start-up file's 3D viewport; the items it drew."""
    drawn = []
    monkeypatch.setattr(tf.viewport, "draw_items", lambda items, *a, **k: drawn.extend(items))
    window, area, region = _viewport(bpy)
    with bpy.context.temp_override(window=window, area=area, region=region):
        tf.viewport.draw_callback()
    return drawn


def test_the_overlay_switches_stop_the_viewport_draw(bpy, tf, scene, monkeypatch):
    """On: the film is drawn. The preference off, or this viewport's toggle off: nothing."""
    mat = film(bpy)
    sheet(bpy, scene, mat)
    assert bpy.ops.thinfilm.bake(material=mat.name) == {"FINISHED"}
    tf.world_state.world_lighting(scene, allow_compute=True)
    bpy.context.view_layer.update()
    assert len(_drawn(bpy, tf, monkeypatch)) == 1

    tf.prefs.preferences().show_overlay = False
    assert _drawn(bpy, tf, monkeypatch) == []
    tf.prefs.preferences().show_overlay = True

    window, area, region = _viewport(bpy)
    with bpy.context.temp_override(window=window, area=area, region=region):
        assert bpy.ops.thinfilm.toggle_overlay() == {"FINISHED"}  # the Overlays popover's toggle
    assert not tf.viewport.shown_in(area.spaces.active)
    assert _drawn(bpy, tf, monkeypatch) == []
    with bpy.context.temp_override(window=window, area=area, region=region):
        bpy.ops.thinfilm.toggle_overlay()
    assert len(_drawn(bpy, tf, monkeypatch)) == 1


def test_the_overlay_preference_stops_the_headless_render(bpy, tf, scene, tmp_path):
    """The same scene renders the film with the preference on and no film with it off."""
    mat = film(bpy)
    sheet(bpy, scene, mat)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = (0.0, -4.0, 0.0)
    cam.rotation_euler = (math.pi / 2.0, 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    on = tf.render.render_scene(scene, str(tmp_path / "on.png"), 32, 32, background=False)
    assert on["objects"] == ["Sheet/0"] or len(on["objects"]) == 1
    tf.prefs.preferences().show_overlay = False
    off = tf.render.render_scene(scene, str(tmp_path / "off.png"), 32, 32, background=False)
    assert off["objects"] == [] and tf.render.OVERLAY_OFF in off["messages"]


def test_a_principled_film_preview_can_be_switched_off_per_material(bpy, tf, scene):
    """The per-material switch: on, the Principled film is previewed; off, nothing is drawn."""
    mat = bpy.data.materials.new("Principled Film")
    bsdf = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    bsdf.inputs["Thin Film Thickness"].default_value = 400.0
    description = importlib.import_module(f"{EXTENSION_ID}.addon.materials.description").description
    assert description(mat) is not None
    mat.thinfilm_sh.preview_principled = False
    assert description(mat) is None
    sheet(bpy, scene, mat)
    tf.world_state.world_lighting(scene, allow_compute=True)
    bpy.context.view_layer.update()
    items, _ = tf.scene_draw.collect(
        bpy.context.evaluated_depsgraph_get(), allow_bake=False, allow_world=False
    )
    assert items == []


# ----------------------------------------------------------------------------------------------
# Background work
# ----------------------------------------------------------------------------------------------
def test_viewport_bakes_show_progress_and_stop_when_cancelled(bpy, tf, scene, monkeypatch):
    """A queued viewport bake shows in the header's activity; Cancel stops its worker, which
    caches nothing and is not remembered as a failure."""
    vp = tf.viewport
    bj = tf.bake_jobs
    bj.cancel_all()  # an earlier test's draw may have left its bake running: start from none
    wait_for(lambda: not bj.BAKES.running, "an earlier test's cancelled viewport bakes to end")
    vp._service()
    assert not bj.BAKES.running, f"a bake started with nothing queued: {list(bj.BAKES.running)}"
    mat = film(bpy)
    mat.thinfilm_sh.sh_order = "AUTO"
    mat.thinfilm_sh.view_samples = 0
    mat.thinfilm_sh.roughness = 0.123  # a kernel no other test has cached
    desc = tf.ui.description(mat)
    held = HeldCall(importlib.import_module(f"{EXTENSION_ID}.precompute.bakes.bake"), "bake", monkeypatch)
    bj.want(desc)
    vp._service()  # starts the worker thread
    assert held.entered.wait(EVENT_TIMEOUT_S), "the viewport's bake never started (in this process)"
    assert bj.BAKES.running
    assert "baking 1 film" in vp.activity()
    assert bj.cancel_all() == 1
    held.open()  # the real bake stops at its first checkpoint
    wait_for(lambda: not bj.BAKES.running, "the cancelled bake's worker to stop")
    # The header's bake part; a World analysis the same ticks started may still show beside it.
    assert "baking" not in vp.activity(), f"the header still shows {vp.activity()!r} after the bake stopped"
    assert tf.tables.peek_table(desc) is None
    assert tf.bake_jobs.description_key(desc) not in tf.tables.FAILURES


def test_a_finished_viewport_bake_asks_for_a_redraw(bpy, tf, scene, monkeypatch):
    """Issue 16: when a worker's bake ends, the timer's next tick tags the 3D views for a redraw
    (the table is there now), and keeps ticking until it has done so."""
    vp = tf.viewport
    bj = tf.bake_jobs
    bake_cue = CueRecorder(lambda: bj.BAKES.running)
    monkeypatch.setattr(bj.BAKES, "_finished", bake_cue)
    redraws = RedrawLog(bake_cue)
    monkeypatch.setattr(vp, "_tag_redraw", redraws)
    mat = film(bpy)
    mat.thinfilm_sh.roughness = 0.234  # a table no other test has baked
    desc = tf.ui.description(mat)
    bj.want(desc)
    vp._service()  # starts the worker (and, if this scene's World or display changed, theirs)
    # The same tick may start a World analysis or a display LUT (their own lanes, 0.1 s polls);
    # the last tick is the one after every lane has ended (the CI stress run caught a World job
    # still running when only the bake was waited for). That first tick may also have taken the
    # bake's cue already (the CI stress run caught that too): the log says which redraw followed it.
    wait_for(lambda: viewport_lanes_idle(vp), "the viewport bake's worker (and any World or display job)")
    assert vp._service() is None, "the timer kept ticking with no work left"
    assert redraws.after_cue(), (
        "the finished bake did not ask for the redraw that shows its table "
        f"(cues set at each redraw: {redraws})"
    )
    assert tf.tables.peek_table(desc) is not None


def test_a_cancelled_modal_bake_stops_its_worker_and_caches_nothing(bpy, tf, scene, monkeypatch):
    """The Bake button's job (what Esc cancels): stops, no result, no error, nothing cached."""
    mat = film(bpy)
    mat.thinfilm_sh.sh_order = "AUTO"
    mat.thinfilm_sh.view_samples = 0
    mat.thinfilm_sh.roughness = 0.321
    desc = tf.ui.description(mat)
    held = HeldCall(importlib.import_module(f"{EXTENSION_ID}.precompute.bakes.bake"), "bake", monkeypatch)
    job = tf.ops.BakeJob(desc, tf.tables.open_cache()).start()
    assert held.entered.wait(EVENT_TIMEOUT_S), "the Bake button's bake never started"
    job.cancel()  # mid-run: the real bake stops at its first checkpoint
    held.open()
    job.join(EVENT_TIMEOUT_S)
    assert job.done.is_set(), f"the cancelled bake's worker did not end in {EVENT_TIMEOUT_S:.0f} s"
    assert job.cancelled
    assert job.result is None and job.error is None
    assert tf.tables.peek_table(desc) is None
    assert np.isfinite(job.elapsed_s)


# ----------------------------------------------------------------------------------------------
# User presets and the panel's place
# ----------------------------------------------------------------------------------------------
def _film_values(settings) -> dict:
    """The values a user preset stores (ops.PRESET_VALUES), layers included."""
    out = {}
    for path in ("vary_thickness", "thickness_min_nm", "thickness_max_nm", "substrate_mode", "substrate_ior"):
        out[path] = getattr(settings, path)
    out["roughness"] = round(settings.roughness, 6)
    out["diffuse_color"] = tuple(round(v, 6) for v in settings.diffuse_color)
    out["layers"] = [
        (layer.index_mode, round(layer.n, 6), round(layer.thickness_nm, 3)) for layer in settings.layers
    ]
    return out


def test_a_user_preset_saves_applies_and_removes_through_blenders_preset_system(
    bpy, tf, scene, tmp_path, monkeypatch
):
    """Add Preset writes a file under the user's scripts/presets/thinfilm_sh/material; Blender's
    execute_preset applies it to another material (layers included); Remove deletes it."""
    monkeypatch.setenv("BLENDER_USER_SCRIPTS", str(tmp_path / "scripts"))
    mat = film(bpy, "Mine")
    s = mat.thinfilm_sh
    s.layers[0].thickness_nm = 321.0
    bpy.ops.thinfilm.layer_add(material=mat.name)
    s.layers[1].n = 1.7
    s.layers[1].thickness_nm = 88.0
    s.roughness = 0.27
    s.diffuse_base = True
    s.diffuse_color = (0.2, 0.3, 0.4)
    assert not bpy.ops.thinfilm.preset_add.poll()  # no material in the context
    with bpy.context.temp_override(material=mat):
        assert bpy.ops.thinfilm.preset_add(name="My Bubble") == {"FINISHED"}
    path = tmp_path / "scripts" / "presets" / "thinfilm_sh" / "material" / "My_Bubble.py"
    assert path.is_file()
    assert str(path.parent) in bpy.utils.preset_paths(tf.ops.PRESET_SUBDIR)  # the menu lists it

    other = bpy.data.materials.new("Other")
    other.thinfilm_sh.preset = "HEAT_TINTED_STEEL"
    other.thinfilm_sh.enabled = True
    assert _film_values(other.thinfilm_sh) != _film_values(s)
    with bpy.context.temp_override(material=other):
        bpy.ops.script.execute_preset(filepath=str(path), menu_idname="THINFILM_MT_presets")
    assert _film_values(other.thinfilm_sh) == _film_values(s)
    assert other.thinfilm_sh.preset == "CUSTOM"  # a user preset is the artist's own settings

    with bpy.context.temp_override(material=mat):
        assert bpy.ops.thinfilm.preset_add(name="My Bubble", remove_name=True) == {"FINISHED"}
    assert not path.exists()


def test_the_panel_sits_among_blenders_material_panels(bpy, tf):
    """After Surface/Volume/Settings (order 0), before Viewport Display, Animation, Custom Props."""
    order = tf.ui.THINFILM_PT_material.bl_order
    assert 0 < order < bpy.types.MATERIAL_PT_viewport.bl_order < bpy.types.MATERIAL_PT_custom_props.bl_order
