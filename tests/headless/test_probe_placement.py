"""Where the scene probe stands and what a frame does when it cannot be rendered
(addon/headless/probe.py, addon/headless/render.py).

- An instanced solid glass (a collection instance, its collection excluded from the view layer)
  puts the probe's point where the instance is drawn: its draw item's matrix places its mesh's
  bounds, not the prototype's object, which stands elsewhere.
- A probe whose renders fail (a RuntimeError from Blender's render, injected at the one call
  the probe makes) costs the frame nothing but the probe: the frame is drawn, a ``note`` says so,
  the picture is the frame rendered without the probe, and the probe's camera is gone.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from _extension import empty_file, registered_extension

pytestmark = pytest.mark.blender

SIZE = (48, 36)


@pytest.fixture(scope="module")
def tf(bpy, tmp_path_factory):
    with registered_extension(
        bpy,
        tmp_path_factory.mktemp("extension"),
        ("addon.drawing.scene_draw", "addon.headless.probe", "addon.headless.render", "addon.ui.prefs"),
    ) as ns:
        yield ns


def solid_glass(bpy):
    """A filmed Principled glass the extension draws as solid glass (Transmission 1, IOR 1.5)."""
    mat = bpy.data.materials.new("Glass")
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    bsdf.inputs["IOR"].default_value = 1.5
    bsdf.inputs["Roughness"].default_value = 0.05
    bsdf.inputs["Transmission Weight"].default_value = 1.0
    bsdf.inputs["Thin Film Thickness"].default_value = 300.0
    bsdf.inputs["Thin Film IOR"].default_value = 1.33
    return mat


def fresh_scene(bpy, tf):
    scene = empty_file(bpy, tf, SIZE)
    scene.eevee.taa_render_samples = 1
    scene.world = bpy.data.worlds.new("World")
    scene.world.color = (0.2, 0.25, 0.3)
    return scene


def test_an_instanced_glass_puts_the_probe_where_the_instance_is(bpy, tf):
    scene = fresh_scene(bpy, tf)
    prototype = bpy.data.collections.new("Prototype")
    scene.collection.children.link(prototype)
    mesh = bpy.data.meshes.new("Ball")
    ball = bpy.data.objects.new("Ball", mesh)
    prototype.objects.link(ball)
    import bmesh

    shape = bmesh.new()
    bmesh.ops.create_uvsphere(shape, u_segments=16, v_segments=8, radius=0.5)
    shape.to_mesh(mesh)
    shape.free()
    mesh.materials.append(solid_glass(bpy))
    ball.location = (0.5, 0.0, 0.0)  # off the collection's origin
    bpy.context.view_layer.layer_collection.children["Prototype"].exclude = True
    instance = bpy.data.objects.new("Instance", None)
    instance.instance_type = "COLLECTION"
    instance.instance_collection = prototype
    instance.location = (3.0, 2.0, 1.0)
    instance.rotation_euler = (0.0, 0.0, math.pi / 2.0)
    instance.scale = (2.0, 2.0, 2.0)
    scene.collection.objects.link(instance)
    bpy.context.view_layer.update()

    items, _ = tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())
    assert [item.name for item in items] == ["Ball/Glass"]  # the instance alone is drawn
    centre = tf.probe.glass_centre(items)
    # the ball's centre (0.5, 0, 0) turned 90° about z, doubled and moved to (3, 2, 1)
    np.testing.assert_allclose(centre, (3.0, 3.0, 1.0), atol=1e-5)
    assert np.linalg.norm(centre - np.array(ball.matrix_world.translation)) > 3.0  # not the prototype's


def test_a_probe_that_cannot_be_rendered_leaves_the_frame_without_it(bpy, tf, tmp_path, monkeypatch):
    scene = fresh_scene(bpy, tf)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=(0.0, 0.0, 0.0), segments=24, ring_count=12)
    bpy.context.object.data.materials.append(solid_glass(bpy))
    bpy.ops.mesh.primitive_plane_add(size=20.0, location=(0.0, 0.0, -0.6))
    bpy.ops.object.camera_add(location=(0.0, -4.0, 0.8), rotation=(math.radians(80.0), 0.0, 0.0))
    camera = bpy.context.object
    scene.camera = camera

    def render(name, **kwargs):
        import OpenEXR

        path = str(tmp_path / f"{name}.png")
        result = tf.render.render_scene(scene, path, *SIZE, supersample=1, engine="EEVEE", **kwargs)
        with OpenEXR.File(str(result["exr"])) as f:
            return result, np.array(f.channels()["RGBA"].pixels, dtype=np.float64)

    without, without_px = render("without", scene_probe=False)
    objects = len(bpy.data.objects)

    def fails(*args, **kwargs):
        raise RuntimeError("Error: render failed (injected)")

    monkeypatch.setattr(tf.probe, "render_views", fails)
    failed, failed_px = render("failed")
    notes = [m for m in failed["messages"] if m.startswith("scene probe not rendered")]
    assert notes and "injected" in notes[0] and "see the World" in notes[0], failed["messages"]
    assert not any(m.startswith("scene probe:") for m in without["messages"])
    assert scene.camera == camera and len(bpy.data.objects) == objects  # its camera removed
    assert all(o is not None for o in bpy.context.view_layer.objects)
    np.testing.assert_array_equal(failed_px, without_px)
