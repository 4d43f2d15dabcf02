"""The scene around solid glass, rendered by Blender (addon/headless/probe.py): six 90° views
from a point over a floor, with a red box to one side and the glass hidden, resampled to the
probe's panorama (precompute/shading/glass/probe.py).

The floor lies 1 below the point and the box's near face 2.5 beside it along +X: the probe's
distance and colour there come from the render, the World above; the scene's camera and
objects are as they were after it.
"""

from __future__ import annotations

import importlib

import numpy as np
import pytest
from _extension import EXTENSION_ID, linked_extension

pytestmark = pytest.mark.blender

CENTRE = np.array([0.4, -0.3, 1.0])


@pytest.fixture(scope="module")
def probe_module(bpy, tmp_path_factory):
    with linked_extension(tmp_path_factory.mktemp("ext")):
        yield importlib.import_module(f"{EXTENSION_ID}.addon.headless.probe")


def coloured(bpy, obj, rgb):
    """A diffuse material of colour ``rgb`` on ``obj``."""
    material = bpy.data.materials.new(obj.name)
    material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (*rgb, 1.0)
    material.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 1.0
    obj.data.materials.append(material)


def test_the_probe_sees_the_floor_and_the_box_around_the_hidden_glass(bpy, probe_module):
    from precompute.world import hdri

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    scene.eevee.taa_render_samples = 1
    bpy.ops.mesh.primitive_plane_add(size=40.0, location=(CENTRE[0], CENTRE[1], 0.0))
    coloured(bpy, bpy.context.object, (0.1, 0.5, 0.1))
    bpy.ops.mesh.primitive_cube_add(
        size=1.0, location=(CENTRE[0] + 3.0, CENTRE[1], CENTRE[2]), scale=(1, 4, 4)
    )
    coloured(bpy, bpy.context.object, (0.8, 0.05, 0.05))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.3, location=tuple(CENTRE))  # the glass: hidden
    glass = bpy.context.object
    bpy.ops.object.camera_add(location=(0.0, -6.0, 2.0))
    camera = bpy.context.object
    scene.camera = camera
    scene.world = bpy.data.worlds.new("World")
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.2, 0.3, 0.6, 1.0)
    objects = len(bpy.data.objects)

    got = probe_module.render_probe(scene, CENTRE, engine="EEVEE", hidden={glass.name}, size=32)
    assert scene.camera == camera and len(bpy.data.objects) == objects  # its camera gone
    assert all(o is not None for o in bpy.context.view_layer.objects)  # and from the view layer
    image = got.image
    rows = image.shape[0]
    dirs = hdri.equirect_directions(rows, 2 * rows)
    down = dirs[..., 2] < -0.5
    floor = image[..., 3][down]
    expected = CENTRE[2] / -dirs[..., 2][down]
    off = np.median(np.abs(floor / expected - 1.0))
    print(f"probe: {got.seconds:.1f} s; floor distance error median {off:.1e}")
    assert off < 0.03  # the floor, not the hidden sphere (0.3)
    assert image[..., 1][down].mean() > 2.0 * image[..., 0][down].mean()  # green
    ahead = dirs @ np.array([1.0, 0.0, 0.0]) > 0.98
    assert np.allclose(np.median(image[..., 3][ahead]), 2.5, rtol=0.03)  # the box's near face
    assert np.median(image[..., 0][ahead]) > 3.0 * np.median(image[..., 1][ahead])  # red
    up = dirs[..., 2] > 0.85  # above the box
    assert np.all(image[..., 3][up] == 0.0)  # the World: no distance
    assert np.allclose(np.median(image[..., :3][up], axis=0), (0.2, 0.3, 0.6), atol=0.02)  # its colour
