"""The 3D viewport: a POST_VIEW draw handler that draws thin-film objects over the scene.

Drawing never bakes or renders: a material whose table is missing, or a World that changed, is
queued and handled by a timer outside the draw callback (a bake runs on a worker thread; a new
World is read by the timer — its image's pixels, or a small Cycles panorama for procedural
worlds — and analysed on a worker, :mod:`.world_job`, while the old lighting is drawn; a
Strength or Mapping rotation edit needs neither; a Principled BSDF's
linked Thin Film Thickness that needs a Cycles bake, :mod:`.linked`, is baked by the timer on
the main thread, where Blender's bakes must run). Works in Solid and
Material Preview shading, and in Rendered shading with EEVEE (:func:`drawn_in_shading`, a
preference); the viewport's depth buffer masks the objects against the scene.

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
the bakes' progress (:func:`activity`), and ``viewport.cancel_bakes`` stops them at their next
progress checkpoint.

A viewport bake runs in the bake helper process (:mod:`.bake_helper`) when it is on, its
worker thread waiting on the pipe: Blender's main thread, which holds Python's lock while it
draws, no longer slows it down.

A frame is always drawn with the best data available: while a material's new table bakes, the
draw shows the table it was last drawn with (``scene_draw.Caches.previous``), and when any
background work ends (a bake, a linked thickness's bake, the World's update) the timer asks for
a redraw. The queue holds one bake per material (:func:`scene_draw.material_identity`), the
newest value winning: dragging a slider over ten values leaves one bake, and a running bake
whose description no material wants any more is cancelled at its next progress checkpoint
(:class:`_Job`'s own cancel, not :func:`cancel_bakes`'). A bake's worker also computes the film
table (:func:`.tables.get_film`) when the draw needs it: nothing of the kind runs in a draw.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field

import bpy

from ..precompute.progress import reporting
from . import (
    bake_asks,
    bake_helper,
    caches,
    display,
    linked,
    prefs,
    radiance_grids,
    scene_draw,
    shader_warmup,
    tables,
    world_job,
)
from .description import description_key
from .gpu.draw import draw_items
from .redraw import tag_view3d as _tag_redraw

log = logging.getLogger(__name__)

SHADING_TYPES = {"SOLID", "MATERIAL"}
#: Render engines whose Rendered shading the overlay is drawn over (the *Overlay in Rendered
#: Shading* preference): EEVEE writes the depth the overlay is tested against.
RENDERED_ENGINES = {"BLENDER_EEVEE"}
_handle = None


@dataclass
class _Job:
    """One viewport bake: the description ``desc`` (its key ``key``), whether the film table is
    wanted too, its own cancel (set when no material wants ``key`` any more) and progress."""

    key: str
    desc: object
    film: bool = False
    cancel: threading.Event = field(default_factory=threading.Event)
    progress: float = 0.0
    #: Run on the worker after the table (and film table): ``then(key, desc, result)``, the
    #: material's grid (:func:`.radiance_grids.chain`), so the bake's one redraw shows both.
    then: object = None
    #: The bake handed to the helper process by the main thread when the job started
    #: (:func:`.bake_helper.submit`), or None: the worker waits for it.
    ticket: object = None
    #: A newer value of its material replaced it (:func:`_want_bake`): it ends without a redraw.
    superseded: bool = False


_pending: dict[object, _Job] = {}  # material identity → the newest bake it wants
_running: dict[str, _Job] = {}  # description key → its running bake
_wanted: dict[object, str] = {}  # material identity → the description key it wants now
_world_stale = False
_lock = threading.Lock()
#: The messages of the last frame drawn (scene_draw.collect's), shown in the viewport header.
_messages: list[str] = []
#: 3D viewports (``SpaceView3D.as_pointer()``) whose overlay is switched off (see :mod:`.caches`).
HIDDEN_IN: set = caches.register("hidden_viewports", set(), scope=caches.FILE)
_finished = threading.Event()  # a worker ended since the timer's last tick: redraw
_drawn = threading.Event()  # a viewport drew films since the file was opened: bake ahead on edits
#: Seconds between the timer's looks while bakes run: a warm bake takes 0.01–0.1 s, so the
#: 0.1 s poll it had added up to 0.1 s to an edit's wait (and 10 ms up to 10 ms); a look that
#: finds nothing costs µs.
POLL_S = 0.005


class BakesCancelled(Exception):
    """Raised inside a viewport bake's progress callback once :func:`cancel_bakes` was called."""


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
    parts = []
    with _lock:
        running = {key: job.progress for key, job in _running.items() if not job.cancel.is_set()}
    if running:
        done = sum(running.values()) / len(running)
        parts.append(f"baking {len(running)} film{'s' if len(running) > 1 else ''} ({100 * done:.0f} %)")
    if _world_stale or world_job.busy():
        parts.append("analyzing the World")
    for extra in (radiance_grids.activity(), shader_warmup.activity()):
        if extra:
            parts.append(extra)
    return ", ".join(parts)


