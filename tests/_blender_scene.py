"""Little scenes built by script for the tests that render through the extension in Blender.

Shared by headless/test_headless.py and extension/test_hostile_blender.py (and anything else
that needs a sphere, a camera, a World and the EXR the headless render writes). Real bpy objects,
nothing mocked; bmesh and OpenEXR are imported where used.
"""

from __future__ import annotations

import math

import numpy as np


def sphere(bpy, scene, name="Sphere", location=(0.0, 0.0, 0.0), radius=1.0, material=None, segments=(64, 32)):
    """A smooth UV sphere (``segments``: around, from pole to pole) linked to ``scene``."""
    import bmesh

    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=segments[0], v_segments=segments[1], radius=radius)
    mesh = bpy.data.meshes.new(name)
    bm.to_mesh(mesh)
    bm.free()
    mesh.shade_smooth()
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    scene.collection.objects.link(obj)
    if material is not None:
        mesh.materials.append(material)
    return obj


def cube(bpy, scene, name="Cube", location=(0.0, 0.0, 0.0), size=1.0):
    """A cube of edge ``size`` linked to ``scene``."""
    import bmesh

    bm = bmesh.new()
    bmesh.ops.create_cube(bm, size=size)
    mesh = bpy.data.meshes.new(name)
    bm.to_mesh(mesh)
    bm.free()
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    scene.collection.objects.link(obj)
    return obj


def camera(bpy, scene, distance=5.0, lens=50.0):
    """The scene's camera: on −y at ``distance``, looking at the origin along +y."""
    data = bpy.data.cameras.new("Camera")
    data.lens = lens
    obj = bpy.data.objects.new("Camera", data)
    obj.location = (0.0, -distance, 0.0)
    obj.rotation_euler = (math.pi / 2.0, 0.0, 0.0)
    scene.collection.objects.link(obj)
    scene.camera = obj
    return obj


def white_world(bpy, scene, value=1.0):
    """A uniform World of radiance ``value`` (Strength 1)."""
    world = bpy.data.worlds.new("White")
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (value, value, value, 1.0)
    background.inputs["Strength"].default_value = 1.0
    scene.world = world
    return world


def read_exr(path) -> np.ndarray:
    """The RGB of an EXR (the headless render's is RGBA), float64, top row first."""
    import OpenEXR

    with OpenEXR.File(str(path)) as f:
        channels = f.channels()
        for key in ("RGBA", "RGB"):
            if key in channels:
                return np.array(channels[key].pixels, dtype=np.float64)[..., :3]
        return np.stack([np.array(channels[c].pixels, dtype=np.float64) for c in "RGB"], axis=-1)
