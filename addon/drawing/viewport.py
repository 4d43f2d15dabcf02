"""The 3D viewport: a POST_VIEW draw handler that draws thin-film objects over the scene.

Drawing never bakes or renders: a material whose table is missing, or a World that changed, is
queued and handled by this module's timer outside the draw callback (a bake runs on a worker
thread, :mod:`..bakes.bake_jobs`; a new World is read by the timer — its image's pixels, or a
small Cycles panorama for procedural worlds — and analysed on a worker,
:mod:`..world.world_job`, while the old lighting is drawn; a Strength or Mapping rotation edit
needs neither; a Principled BSDF's linked Thin Film Thickness that needs a Cycles bake,
:mod:`..thickness.linked`, is baked by the timer on the main thread, where Blender's bakes must
run). Works in Solid and Material Preview shading, and in Rendered shading with EEVEE
(:func:`drawn_in_shading`, a preference); the viewport's depth buffer masks the objects against
the scene.

A bake that fails is remembered with its error by description key (:func:`.tables.failure`)
and not queued again until the material's description changes (or Clear Cache, or a
successful Bake button): one failing bake per change, not one per redraw. The error is in the
material panel's error line and, with every other message of the last frame, in the 3D
viewport's header (:func:`draw_header`).

The overlay can be switched off (:func:`shown_in`): everywhere by the *Show Thin Film Overlay*
preference, or in one 3D viewport by the *Thin Film SH* toggle in its Overlays popover
(:data:`HIDDEN_IN`, :func:`draw_overlay_toggle`). Switched off, the draw callback returns
before collecting anything: nothing is drawn, queued or baked for that viewport.

Background work is visible: while bakes run or the World is analysed, the header says so with
the bakes' progress (:func:`activity`), and its Cancel button (``bake_jobs.cancel_all``) stops
them at their next progress checkpoint.

A viewport bake runs in the bake helper process (:mod:`.bake_helper`) when it is on, its
worker thread waiting on the pipe: Blender's main thread, which holds Python's lock while it
draws, no longer slows it down.

A frame is always drawn with the best data available: while a material's new table bakes, the
draw shows the table it was last drawn with (``scene_draw.Caches.previous``), and when any
background work ends (a bake, a linked thickness's bake, the World's update, the display LUT)
the timer asks for a redraw. The bakes are the bakes room's: the draw asks it for what it needs
(``scene_draw.collect`` with ``bake_later``, :mod:`..bakes.bake_asks`) and its queue
(:mod:`..bakes.bake_jobs`: one bake per material, the newest value winning, a superseded one
cancelled) is started by this module's timer. A bake's worker also computes the film table
(:func:`..bakes.tables.get_film`) when the draw needs it: nothing of the kind runs in a draw.
"""

from __future__ import annotations

import logging
import threading

import bpy

from .. import caches, workers
from ..bakes import bake_asks, bake_helper, bake_jobs, radiance_grids
from ..gpu.draw import draw_items
from ..thickness import linked
from ..ui import prefs
from ..workers import tag_view3d as _tag_redraw
from ..world import world_job, world_state
from . import display, scene_draw, shader_warmup

log = logging.getLogger(__name__)

SHADING_TYPES = {"SOLID", "MATERIAL"}
#: Render engines whose Rendered shading the overlay is drawn over (the *Overlay in Rendered
#: Shading* preference): EEVEE writes the depth the overlay is tested against.
RENDERED_ENGINES = {"BLENDER_EEVEE"}
_handle = None
_world_stale = False
#: The messages of the last frame drawn (scene_draw.collect's), shown in the viewport header.
_messages: list[str] = []
#: 3D viewports (``SpaceView3D.as_pointer()``) whose overlay is switched off (see :mod:`..caches`).
HIDDEN_IN: set = caches.register("hidden_viewports", set(), scope=caches.FILE)
_drawn = threading.Event()  # a viewport drew films since the file was opened: bake ahead on edits


def shown_in(space) -> bool:
    """Whether the overlay is drawn in the 3D viewport ``space``: the preference is on and the
    viewport's own toggle is not off."""
    return prefs.overlay_enabled() and space.as_pointer() not in HIDDEN_IN


