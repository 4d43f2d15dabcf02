"""Keeping every film material's EEVEE path in step with its film, live and headless.

- **Live (the interface):** ``depsgraph_update_post`` notes the materials an update touched;
  a timer reads their :class:`.source.Spec` on the main thread and, where the image's key
  differs, queues the spec for one worker (a job on the lane :data:`WORK`,
  :mod:`..workers`), which gets the table (memory, disk cache, or a
  bake: in the bake helper process when it is on, :mod:`..bake_helper`) and computes the
  pixels (:func:`precompute.bakes.eevee_table.film_image`). The timer then writes them (:mod:`.wiring`:
  a copy, an update, a pack). A newer edit of the same material replaces a queued one; the
  EEVEE film shows its last image until then. A film that is switched off loses its EEVEE path
  at once.
- **Headless (``blender -b``, the bpy module):** after a file loads (``load_post``) and before
  each render (``render_pre`` on the main thread: ``bpy.ops.render.render``, ``-f``, ``-a``)
  every film material is synced in place, baking what it needs, so a farm renders the film
  even from a file saved without it (a linked thickness that needs a Cycles bake to find its
  range is evaluated at load, never inside a render). In the interface, F12's ``render_pre``
  runs on the render job's thread and writes nothing: the live path has already.

:func:`sync_material` and :func:`sync_all` are the calls the tests and commands use.
"""

from __future__ import annotations

import logging
import threading
import time

import bpy

from ...precompute.bakes import eevee_table
from ...precompute.world import prefilter
from .. import caches, workers
from ..bakes import bake_helper, tables
from ..thickness import linked, maps
from ..workers import tag_view3d as _tag_redraw
from ..world import world_state
from . import image as film_image_store
from . import lights as light_objects
from . import nodes, source, wiring

__all__ = [
    "compute",
    "pending",
    "register",
    "status",
    "sync_all",
    "sync_material",
    "unregister",
    "wait_idle",
    "world_of",
]

log = logging.getLogger(__name__)

#: Seconds between the timer's looks while work is queued or running.
POLL_S = 0.02
#: Seconds between its looks at the World's analysis while the file has EEVEE films: a new World
#: (or a Strength or rotation edit) changes their dominant-direction image.
WORLD_POLL_S = 0.5
_world_key: str | None = None  # the World analysis the films were last read with
_lights_signature: tuple | None = None  # the light objects they were last read with (.lights)
_maps_seen = 0  # thickness maps made when the films were last read (maps.STATS["made"])
#: The EEVEE films' background work: one worker job (key :data:`_WORKER`) that drains
#: :data:`_queue`. Its lock guards the dictionaries below (never held while the worker computes).
WORK = workers.Lane("EEVEE film")
_WORKER = "worker"
_queue: dict = {}  # material name → (spec, cache, helper ticket): the newest edit per material
_done: list = []  # (material name, spec, FilmImage | Exception), filled by the worker
_lock = WORK.lock
_wanted: dict[str, str] = {}  # material name → the spec key it wants now
_dirty: set[str] = set()  # materials an update touched: the timer reads their spec
_idle = threading.Event()  # set while nothing is queued or computed (the tests wait on it)
_idle.set()
#: Main-thread seconds spent writing each image (the tests and the benchmark read it).
write_seconds: list[float] = []


def compute(spec: source.Spec, cache=None, baker=None):
    """(film image, dominant-direction pixels or None) of ``spec``: its table
    (:func:`..tables.get_table_with_source`), the diffuse base's and the film table a wall
    needs, then the pixels; the World's prefilter with moments (computed here the first time:
    seconds) and the directions at the film's roughness. Thread-safe, no bpy."""
    result = tables.get_table_with_source(spec.film, cache, baker=baker)[0]
    film = tables.get_film(spec.film, result) if spec.wall is not None else None
    base = tables.get_table(spec.base, cache) if spec.base is not None else None
    made = eevee_table.film_image(
        result, film=film, wall=spec.wall, base_result=base, base_color=spec.base_color
    )
    light, pre = None, None
    if spec.world is not None:
        pre = _moments(spec.world.environment)
        if spec.world.matrix is not None or spec.world.scale != 1.0:
            pre = pre.transformed(rotation=spec.world.matrix, scale=spec.world.scale)
    if pre is not None or spec.lights is not None:
        light = eevee_table.dominant_directions(pre, float(spec.film.roughness), lights=spec.lights)
    return made, light


