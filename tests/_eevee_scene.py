"""EEVEE test scenes for the native film's tests (tests/eevee/, whose conftest.py registers the
extension): tiny orthographic frames under a uniform World, renders read back from EXR."""

import numpy as np
from _cycles_scenes import film_material

SIZE = 32


def eevee_scene(bpy, size=SIZE):
    """A factory-settings scene rendered by EEVEE (one TAA sample) at ``size``², Standard view,
    32-bit EXR output, under a white World."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "BLENDER_EEVEE"
    scene.eevee.taa_render_samples = 1
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    world = bpy.data.worlds.new("white")
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    scene.world = world
    return scene


def eevee_camera(bpy, scene, location=(0.0, 0.0, 3.0), rotation=(0.0, 0.0, 0.0), scale=1.0):
    """An orthographic camera of width ``scale``, made the scene's."""
    data = bpy.data.cameras.new("cam")
    data.type = "ORTHO"
    data.ortho_scale = scale
    cam = bpy.data.objects.new("cam", data)
    cam.location, cam.rotation_euler = location, rotation
    scene.collection.objects.link(cam)
    scene.camera = cam


def eevee_film(bpy, name="film", thickness=300.0, film_ior=2.0, ior=1.5, roughness=0.2):
    """A Principled film material (:func:`_cycles_scenes.film_material`)."""
    return film_material(bpy, name, thickness, film_ior, ior, roughness)


def eevee_plate(bpy, scene, mat):
    """A 4 m plate at the origin wearing ``mat``, seen head-on by :func:`eevee_camera`."""
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    plate = bpy.context.active_object
    plate.data.materials.append(mat)
    eevee_camera(bpy, scene)
    return plate


def eevee_render(bpy, scene, path) -> np.ndarray:
    """Render the scene to ``path`` (EXR) and return its RGB, top row first."""
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(str(path))
    try:
        w, h = image.size
        return np.array(image.pixels[:], dtype=np.float64).reshape(h, w, 4)[::-1, :, :3]
    finally:
        bpy.data.images.remove(image)
