"""Light objects in the add-on's draw path: read every frame, never a bake or World work.

Through ``scene_draw.collect`` as the viewport's draw callback calls it (``allow_bake`` and
``allow_world`` False): moving, re-colouring or re-powering a light changes the frame's lights
buffer and the drawn pixels, with no bake asked for, no World panorama or SH, and the same
``WorldLighting``. Also: glossy ray visibility off, Specular 0 and light linking.
"""

from __future__ import annotations

import types

import numpy as np
import pytest

pytestmark = pytest.mark.blender


@pytest.fixture
def lit(bpy, tf):
    """A film sphere, a grey World and a point light; the first frame collected (and baked)."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    tf.package.register()
    tf.prefs.preferences().cache_dir = tf.cache_dir
    tf.scene_draw.CACHES.clear()
    scene = bpy.context.scene
    world = bpy.data.worlds.new("grey")
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.05, 0.05, 0.05, 1.0)
    scene.world = world
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=1.0)
    sphere = bpy.context.active_object
    mat = bpy.data.materials.new("film")
    s = mat.thinfilm_sh
    s.preset = "SOAP_FILM"
    s.enabled = True
    s.roughness = 0.3
    s.sh_order = "2"
    s.view_samples = 4
    s.wavelength_count = 32
    sphere.data.materials.append(mat)
    light = bpy.data.lights.new("lamp", "POINT")
    light.energy = 500.0
    lamp = bpy.data.objects.new("lamp", light)
    scene.collection.objects.link(lamp)
    lamp.location = (2.0, -2.0, 1.0)
    bpy.context.view_layer.update()
    items, _ = tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())
    assert len(items) == 1 and items[0].lights is not None
    return types.SimpleNamespace(scene=scene, sphere=sphere, lamp=lamp, first=items[0])


def draw_frame(bpy, tf, want, monkeypatch):
    """``collect`` as the draw callback calls it; the bakes it asks the bakes room for land in
    ``want``."""
    monkeypatch.setattr(tf.bake_jobs, "want", lambda desc, **_: want.append(desc))
    bpy.context.view_layer.update()
    return tf.scene_draw.collect(
        bpy.context.evaluated_depsgraph_get(), allow_bake=False, allow_world=False, bake_later=True
    )


VIEW = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, -4.0], [0, 0, 0, 1]], dtype=float)  # camera at −y
PROJ = np.array([[3.5, 0, 0, 0], [0, 3.5, 0, 0], [0, 0, -1.002, -0.2002], [0, 0, -1, 0]], dtype=float)


def test_moving_or_editing_a_light_redraws_with_no_bake_and_no_world_work(bpy, tf, lit, monkeypatch):
    """Move, re-colour, re-power: new lights and new pixels; no bake, no panorama, same World."""
    world_before = tf.world_state.STATE.lighting
    bakes = tf.tables.bake_count

    def forbidden(*_a, **_k):
        raise AssertionError("a light edit started bake or World work")

    monkeypatch.setattr(tf.panorama, "render_world_panorama", forbidden)
    monkeypatch.setattr(tf.world, "world_sh", forbidden)
    monkeypatch.setattr(tf.world_state.world_analysis, "analyse_world", forbidden)
    monkeypatch.setattr(tf.tables, "get_table", forbidden)
    want: list = []
    frames, contents = [], []
    for edit in ("none", "move", "colour", "power"):
        if edit == "move":
            lit.lamp.location = (-1.5, -2.5, 0.5)
        elif edit == "colour":
            lit.lamp.data.color = (1.0, 0.3, 0.2)
        elif edit == "power":
            lit.lamp.data.energy = 2000.0
        items, messages = draw_frame(bpy, tf, want, monkeypatch)
        assert len(items) == 1, messages
        contents.append(np.array(items[0].lights))
        frames.append(tf.gpu.draw.render_offscreen(items, VIEW, PROJ, 32, 32))
    assert want == [] and tf.tables.bake_count == bakes
    assert tf.world_state.STATE.lighting is world_before
    np.testing.assert_array_equal(contents[0], np.array(lit.first.lights))
    for a, b in zip(frames, frames[1:], strict=False):
        assert np.max(np.abs(a[..., :3] - b[..., :3])) > 1e-3  # every edit shows in the frame
    for a, b in zip(contents, contents[1:], strict=False):
        assert not np.array_equal(a, b)


def test_lights_that_cannot_reach_the_film_are_left_out(bpy, tf, lit, monkeypatch):
    """Glossy ray visibility off or Specular 0: no lights (and no light loop); the panel says
    that light objects cast no shadows yet."""
    assert "no cast shadows" in tf.lights.lights_summary(lit.scene)
    want: list = []
    lit.lamp.visible_glossy = False
    items, _ = draw_frame(bpy, tf, want, monkeypatch)
    assert items[0].lights is None
    lit.lamp.visible_glossy = True
    lit.lamp.data.specular_factor = 0.0
    items, _ = draw_frame(bpy, tf, want, monkeypatch)
    assert items[0].lights is None
    lit.lamp.data.specular_factor = 0.5
    items, _ = draw_frame(bpy, tf, want, monkeypatch)
    full = np.array(lit.first.lights)
    # energy (row 2 of light 0, after the count vec4) halves
    np.testing.assert_allclose(np.array(items[0].lights)[3, :3], 0.5 * full[3, :3], rtol=1e-6)


def test_light_linking_limits_a_light_to_its_receivers(bpy, tf, lit, monkeypatch):
    """A light whose receiver collection holds another object lights only that object."""
    bpy.ops.mesh.primitive_cube_add(location=(3.0, 0.0, 0.0))
    cube = bpy.context.active_object
    cube.data.materials.append(lit.sphere.data.materials[0])
    receivers = bpy.data.collections.new("receivers")
    receivers.objects.link(cube)
    lit.lamp.light_linking.receiver_collection = receivers
    items, _ = draw_frame(bpy, tf, [], monkeypatch)
    by_name = {item.name.split("/")[0]: item for item in items}
    assert by_name[cube.name].lights is not None
    assert by_name[lit.sphere.name].lights is None
