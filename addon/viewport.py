"""The 3D viewport: a POST_VIEW draw handler that draws thin-film objects over the scene.

Drawing never bakes or renders: a material whose table is missing, or a World that changed, is
queued and handled by a timer outside the draw callback (a bake runs on a worker thread; the
World update may render a small Cycles panorama for procedural worlds). Works in Solid and
Material Preview shading; the viewport's depth buffer masks the objects against the scene.

A bake that fails is remembered with its error by description key (:func:`.tables.failure`)
and not queued again until the material's description changes (or Clear Cache, or a
successful Bake button): one failing bake per change, not one per redraw. The error is in the
material panel's error line and, with every other message of the last frame, in the 3D
viewport's header (:func:`draw_header`).
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
#: The messages of the last frame drawn (scene_draw.collect's), shown in the viewport header.
_messages: list[str] = []


def _tag_redraw() -> None:
    for window in getattr(bpy.context.window_manager, "windows", []):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


def _want_bake(desc) -> None:
    """Queue a bake of ``desc`` unless one is queued or running, or its last bake failed."""
    key = description_key(desc)
    if key in tables.FAILURES:
        return  # backs off until the description (so its key) changes
    with _lock:
        if key not in _running:
            _pending[key] = desc


def _bake_worker(key: str, desc, cache) -> None:
    try:
        tables.get_table(desc, cache)
    except Exception as exc:  # reported, never raised into Blender's timer
        text = tables.record_failure(desc, exc)  # before leaving _running: the draw must not re-queue
        log.error("Thin Film SH: bake failed: %s", text)
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
    cache = tables.open_cache() if jobs else None  # here: it reads the preferences
    for key, desc in jobs:
        threading.Thread(target=_bake_worker, args=(key, desc, cache), daemon=True).start()
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
    """POST_VIEW draw handler: draw the film of every visible material in this 3D view."""
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
        items, messages = scene_draw.collect(
            depsgraph, allow_bake=False, allow_world=False, want_bake=_want_bake
        )
        _messages[:] = messages
        if _pending:
            _schedule()
        exposure = float(depsgraph.scene.view_settings.exposure)
        draw_items(items, rv3d.view_matrix, rv3d.window_matrix, display_srgb=True, exposure=exposure)
    except Exception as exc:  # a draw callback must never raise
        log.error("Thin Film SH: viewport draw failed: %s", exc)


def draw_header(self, context) -> None:
    """In the 3D viewport's header: the last frame's first message (a failed bake, a table the
    disk cache could not keep, NaN thickness values, …) and how many more there are."""
    if not _messages:
        return
    more = f" (+{len(_messages) - 1} more)" if len(_messages) > 1 else ""
    self.layout.label(text=f"Thin Film SH: {_messages[0]}{more}", icon="ERROR")


@bpy.app.handlers.persistent
def _on_load(*_args) -> None:
    caches.clear(file_load=True)
    _messages.clear()


@bpy.app.handlers.persistent
def _on_depsgraph(scene, depsgraph) -> None:
    scene_draw.on_depsgraph_update(scene, depsgraph)


def register() -> None:
    """Add the viewport draw handler (not in background mode)."""
    global _handle
    if _handle is None and not bpy.app.background:
        _handle = bpy.types.SpaceView3D.draw_handler_add(draw_callback, (), "WINDOW", "POST_VIEW")
    bpy.types.VIEW3D_HT_header.remove(draw_header)  # once, however often register() runs
    bpy.types.VIEW3D_HT_header.append(draw_header)
    for handlers, fn in (
        (bpy.app.handlers.load_post, _on_load),
        (bpy.app.handlers.depsgraph_update_post, _on_depsgraph),
    ):
        if fn not in handlers:
            handlers.append(fn)


def unregister() -> None:
    """Remove the viewport draw handler."""
    global _handle
    if _handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_handle, "WINDOW")
        _handle = None
    bpy.types.VIEW3D_HT_header.remove(draw_header)
    _messages.clear()
    for handlers, fn in (
        (bpy.app.handlers.load_post, _on_load),
        (bpy.app.handlers.depsgraph_update_post, _on_depsgraph),
    ):
        while fn in handlers:
            handlers.remove(fn)
    if bpy.app.timers.is_registered(_service):
        bpy.app.timers.unregister(_service)