#: Width of the prefilter the directions are read from when the overlay has not computed its own:
#: 0.4 s for the studio HDRI against 1.05 s at the overlay's 512, directions within 1° (p95).
MOMENTS_WIDTH = 256
#: (environment, Prefiltered) by the environment's id, the last two Worlds (see :mod:`..caches`).
MOMENTS = caches.register("eevee_moments", caches.LRU(2), scope=caches.FILE)


def _moments(environment):
    """A prefilter with moments of ``environment``'s panorama: the overlay's whole-World one when
    it exists, else one of :data:`MOMENTS_WIDTH` (kept for the last two Worlds)."""
    if "prefiltered_whole" in environment.__dict__:  # functools.cached_property, computed
        return environment.prefiltered_whole
    found = MOMENTS.get(id(environment))
    if found is not None and found[0] is environment:
        return found[1]
    pre = prefilter.prefilter(environment.panorama, width=MOMENTS_WIDTH)
    MOMENTS[id(environment)] = (environment, pre)
    return pre


def world_of(scene, compute: bool | None = None) -> source.WorldRef | None:
    """The scene's World as the overlay analysed it (``scene_draw.world_lighting``): analysed
    here when ``compute`` (default: in background mode), else the last analysis (the viewport's
    worker makes it), or None."""
    try:
        allow = bpy.app.background if compute is None else compute
        lighting = world_state.world_lighting(scene, allow_compute=allow)
    except Exception as exc:  # the film is still written, read at the view angle
        log.info("Thin Film SH: no World analysis for EEVEE films: %s", exc)
        return None
    if lighting is None or lighting.environment is None:
        return None
    scale = 1.0 if lighting.scale is None else float(lighting.scale)
    return source.WorldRef(lighting.key, lighting.environment, lighting.matrix, scale)


def _spec_of(material, scene, defer: bool, world, lights):
    """(spec or None, True if known). ``defer``: a linked thickness that needs a Cycles bake is
    queued (:func:`..linked.deferring`) and the film is not known until it is done. ``world``
    (False) and ``lights`` (None) are read here when not given."""
    if world is False:
        world = world_of(scene)
    if lights is None:
        lights = light_objects.SceneLights(scene)
    lights = lights.for_material(material) if source.may_show_film(material) else None
    try:
        if defer:
            with linked.deferring():
                return source.spec(material, scene, world, lights), True
        return source.spec(material, scene, world, lights), True
    except linked.Pending:
        return None, False
    except ValueError as exc:  # the panel and the overlay say why; EEVEE keeps what it had
        log.info("Thin Film SH: EEVEE film of %r not updated: %s", material.name, exc)
        return None, False


def _current_key(material) -> str | None:
    """The key of the film image ``material``'s group reads (None: no EEVEE path)."""
    node, _output = nodes.find(material.node_tree)
    if node is None or node.node_tree is None:
        return None
    return film_image_store.stored_key(nodes.film_image_of(node.node_tree))


def _written(material, spec, made) -> None:
    t0 = time.perf_counter()
    wiring.apply(material, spec, *made)
    write_seconds.append(time.perf_counter() - t0)


def sync_material(
    material, scene=None, wait: bool = True, defer: bool | None = None, world=False, lights=None
) -> str:
    """Bring ``material``'s EEVEE path in step: "removed", "unchanged", "written" (``wait``: baked
    here), "queued" (the worker bakes it), "read-only" (a linked material) or "unknown" (its film
    cannot be evaluated now). ``defer`` (default: not ``wait``): a linked thickness that needs a
    Cycles bake is queued instead of baked here. ``world``: a :class:`.source.WorldRef` (or None)
    already read for this scene, else it is read here (:func:`world_of`); ``lights``: the scene's
    :class:`.lights.SceneLights` already read (None: read here). Main thread."""
    if material.node_tree is None or wiring.is_read_only(material):
        return "read-only"
    scene = scene or bpy.context.scene
    spec, known = _spec_of(material, scene, (not wait) if defer is None else defer, world, lights)
    if not known:
        return "unknown"
    if spec is None:
        with _lock:
            _wanted.pop(material.name, None)
        return "removed" if wiring.remove(material) else "unchanged"
    key = spec.key
    if _current_key(material) == key:
        node, _output = nodes.find(material.node_tree)
        wiring.feed(material, node, spec, getattr(material, "thinfilm_sh", None))  # a relinked input
        return "unchanged"
    if wait:
        _written(material, spec, compute(spec))
        return "written"
    with _lock:
        if _wanted.get(material.name) == key:
            return "queued"
        _wanted[material.name] = key
    ticket = None
    if bake_helper.enabled() and tables.peek_table(spec.film) is None:
        try:
            ticket = bake_helper.submit(spec.film, spec.wall is not None)
        except bake_helper.HelperError:
            ticket = None  # baked in process
    with _lock:
        _idle.clear()
        replaced = _queue.pop(material.name, None)
        _queue[material.name] = (spec, tables.open_cache(), ticket)
        if _WORKER not in WORK.running:
            WORK.start(workers.Job(_WORKER, _work))
    if replaced is not None and replaced[2] is not None:
        replaced[2].cancel()  # the helper stops the superseded bake
    _schedule()
    return "queued"