def cancel_bakes() -> int:
    """Stop the running viewport bakes at their next progress checkpoint (≤ one step of the
    bake, :mod:`precompute.progress`) and drop the queued ones; returns how many were running.
    Nothing half-made is cached, and a cancelled bake is not remembered as failed: the next
    draw queues it again unless the overlay is switched off."""
    with _lock:
        jobs = list(_running.values())
        _pending.clear()
    for job in jobs:
        job.cancel.set()
        if job.ticket is not None:
            job.ticket.cancel()  # the helper stops it now, whatever its worker waits for
    return len(jobs)


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


def _want_bake(desc, owner=None, film: bool = False, then=None) -> None:
    """Queue a bake of ``desc`` for the material ``owner`` (None: the description itself), with
    its film table if ``film`` and ``then`` run after it (:attr:`_Job.then`), unless its last
    bake failed. One bake per owner: a newer description replaces the queued one, and a running
    bake that no owner wants any more is cancelled at its next progress checkpoint."""
    key = description_key(desc)
    if key in tables.FAILURES:
        return  # backs off until the description (so its key) changes
    owner = key if owner is None else owner
    with _lock:
        _wanted[owner] = key
        running = _running.get(key)
        if running is not None and (running.film or not film):
            _pending.pop(owner, None)  # the running bake makes what this owner wants
            running.then = running.then or then  # read by its worker after the table
        else:
            queued = _pending.get(owner)
            same = queued is not None and queued.key == key
            film = film or (same and queued.film)
            _pending[owner] = _Job(key, desc, film, then=then or (queued.then if same else None))
        wanted = set(_wanted.values())
        superseded = [job for job in _running.values() if job.key not in wanted]
    for job in superseded:
        job.superseded = True  # before the cancel: its worker reads it once it stops
        job.cancel.set()  # stops at its next checkpoint, caches nothing
        if job.ticket is not None:
            job.ticket.cancel()  # in the helper too, now: its worker may wait for the lock


def _table_of(job: _Job, cache, report):
    """(table, source) of the job: from memory or disk, else baked by the helper (its ticket,
    handed over on the main thread) or in process (:func:`.tables.get_table_with_source`). A ticket whose
    table was found after all, or whose job failed or was superseded, is cancelled."""
    baker = bake_helper.baker(job.ticket, tables.keep_film) if job.ticket is not None else None
    try:
        result, source = tables.get_table_with_source(
            job.desc, cache, report, store=False, keep_nodes=True, baker=baker
        )
    except BaseException:
        if job.ticket is not None:
            job.ticket.cancel()
        raise
    if job.ticket is not None and source != "bake":
        job.ticket.cancel()  # in memory or on disk after all
    return result, source


