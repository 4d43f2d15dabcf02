"""The 3D viewport: a POST_VIEW draw handler that draws thin-film objects over the scene.

Drawing never bakes or renders: a material whose table is missing, or a World that changed, is
queued and handled by a timer outside the draw callback (a bake runs on a worker thread; the
World update may render a small Cycles panorama for procedural worlds). Works in Solid and
Material Preview shading; the viewport's depth buffer masks the objects against the scene.
"""

from __future__ import annotations

import logging
import threading

import bpy

from . import caches, scene_draw, tables
from .description import description_key
from .gpu.draw import draw_items

log = logging.getLogger(__name__)

SHADING_TYPES = {"SOLID", "MATERIAL"}
_handle = None
_pending: dict[str, object] = {}  # description key → Material waiting for a bake
_running: set[str] = set()
_world_stale = False
_lock = threading.Lock()


def _tag_redraw() -> None:
    for window in getattr(bpy.context.window_manager, "windows", []):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


def _want_bake(desc) -> None:
    key = description_key(desc)
    with _lock:
        if key not in _running:
            _pending[key] = desc


def _bake_worker(key: str, desc) -> None:
    try:
        tables.get_table(desc)
    except Exception as exc:  # reported, never raised into Blender's timer
        log.error("Thin Film SH: bake failed: %s", exc)
    finally:
        with _lock:
            _running.discard(key)


def _service() -> float | None:
    """Timer: start queued bakes on threads, refresh the World, ask for a redraw when done."""
    global _world_stale
    with _lock:
        jobs = list(_pending.items())
        _pending.clear()
        _running.update(key for key, _ in jobs)
    for key, desc in jobs:
        threading.Thread(target=_bake_worker, args=(key, desc), daemon=True).start()
    if _world_stale and bpy.context.scene is not None:
        _world_stale = False
        try:
            scene_draw.world_lighting(bpy.context.scene, allow_compute=True)
        except Exception as exc:
            log.error("Thin Film SH: World lighting failed: %s", exc)
    if jobs or _running:
        _tag_redraw()
    return 0.1 if (_running or _pending) else None


def _schedule() -> None:
    if not bpy.app.timers.is_registered(_service):
        bpy.app.timers.register(_service, first_interval=0.0)


def draw_callback() -> None:
    global _world_stale
    context = bpy.context
    space = context.space_data
    if space is None or space.type != "VIEW_3D" or space.shading.type not in SHADING_TYPES:
        return
    rv3d = context.region_data
    depsgraph = context.evaluated_depsgraph_get()
    try:
        if scene_draw.world_lighting(depsgraph.scene, allow_compute=False) is None:
            _world_stale = True
            _schedule()
            return
        items, _ = scene_draw.collect(depsgraph, allow_bake=False, allow_world=False, want_bake=_want_bake)
        if _pending:
            _schedule()
        exposure = float(depsgraph.scene.view_settings.exposure)
        draw_items(items, rv3d.view_matrix, rv3d.window_matrix, display_srgb=True, exposure=exposure)
    except Exception as exc:  # a draw callback must never raise
        log.error("Thin Film SH: viewport draw failed: %s", exc)


@bpy.app.handlers.persistent
def _on_load(*_args) -> None:
    caches.clear(file_load=True)


@bpy.app.handlers.persistent
def _on_depsgraph(scene, depsgraph) -> None:
    scene_draw.on_depsgraph_update(scene, depsgraph)


def register() -> None:
    global _handle
    if _handle is None and not bpy.app.background:
        _handle = bpy.types.SpaceView3D.draw_handler_add(draw_callback, (), "WINDOW", "POST_VIEW")
    for handlers, fn in (
        (bpy.app.handlers.load_post, _on_load),
        (bpy.app.handlers.depsgraph_update_post, _on_depsgraph),
    ):
        if fn not in handlers:
            handlers.append(fn)


def unregister() -> None:
    global _handle
    if _handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_handle, "WINDOW")
        _handle = None
    for handlers, fn in (
        (bpy.app.handlers.load_post, _on_load),
        (bpy.app.handlers.depsgraph_update_post, _on_depsgraph),
    ):
        while fn in handlers:
            handlers.remove(fn)
    if bpy.app.timers.is_registered(_service):
        bpy.app.timers.unregister(_service)