def drawn_in_shading(space, scene) -> bool:
    """Whether the overlay draws in the 3D viewport ``space``'s shading: Solid and Material
    Preview, and Rendered with EEVEE while the *Overlay in Rendered Shading* preference is on."""
    kind = space.shading.type
    if kind in SHADING_TYPES:
        return True
    return kind == "RENDERED" and scene.render.engine in RENDERED_ENGINES and prefs.overlay_in_rendered()


def set_shown_in(space, shown: bool) -> None:
    """Switch the overlay on or off in one 3D viewport."""
    if shown:
        HIDDEN_IN.discard(space.as_pointer())
    else:
        HIDDEN_IN.add(space.as_pointer())


def activity() -> str:
    """What runs in the background, for the header: "" when nothing does."""
    parts = [bake_jobs.activity()]
    if _world_stale or world_job.busy():
        parts.append("analyzing the World")
    parts += [radiance_grids.activity(), shader_warmup.activity()]
    return ", ".join(part for part in parts if part)


def _tag_header() -> None:
    """Redraw only the 3D views' headers (the bakes' progress): the frame itself does not change
    until a bake ends, and redrawing it ten times a second takes the CPU the bake needs (two
    llvmpipe cores: the soap bubble's thickness and IOR edits showed in 12–13 s with the view
    redrawn, in about 4 s with the header alone; benchmarks/latency.py, load average ≈ 12)."""
    for window in getattr(bpy.context.window_manager, "windows", []):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                for region in area.regions:
                    if region.type == "HEADER":
                        region.tag_redraw()


def _service() -> float | None:
    """Timer: start queued bakes on threads, refresh the World, ask for a redraw when done."""
    global _world_stale
    if _drawn.is_set():
        bake_helper.warm()  # a few ms once: warm (kernels too) by the first edit
    jobs = bake_jobs.start_queued()
    queued = linked.pending_count()
    if queued:  # Cycles bakes and maps of thicknesses: main thread, never inside the draw
        for error in linked.run_pending():
            log.error("Thin Film SH: linked thickness: %s", error)
    baked = linked.pending_count() < queued  # a map waits maps.SETTLE_S after its last edit
    _world_stale = False
    try:  # the World: read here (bpy), analysed on a worker; a finished worker redraws
        world_done = world_job.service(bpy.context.scene)
    except Exception as exc:
        world_done = False
        log.error("Thin Film SH: World lighting failed: %s", exc)
    finished = bake_jobs.BAKES.take_finished()
    finished = display.take_finished() or finished  # the scene's display LUT is ready
    if baked or finished or world_done:
        _tag_redraw()
    elif jobs or bake_jobs.BAKES.busy():
        _tag_header()  # progress only
    if bake_jobs.busy() or bake_jobs.BAKES.finished():
        return bake_jobs.POLL_S  # a bake ends within ~0.05–0.3 s: looked for often, at µs a look
    return 0.1 if world_job.busy() or display.baking() or linked.has_pending() else None


def _schedule() -> None:
    if not bpy.app.timers.is_registered(_service):
        bpy.app.timers.register(_service, first_interval=0.0)


def schedule() -> None:
    """Start the timer that runs queued work (a panel queued a linked thickness's bake)."""
    _schedule()