def _bake_worker(job: _Job, cache) -> None:
    def report(fraction, text):
        if job.cancel.is_set():
            raise BakesCancelled
        job.progress = float(fraction)

    baked = result = None
    cancelled = False
    try:
        report(0.0, "")  # superseded before it started: stops here
        result, source = _table_of(job, cache, report)
        baked = result if source == "bake" else None
        if not job.film:
            tables.release_nodes(result)
        else:  # from the fresh bake's reflectance at its nodes: no second sweep
            report(1.0, "film table")  # superseded meanwhile: stops here
            tables.get_film(job.desc, result, report)
        report(1.0, "grid")
        _then(job, result)
    except BakesCancelled:
        cancelled = True
        tables.release_nodes(result)
    except Exception as exc:  # reported, never raised into Blender's timer
        text = tables.record_failure(job.desc, exc)  # before leaving _running: the draw must not re-queue
        log.error("Thin Film SH: bake failed: %s", text)
    finally:
        with _lock:
            if _running.get(job.key) is job:
                del _running[job.key]
            for owner in [o for o, k in _wanted.items() if k == job.key and o not in _pending]:
                del _wanted[owner]  # served (or failed, or cancelled: the next draw asks again)
        shown_after = _frames.started
        if not (cancelled and job.superseded):  # it has nothing to show: a redraw would delay the next
            _finished.set()  # its table, its error or its cancel (the header): the timer redraws
    if baked is not None:  # after the frame that shows it: the disk copy only serves the next session
        _frames.wait_past(shown_after, STORE_WAIT_S)  # the write would compete with that frame
        if tables.MEMORY.get(job.key) is not None:  # not cleared meanwhile (Clear Cache, file load)
            tables.store_table(job.desc, baked, cache)
        if tables.CACHE_ERRORS.get(job.key) is not None:
            _finished.set()  # a redraw shows why the table was not saved


class _FrameCount:
    """The draw callback's frames, numbered: a bake's worker waits for the first frame started
    after its table arrived (:meth:`wait_past`) before it writes the table's disk copy."""

    def __init__(self):
        self.started = 0
        self.ended = 0
        self._cond = threading.Condition()

    def start(self) -> int:
        """A frame begins: its number."""
        with self._cond:
            self.started += 1
            return self.started

    def end(self, number: int) -> None:
        """Frame ``number`` has been drawn (or given up)."""
        with self._cond:
            self.ended = max(self.ended, number)
            self._cond.notify_all()

    def wait_past(self, number: int, timeout: float) -> bool:
        """Wait until a frame started after frame ``number`` has ended, at most ``timeout`` s."""
        with self._cond:
            return self._cond.wait_for(lambda: self.ended > number, timeout)


_frames = _FrameCount()
#: Longest a bake's worker waits for the frame that shows its table before writing the disk copy
#: (no viewport redraws, e.g. it is hidden): the copy only serves the next session.
STORE_WAIT_S = 1.0


def _check_cancel(job: _Job) -> None:
    if job.cancel.is_set():
        raise BakesCancelled


def _then(job: _Job, result) -> None:
    """Run the job's follow-up (its grid) unless it was superseded; its failure is logged and
    leaves the table (the draw asks for the grid again)."""
    if job.then is None or job.cancel.is_set():
        return
    try:
        built = getattr(job.ticket, "grid", None)  # built by the bake helper with the table
        with reporting(lambda: _check_cancel(job)):  # the grid's steps: a superseded job stops
            if built is not None:
                job.then(job.key, job.desc, result, built)
            else:
                job.then(job.key, job.desc, result)
    except BakesCancelled:
        raise
    except Exception as exc:  # the table is good; the draw asks for the grid the usual way
        log.error("Thin Film SH: radiance grid after the bake failed: %s", exc)


