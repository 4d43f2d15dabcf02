"""The GPU context: whether ``gpu`` can draw now, and creating a context in background mode."""

from __future__ import annotations

import bpy
import gpu


def drawing_available() -> bool:
    """Whether gpu drawing works now (it does not in background mode before a context exists).

    Probes with a call that creates nothing: making a throw-away off-screen buffer here would
    unbind the caller's framebuffer.
    """
    try:
        gpu.platform.backend_type_get()
    except SystemError:
        return False
    return True


_context_ready = False


def _context_from_workbench_render() -> None:
    """Create Blender's GPU context by rendering 8×8 pixels of an empty scene with Workbench.

    Everything created for it (scene, camera object and data) is removed again.
    """
    scene = bpy.data.scenes.new("tf_gpu_context")
    cam_data = bpy.data.cameras.new("tf_gpu_context")
    cam = bpy.data.objects.new("tf_gpu_context", cam_data)
    try:
        scene.collection.objects.link(cam)
        scene.camera = cam
        scene.render.engine = "BLENDER_WORKBENCH"
        scene.render.resolution_x = scene.render.resolution_y = 8
        scene.render.resolution_percentage = 100
        with bpy.context.temp_override(scene=scene):
            bpy.ops.render.render(write_still=False, scene=scene.name)
    finally:
        bpy.data.objects.remove(cam)
        bpy.data.cameras.remove(cam_data)
        bpy.data.scenes.remove(scene)


def ensure_gpu_context() -> None:
    """Make gpu drawing available in background mode; a no-op when it already is.

    Blender 5.2 has ``gpu.init()``; without it (or if it fails) a tiny Workbench render creates
    the context. The context then survives ``read_homefile`` / ``read_factory_settings``.
    """
    global _context_ready
    if _context_ready or not bpy.app.background:
        return
    if drawing_available():
        _context_ready = True
        return
    init = getattr(gpu, "init", None)
    if init is not None:
        try:
            init()
        except SystemError:
            pass
    if not drawing_available():
        _context_from_workbench_render()
    if not drawing_available():
        raise RuntimeError("could not create a GPU context for drawing")
    _context_ready = True