def draw_callback() -> None:
    """POST_VIEW draw handler: draw the film of every visible material in this 3D view, unless
    the overlay is switched off there (:func:`shown_in`)."""
    global _world_stale
    context = bpy.context
    space = context.space_data
    if space is None or space.type != "VIEW_3D" or not drawn_in_shading(space, context.scene):
        return
    if not shown_in(space):
        return
    rv3d = context.region_data
    depsgraph = context.evaluated_depsgraph_get()
    number = workers.FRAMES.start()
    try:
        lighting = world_state.world_lighting(depsgraph.scene, allow_compute=False)
        if world_job.busy():  # a new World (or prefilter) to analyse: the old one is drawn meanwhile
            _schedule()
        if lighting is None:
            _world_stale = True
            return
        with linked.deferring():  # a linked thickness that needs a bake is queued for the timer
            items, messages = scene_draw.collect(
                depsgraph, allow_bake=False, allow_world=False, bake_later=True
            )
        if linked.baking():
            messages.append("a linked Thin Film Thickness is being baked with Cycles")
        _messages[:] = messages
        _drawn.set()
        if bake_jobs.pending() or linked.has_pending() or world_job.busy():  # collect may ask for a prefilter
            _schedule()
        settings = display.settings_of(depsgraph.scene)
        lut = display.viewport_lut(settings)  # None (Standard sRGB) until its bake is done
        if lut is None and display.baking():
            _schedule()
        draw_items(
            items,
            rv3d.view_matrix,
            rv3d.window_matrix,
            display_srgb=True,
            exposure=settings.exposure,
            display_lut=lut,
            compile_now=False,
        )
        shader_warmup.schedule()  # the variants this frame drew by their stand-in
    except Exception as exc:  # a draw callback must never raise
        log.error("Thin Film SH: viewport draw failed: %s", exc)
    finally:
        workers.FRAMES.end(number)


def draw_header(self, context) -> None:
    """In the 3D viewport's header: what runs in the background (bakes with their progress, the
    World's analysis), then the last frame's first message (a failed bake, a table the disk
    cache could not keep, NaN thickness values, …) and how many more there are."""
    busy = activity()
    if busy:
        row = self.layout.row(align=True)
        row.label(text=f"Thin Film SH: {busy}", icon="TIME")
        row.operator("thinfilm.cancel_bakes", text="", icon="CANCEL")
    if not _messages:
        return
    more = f" (+{len(_messages) - 1} more)" if len(_messages) > 1 else ""
    self.layout.label(text=f"Thin Film SH: {_messages[0]}{more}", icon="ERROR")


def draw_overlay_toggle(self, context) -> None:
    """In the 3D viewport's Overlays popover: this viewport's Thin Film SH switch."""
    space = context.space_data
    if space is None or space.type != "VIEW_3D":
        return
    layout = self.layout
    row = layout.row()
    row.active = prefs.overlay_enabled()
    shown = space.as_pointer() not in HIDDEN_IN
    row.operator(
        "thinfilm.toggle_overlay",
        text="Thin Film SH",
        icon="CHECKBOX_HLT" if shown else "CHECKBOX_DEHLT",
        depress=shown,
    )


@bpy.app.handlers.persistent
def _on_load(*_args) -> None:
    caches.clear(file_load=True)
    _messages.clear()
    _drawn.clear()


@bpy.app.handlers.persistent
def _on_depsgraph(scene, depsgraph) -> None:
    scene_draw.on_depsgraph_update(scene, depsgraph)
    if not _drawn.is_set():
        return  # no viewport draws films: nothing to bake ahead for
    try:  # an edited material's bake starts now, while its first redraw shows the old table
        if bake_asks.ask_changed(depsgraph, scene_draw.CACHES.previous, world_state.current()):
            bake_jobs.start_queued()
            _schedule()  # the timer starts what waits for a superseded bake, and redraws
    except Exception as exc:  # a handler must never raise; the draw asks for the bake anyway
        log.error("Thin Film SH: early bake failed: %s", exc)


def register() -> None:
    """Add the viewport draw handler (not in background mode)."""
    global _handle
    if _handle is None and not bpy.app.background:
        _handle = bpy.types.SpaceView3D.draw_handler_add(draw_callback, (), "WINDOW", "POST_VIEW")
    bpy.types.VIEW3D_HT_header.remove(draw_header)  # once, however often register() runs
    bpy.types.VIEW3D_HT_header.append(draw_header)
    bpy.types.VIEW3D_PT_overlay.remove(draw_overlay_toggle)
    bpy.types.VIEW3D_PT_overlay.append(draw_overlay_toggle)
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
    bpy.types.VIEW3D_PT_overlay.remove(draw_overlay_toggle)
    _messages.clear()
    for handlers, fn in (
        (bpy.app.handlers.load_post, _on_load),
        (bpy.app.handlers.depsgraph_update_post, _on_depsgraph),
    ):
        while fn in handlers:
            handlers.remove(fn)
    if bpy.app.timers.is_registered(_service):
        bpy.app.timers.unregister(_service)
    shader_warmup.unregister()