def _start_jobs() -> list[_Job]:
    """Move the queued bakes that can start now to :data:`_running`; a description already
    being baked waits (unless that bake makes what it wants: then it is dropped). Nothing starts
    while a superseded in-process bake is still stopping (it ends at its next checkpoint, tens
    of ms): on two cores a slider drag's newest bake would otherwise share them with every older
    one. A bake handed to the helper is no such obstacle: its cancel went to the helper with the
    superseding edit, and the helper bakes one request after the other."""
    jobs = []
    with _lock:
        if any(job.cancel.is_set() and job.ticket is None for job in _running.values()):
            return jobs
        for owner, job in list(_pending.items()):
            running = _running.get(job.key)
            if running is not None:
                if running.film or not job.film:
                    del _pending[owner]
                continue
            del _pending[owner]
            if _wanted.get(owner) != job.key:
                continue  # superseded since it was queued
            _running[job.key] = job
            jobs.append(job)
    return jobs


def _on_disk(cache, key: str) -> bool:
    """Whether the disk cache has a table file for ``key`` (one stat: a reopened file's tables
    are read by the worker, not baked by the helper)."""
    path_for = getattr(cache, "path_for", None)  # an UnusableCache has none
    try:
        return path_for is not None and path_for(key).is_file()
    except (OSError, ValueError):
        return False


def _start_queued() -> list[_Job]:
    """Start the queued bakes that can start now, each on its thread (main thread: the cache
    folder comes from the preferences). A table not in memory is handed to the bake helper
    here, before the thread runs: that thread needs Python's lock, which the edit's first
    redraw holds for its whole draw (20–40 ms on the 2-core machine's llvmpipe)."""
    jobs = _start_jobs()
    cache = tables.open_cache() if jobs else None
    for job in jobs:
        if bake_helper.enabled() and tables.peek_table(job.desc) is None and not _on_disk(cache, job.key):
            try:
                spec = getattr(job.then, "helper_spec", None)  # its grid, built there too
                job.ticket = bake_helper.submit(job.desc, job.film, spec() if spec is not None else None)
            except bake_helper.HelperError:
                pass  # the worker bakes in process (and gives the helper up, if it is broken)
        threading.Thread(target=_bake_worker, args=(job, cache), daemon=True).start()
    return jobs


def _service() -> float | None:
    """Timer: start queued bakes on threads, refresh the World, ask for a redraw when done."""
    global _world_stale
    if _drawn.is_set():
        bake_helper.warm()  # a few ms once: warm (kernels too) by the first edit
    jobs = _start_queued()
    baked = linked.has_pending()
    if baked:  # Cycles bakes of linked thicknesses: main thread, never inside the draw
        for error in linked.run_pending():
            log.error("Thin Film SH: linked thickness: %s", error)
    _world_stale = False
    try:  # the World: read here (bpy), analysed on a worker; a finished worker redraws
        world_done = world_job.service(bpy.context.scene)
    except Exception as exc:
        world_done = False
        log.error("Thin Film SH: World lighting failed: %s", exc)
    finished = _finished.is_set()
    _finished.clear()
    finished = display.take_finished() or finished  # the scene's display LUT is ready
    if baked or finished or world_done:
        _tag_redraw()
    elif jobs or _running:
        _tag_header()  # progress only
    if _running or _pending or _finished.is_set():
        return POLL_S  # a bake ends within ~0.05–0.3 s: looked for often, at µs a look
    return 0.1 if world_job.busy() or display.baking() else None


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
    number = _frames.start()
    try:
        lighting = scene_draw.world_lighting(depsgraph.scene, allow_compute=False)
        if world_job.busy():  # a new World (or prefilter) to analyse: the old one is drawn meanwhile
            _schedule()
        if lighting is None:
            _world_stale = True
            return
        with linked.deferring():  # a linked thickness that needs a bake is queued for the timer
            items, messages = scene_draw.collect(
                depsgraph, allow_bake=False, allow_world=False, want_bake=_want_bake
            )
        if linked.has_pending():
            messages.append("a linked Thin Film Thickness is being baked with Cycles")
        _messages[:] = messages
        _drawn.set()
        if _pending or linked.has_pending() or world_job.busy():  # collect may ask for a prefilter
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
        _frames.end(number)


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
        drawn = scene_draw.CACHES
        if bake_asks.ask_changed(depsgraph, _want_bake, drawn.previous, drawn.world):
            _start_queued()
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