def status(material) -> str:
    """One line for the material panel: whether EEVEE renders this material's film itself ("" when
    it has no EEVEE path)."""
    node, _output = nodes.find(getattr(material, "node_tree", None))
    if node is None:
        return ""
    if material.library is not None:
        return f"EEVEE renders this film (from the library {material.library.name!r})"
    with _lock:
        waiting = material.name in _wanted or material.name in _dirty
    if waiting:
        return "EEVEE's film is being updated (the last one is shown meanwhile)"
    return "EEVEE renders this film itself (F12, Rendered view, blender -b -a)"


def sync_all(scene=None, wait: bool = True, defer: bool | None = None, world=False) -> dict[str, str]:
    """:func:`sync_material` for every material of the file; {name: outcome}. ``world``: as for
    :func:`sync_material` (False: read here, :func:`world_of`)."""
    scene = scene or bpy.context.scene
    materials = [m for m in bpy.data.materials if m.node_tree is not None]
    if world is False:
        world = world_of(scene) if _has_films(materials) else None
    lights = light_objects.SceneLights(scene)
    return {m.name: sync_material(m, scene, wait, defer, world, lights) for m in materials}


def _has_films(materials) -> bool:
    """Whether any of ``materials`` has a film to write or an EEVEE path to keep: only then is
    the World read (and a procedural one rendered); a file without films loads without it."""
    return any(
        m.node_tree is not None and (source.may_show_film(m) or nodes.find(m.node_tree)[0] is not None)
        for m in materials
    )


def _work() -> None:
    """The worker (a job on :data:`WORK`, one at a time): compute the queued films one after the
    other until none is left; the timer writes each (:func:`_finish`)."""
    while True:
        with _lock:
            if not _queue:  # off the running jobs now, in the step that finds the queue empty
                WORK.running.pop(_WORKER, None)  # this job: only one is ever started at a time
                _idle.set()
                return
            name = next(iter(_queue))
            spec, cache, ticket = _queue.pop(name)
            stale = _wanted.get(name) != spec.key
        if stale:
            if ticket is not None:
                ticket.cancel()
            continue
        baker = bake_helper.baker(ticket, tables.keep_film) if ticket is not None else None
        try:
            made = compute(spec, cache, baker)
        except Exception as exc:  # reported on the main thread
            made = exc
        with _lock:
            _done.append((name, spec, made))


def pending() -> bool:
    """Whether EEVEE images are queued, being computed or waiting to be written."""
    with _lock:
        return bool(_dirty or _done or _queue) or not _idle.is_set()


def wait_idle(timeout: float = 60.0) -> bool:
    """Wait until the worker has computed everything queued (tests); the timer still writes."""
    return _idle.wait(timeout)


def _finish() -> None:
    with _lock:
        finished, _done[:] = list(_done), []
    for name, spec, made in finished:
        material = bpy.data.materials.get(name)
        with _lock:
            current = _wanted.get(name) == spec.key
            if current:
                _wanted.pop(name, None)
        if material is None or not current:
            continue
        if isinstance(made, Exception):
            log.error("Thin Film SH: EEVEE film of %r failed: %s", name, made)
            continue
        try:
            _written(material, spec, made)
        except Exception as exc:  # a timer must never raise
            log.error("Thin Film SH: writing the EEVEE film of %r failed: %s", name, exc)


