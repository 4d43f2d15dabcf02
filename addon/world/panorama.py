"""A World rendered alone as an equirectangular panorama, with Cycles on the CPU.

The ground truth of :mod:`.world` (procedural Worlds are projected from it) and the image the
split sum prefilters (:mod:`.scene_draw`).

The panorama camera sits at the origin with rotation Euler (90°, 0, −90°): Blender's panorama
camera looks along its −Z axis with +Y up, so this turns its view to world +X with +Z up and
the rendered equirect then follows the Environment Texture convention (image centre = +X,
u = ¼ = +Y). ``tests/world/test_world.py`` proves it against direct projection.
"""

from __future__ import annotations

import math
import os
import tempfile

import bpy
import numpy as np

from ..colour_space import working_space

__all__ = ["PANORAMA_CAMERA_ROTATION", "PANORAMA_SAMPLES", "PANORAMA_WIDTH", "render_world_panorama"]

#: Panorama fallback: resolution (width; height = width/2) and Cycles samples per pixel.
#: At 256×128 and 32 samples bands 0–2 of the studio HDRIs agree with direct projection to
#: ~0.1–2 % of the l = 0 term (the error is the noise of tiny bright suns); a render takes 1–2 s.
PANORAMA_WIDTH = 256
PANORAMA_SAMPLES = 32

#: Rotation of the panorama camera that makes its equirect match the Environment Texture's.
PANORAMA_CAMERA_ROTATION = (math.pi / 2.0, 0.0, -math.pi / 2.0)


def render_world_panorama(world, width: int = PANORAMA_WIDTH, samples: int = PANORAMA_SAMPLES) -> np.ndarray:
    """Render ``world`` alone as an equirect panorama with Cycles on the CPU.

    A temporary scene sharing the World (no objects) with a panorama camera at the origin is
    rendered to a 32-bit OpenEXR (scene linear) in a temporary folder and read back through
    Blender; the scene, camera and image are removed again, nothing else is touched. Must not
    be called from a draw callback (it runs the render operator).

    Returns
    -------
    ndarray, shape (width/2, width, 3), float32
        Scene-linear radiance, top row first, in the Environment Texture's equirect convention.
    """
    width = int(width)
    height = max(1, width // 2)
    had_render_result = "Render Result" in bpy.data.images
    scene = bpy.data.scenes.new(".thinfilm_sh panorama")
    cam_data = obj = image = None
    try:
        scene.world = world
        scene.render.engine = "CYCLES"
        if scene.render.engine != "CYCLES":
            raise RuntimeError("Cycles is not available")
        cycles = scene.cycles
        cycles.device = "CPU"
        cycles.samples = int(samples)
        cycles.use_adaptive_sampling = False
        cycles.use_denoising = False
        cycles.seed = 0
        scene.render.resolution_x = width
        scene.render.resolution_y = height
        scene.render.resolution_percentage = 100
        scene.render.film_transparent = False
        scene.render.use_compositing = False
        scene.render.use_sequencer = False
        scene.render.use_border = False
        scene.view_settings.view_transform = "Standard"
        scene.view_settings.look = "None"
        scene.view_settings.exposure = 0.0
        scene.view_settings.gamma = 1.0
        settings = scene.render.image_settings
        settings.file_format = "OPEN_EXR"
        settings.color_depth = "32"
        settings.color_mode = "RGB"
        settings.color_management = "FOLLOW_SCENE"

        cam_data = bpy.data.cameras.new(".thinfilm_sh panorama")
        cam_data.type = "PANO"
        cam_data.panorama_type = "EQUIRECTANGULAR"
        cam_data.latitude_min, cam_data.latitude_max = -math.pi / 2.0, math.pi / 2.0
        cam_data.longitude_min, cam_data.longitude_max = -math.pi, math.pi
        obj = bpy.data.objects.new(".thinfilm_sh panorama", cam_data)
        obj.location = (0.0, 0.0, 0.0)
        obj.rotation_euler = PANORAMA_CAMERA_ROTATION
        scene.collection.objects.link(obj)
        scene.camera = obj

        with tempfile.TemporaryDirectory(prefix="thinfilm_sh_") as folder:
            path = os.path.join(folder, "world.exr")
            scene.render.filepath = path
            bpy.ops.render.render(write_still=True, scene=scene.name)
            if not os.path.isfile(path):
                raise RuntimeError("the panorama render wrote no image")
            image = bpy.data.images.load(path, check_existing=False)
            image.colorspace_settings.name = working_space()
            w, h = image.size[:]
            buf = np.empty(w * h * image.channels, dtype=np.float32)
            image.pixels.foreach_get(buf)
            rgb = np.ascontiguousarray(buf.reshape(h, w, image.channels)[::-1, :, :3])
    finally:
        if image is not None:
            bpy.data.images.remove(image)
        bpy.data.scenes.remove(scene)
        if obj is not None:
            bpy.data.objects.remove(obj)
        if cam_data is not None:
            bpy.data.cameras.remove(cam_data)
        if not had_render_result and "Render Result" in bpy.data.images:
            bpy.data.images.remove(bpy.data.images["Render Result"])
    return rgb