def _service() -> float | None:
    """Timer: read the touched materials' specs, queue what changed, write what is done."""
    with _lock:
        names = list(_dirty)
        _dirty.clear()
    scene = bpy.context.scene
    world = world_of(scene)
    current = None if world is None else world.key
    global _world_key, _lights_signature, _maps_seen
    lit = light_objects.signature(scene)
    made = maps.STATS["made"]
    # a new World analysis, a light edit, or a thickness map (made by the viewport's timer once
    # edits settled: it may widen a textured thickness's range, the rows of the film's table)
    if current != _world_key or lit != _lights_signature or made != _maps_seen:
        _world_key, _lights_signature, _maps_seen = current, lit, made
        names = sorted(set(names) | {m.name for m in bpy.data.materials if nodes.find(m.node_tree)[0]})
    lights = light_objects.SceneLights(scene) if names else None  # read once for them all
    unknown = []
    for name in names:
        material = bpy.data.materials.get(name)
        if material is not None:
            try:
                if sync_material(material, scene, wait=False, world=world, lights=lights) == "unknown":
                    unknown.append(name)
            except Exception as exc:  # a timer must never raise
                log.error("Thin Film SH: EEVEE film of %r: %s", name, exc)
    if unknown and linked.baking():  # a linked thickness's Cycles bake: here, not in a draw
        for error in linked.run_pending():
            log.error("Thin Film SH: linked thickness: %s", error)
        with _lock:
            _dirty.update(unknown)  # known now: read again at the next tick
    elif linked.has_pending():  # thickness maps, once edits settled (no viewport may draw them)
        queued = linked.pending_count()
        for error in linked.run_pending():
            log.error("Thin Film SH: thickness map: %s", error)
        if linked.pending_count() < queued:
            _tag_redraw()  # the overlay's batches read the new map at their next frame
    _finish()
    if pending():
        return POLL_S
    return WORLD_POLL_S if any(nodes.find(m.node_tree)[0] for m in bpy.data.materials) else None


def _schedule() -> None:
    if not bpy.app.timers.is_registered(_service):
        bpy.app.timers.register(_service, first_interval=0.0)


@bpy.app.handlers.persistent
def _on_depsgraph(scene, depsgraph) -> None:
    touched = []
    for update in depsgraph.updates:
        found = update.id
        if isinstance(found, bpy.types.Material):
            touched.append(getattr(found, "original", found).name)
        elif isinstance(found, (bpy.types.World, bpy.types.Scene, bpy.types.Light)):
            _schedule()  # the timer compares the World's analysis and the lights with the films' own
        elif isinstance(found, bpy.types.Object):
            if found.type == "LIGHT":
                _schedule()
            elif update.is_updated_transform:  # a film's object moved: its lights' directions
                touched += [s.material.name for s in found.material_slots if s.material is not None]
    if touched:
        with _lock:
            _dirty.update(touched)
        _schedule()


@bpy.app.handlers.persistent
def _on_load(*_args) -> None:
    with _lock:
        _wanted.clear()
        _dirty.clear()
        _done.clear()
    if bpy.app.background:
        _sync_headless()
        return
    with _lock:
        _dirty.update(m.name for m in bpy.data.materials)
    _schedule()


_headless_busy = False  # a headless sync is running: a render it starts (a World panorama) waits


def _sync_headless(inside_render: bool = False) -> None:
    """Sync every film material in place (background mode). ``inside_render`` (``render_pre``):
    nothing that renders itself, a linked thickness's Cycles bake or a procedural World's
    panorama, is started (the World analysed at load is used)."""
    global _headless_busy
    if _headless_busy:
        return  # a render started by the sync itself
    _headless_busy = True
    try:
        scene = bpy.context.scene
        if not inside_render and bpy.context.view_layer is not None:
            bpy.context.view_layer.update()  # objects' matrix_world: a file saved unevaluated has none
        world = world_of(scene, compute=not inside_render) if _has_films(bpy.data.materials) else None
        sync_all(scene, wait=True, defer=inside_render, world=world)
    except Exception as exc:  # a handler must never raise
        log.error("Thin Film SH: EEVEE films not synced: %s", exc)
    finally:
        _headless_busy = False


@bpy.app.handlers.persistent
def _on_render_pre(*_args) -> None:
    if threading.current_thread() is threading.main_thread() and bpy.app.background:
        _sync_headless(inside_render=True)


_HANDLERS = (
    ("depsgraph_update_post", _on_depsgraph),
    ("load_post", _on_load),
    ("render_pre", _on_render_pre),
)


def register() -> None:
    """Add the handlers (repeat calls are harmless)."""
    for name, fn in _HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        if fn not in handlers:
            handlers.append(fn)


def unregister() -> None:
    """Remove the handlers and the timer; the worker ends after its current item."""
    for name, fn in _HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        while fn in handlers:
            handlers.remove(fn)
    if bpy.app.timers.is_registered(_service):
        bpy.app.timers.unregister(_service)
    with _lock:
        _queue.clear()
        _wanted.clear()
        _dirty.clear()
        _done.clear()
