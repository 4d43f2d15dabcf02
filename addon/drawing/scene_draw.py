"""What to draw: visible objects with a thin-film material → GPU draw items, with caches.

Shared by the viewport draw handler and the headless render, so both draw the same thing.

:data:`CACHES` (registered in :mod:`.caches` as ``scene_draw``, emptied on file load) holds:

- batches per (object, material slot, instance) (:class:`BatchEntry`), rebuilt only when the
  object's geometry changed (a depsgraph handler marks it) or what its thickness is made of
  changed (:func:`.thickness.thickness_inputs`: the source, noise scale and seed, attribute
  name, image and its pixels) — moving an object only changes the matrix passed at draw time;
- GPU table textures per material description key (equal materials share one);
- lighting UBOs per (World key, SH order, roughness, lamps or not);
- film textures (the reflectance table of the World's lamps and the light objects) per material
  description key, uploaded from the film table the bake's worker computed
  (:func:`.tables.get_film`): never computed in a draw;
- per material (its ``session_uid``) the entry it was last drawn with (:attr:`Caches.previous`):
  while the material's new table bakes, the draw shows that one instead of nothing — a frame is
  always drawn with the best data available.

The World's lighting is the world room's (:mod:`..world.world_state`): read through
:func:`.world_state.world_lighting` and :func:`.world_state.prefilter`.

The four GPU maps are :class:`.caches.LRU` s bounded by :data:`BATCH_CACHE_SIZE`,
:data:`TABLE_CACHE_SIZE`, :data:`FILM_CACHE_SIZE` and :data:`LIGHTING_CACHE_SIZE` entries, or by
what the last frame used when that is more (a map grows rather than drop an entry the frame
already uses, :meth:`Caches.make_room`, and shrinks back after the frame, :meth:`Caches.fit`;
so a large scene does not rebuild every frame): a long session of edits, each making new keys,
keeps at most that many. A dropped entry is only dereferenced; its GPU buffers and textures are
freed with the last reference (the draw items of the frame being drawn).

The GPU layer's shader and uniform-buffer caches (``gpu.shaders.SHADERS``, ``gpu.draw.UNIFORMS``)
are registered in :mod:`.caches` here too.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass, field

import bpy
import numpy as np

from ...precompute.materials.material import FALLBACK
from ...precompute.shading import policy
from ...precompute.shading.transmit import WALL_SOLID
from .. import caches
from ..bakes import bake_asks, bake_jobs, radiance_grids, tables
from ..bakes.bake_asks import material_identity
from ..gpu import draw, layout, resources, shaders
from ..gpu.mesh import MeshBatch
from ..materials import description, transparency
from ..thickness import generated, linked
from ..world import world_state
from ..world.world_analysis import WorldLighting
from . import batches
from . import lights as scene_lights

log = logging.getLogger(__name__)


@dataclass
class DrawItem:
    """One (object, material slot) to draw: what :func:`.gpu.draw.draw_items` needs."""

    batch: MeshBatch
    model_matrix: np.ndarray
    table: resources.TableTexture
    lighting: resources.Lighting
    name: str
    prefiltered: resources.PrefilterTexture | None = None
    roughness: float = 0.0
    sh_weight: float = 1.0
    film: resources.FilmTexture | None = None
    #: Drawn as :data:`precompute.materials.material.FALLBACK` (matte magenta): its material failed.
    fallback: bool = False
    #: Blender's light objects this object receives (:func:`.gpu.resources.lights_content`), or None.
    lights: np.ndarray | None = None
    #: A transparent film's wall, (mode, η) of precompute.shading.transmit (:func:`.transparency.wall`).
    wall: tuple | None = None
    #: The film's outgoing-radiance grid (:mod:`.radiance_grids`), or None (per-pixel SH).
    grid: resources.RadianceGridTexture | None = None
    #: Its grid is being built: the per-pixel variant is drawn only if compiled (else the
    #: stand-in, and it is not asked for: 77–83 s of llvmpipe compile for a frame or two).
    grid_pending: bool = False


#: Batches kept besides those the last frame drew (each holds a mesh's vertex buffers).
BATCH_CACHE_SIZE = 256
#: GPU table textures kept: as many as the tables kept in memory (tables.LRU_SIZE, 32).
TABLE_CACHE_SIZE = tables.LRU_SIZE
#: Film textures (the lamps' reflectance) kept, one per table.
FILM_CACHE_SIZE = tables.LRU_SIZE
#: Lighting uniform buffers kept (a roughness slider's drag makes one per step).
LIGHTING_CACHE_SIZE = 64


def _lru(size: int) -> caches.LRU:
    return caches.LRU(size)


@dataclass
class Caches:
    """The draw collector's GPU-side caches, each a bounded LRU."""

    batches: caches.LRU = field(
        default_factory=lambda: _lru(BATCH_CACHE_SIZE)
    )  # (object, slot, instance) → BatchEntry
    tables: caches.LRU = field(
        default_factory=lambda: _lru(TABLE_CACHE_SIZE)
    )  # description key → TableTexture
    films: caches.LRU = field(default_factory=lambda: _lru(FILM_CACHE_SIZE))  # description key → FilmTexture
    lightings: caches.LRU = field(
        default_factory=lambda: _lru(LIGHTING_CACHE_SIZE)
    )  # (world key, l_max, roughness, lamps) → Lighting
    previous: caches.LRU = field(
        default_factory=lambda: _lru(TABLE_CACHE_SIZE)
    )  # material session_uid → the _MaterialEntry it was last drawn with
    lighting_key: str | None = None  # the World lighting the lighting buffers were made for
    dirty: set = field(default_factory=set)  # object names whose geometry changed
    stats: dict = field(default_factory=lambda: {"batch_builds": 0, "table_uploads": 0})

    def clear(self):
        """Empty every cache and restore its size limit."""
        for lru, size in self._bounded():
            lru.clear()
            lru.resize(size)
        self.lighting_key = None
        self.dirty.clear()

    def _bounded(self):
        return (
            (self.batches, BATCH_CACHE_SIZE),
            (self.tables, TABLE_CACHE_SIZE),
            (self.films, FILM_CACHE_SIZE),
            (self.lightings, LIGHTING_CACHE_SIZE),
            (self.previous, TABLE_CACHE_SIZE),
        )

    def make_room(self, batches: int = 0, materials: int = 0) -> None:
        """Before storing the frame's ``batches``-th batch or ``materials``-th material: grow a
        map that would otherwise drop an entry this frame already uses."""
        for lru, needed in (
            (self.batches, batches),
            (self.tables, materials),
            (self.films, materials),
            (self.lightings, materials),
            (self.previous, materials),
        ):
            if lru.maxsize < needed:
                lru.resize(needed)

    def fit(self, batches: int, materials: int) -> None:
        """Bound the GPU maps after a frame that used ``batches`` batches and ``materials``
        materials: the base sizes, or the frame's own use when it is larger."""
        self.batches.resize(max(BATCH_CACHE_SIZE, batches))
        self.tables.resize(max(TABLE_CACHE_SIZE, materials))
        self.films.resize(max(FILM_CACHE_SIZE, materials))
        self.lightings.resize(max(LIGHTING_CACHE_SIZE, materials))
        self.previous.resize(max(TABLE_CACHE_SIZE, materials))


CACHES = caches.register("scene_draw", Caches(), scope=caches.FILE)
caches.register("shaders", shaders.SHADERS, scope=caches.SESSION)
caches.register("uniforms", draw.UNIFORMS, scope=caches.SESSION)
caches.register("fullscreen_triangle", draw.FULLSCREEN_TRIANGLE, scope=caches.SESSION)


def on_depsgraph_update(scene, depsgraph) -> None:
    """Mark objects whose geometry changed (transform-only updates keep their batch).

    Material updates mark nothing: what a batch takes from its material (the thickness source,
    noise, image) is part of the batch's signature (:func:`.thickness.thickness_inputs`), read
    from the material itself each frame, so any other material edit (dragging the roughness)
    rebuilds no batch.
    """
    for update in depsgraph.updates:
        data = update.id
        if isinstance(data, bpy.types.Object) and update.is_updated_geometry:
            name = data.original.name if hasattr(data, "original") else data.name
            CACHES.dirty.add(name)
            linked.mark_geometry(name)
        elif isinstance(data, bpy.types.Mesh) and update.is_updated_geometry:
            for obj in scene.objects:
                if obj.data is not None and obj.data.name == data.name:
                    CACHES.dirty.add(obj.name)
                    linked.mark_geometry(obj.name)


def _keep_lightings_of(key: str) -> None:
    """A new World lighting (``key``): the lighting buffers made for any other are dropped."""
    if CACHES.lighting_key != key:
        for stale in [k for k, _ in CACHES.lightings.items() if k[0] != key]:
            CACHES.lightings.pop(stale)
        CACHES.lighting_key = key


def lighting_for(
    lighting: WorldLighting, l_max: int, roughness: float, lamps: bool = False
) -> resources.Lighting:
    """The lighting UBO; with ``lamps`` (and a World that has some) the SH without the lamps and
    the lamps themselves. The World's rotation and strength are in it for the prefilter lookup."""
    env = lighting.environment
    lamps = bool(lamps and env is not None and env.lamps is not None)
    key = (lighting.key, int(l_max), round(float(roughness), 6), lamps)
    found = CACHES.lightings.get(key)
    if found is None:
        coeffs = lighting.sh_without_lamps() if lamps else np.asarray(lighting.sh.coeffs, dtype=np.float64)
        found = resources.Lighting.from_sh(
            coeffs,
            l_max,
            roughness,
            lighting.lamps() if lamps else None,
            lighting.matrix,
            1.0 if lighting.scale is None else lighting.scale,
        )
        CACHES.lightings[key] = found
    return found


def film_texture(desc_key: str, film=None) -> resources.FilmTexture | None:
    """The film colour texture of a description key, uploaded once: from ``film`` (a
    :class:`precompute.colour.film_colour.FilmTable`) or the one the bake's worker computed
    (:func:`.tables.peek_film`); None while neither exists (it is never computed here)."""
    found = CACHES.films.get(desc_key)
    if found is None:
        film = film if film is not None else tables.peek_film(desc_key)
        if film is None:
            return None
        found = resources.FilmTexture.from_film(film)
        CACHES.films[desc_key] = found
    return found


def _film_for(desc, key: str, result, allow_bake: bool, bake_later: bool, owner):
    """The film texture of the table ``result``: uploaded from the film table in memory, computed
    here only for a headless frame (``allow_bake``); in the viewport (``bake_later``) asked of
    the bake's worker (:func:`.bake_jobs.want` with ``film``) and meanwhile the material's
    previous film, or None."""
    found = film_texture(key)
    if found is None and allow_bake:
        found = film_texture(key, tables.get_film(desc, result))
    if found is None:
        if bake_later:
            bake_jobs.want(desc, owner=owner, film=True)
        last = CACHES.previous.get(owner)
        found = last.film if last is not None else None
    return found


def uses_lamps(bpy_material, desc) -> bool:
    """Whether the World's lamps are shaded per light direction for this material: its
    "World Lamps" setting (on by default, also for Principled previews), and not under a
    diffuse base, whose lamp light the analytic specular lobe does not carry (it keeps the
    whole World in its SH and prefilter)."""
    props = getattr(bpy_material, "thinfilm_sh", None)
    return bool(getattr(props, "world_lamps", True)) and getattr(desc, "base_color", None) is None


def table_texture(desc_key: str, result) -> resources.TableTexture:
    """The SH table texture for a baked table, uploaded once per description key."""
    found = CACHES.tables.get(desc_key)
    if found is None:
        found = resources.TableTexture.from_result(result)
        CACHES.tables[desc_key] = found
        CACHES.stats["table_uploads"] += 1
    return found


@dataclass
class _MaterialEntry:
    """What one material contributes to a frame, worked out once per frame however many use it."""

    desc: object  # precompute Material
    key: str  # description.description_key(desc)
    table: resources.TableTexture
    lighting: resources.Lighting
    roughness: float
    sh_weight: float
    film: resources.FilmTexture | None = None
    props: object = None  # the original material's thinfilm_sh settings when enabled, else None
    thickness_key: object = None  # thickness.thickness_inputs(props): part of the batches' signature
    linked_source: tuple | None = None  # (material, linked Thin Film Thickness socket) or None
    fallback: bool = False  # drawn as precompute.materials.material.FALLBACK (its material failed)
    lamps: bool = False  # the World's lamps shaded per direction (the prefilter without them)
    sh_order: int = 0  # the table's SH order (the lighting's l_max)
    wall: tuple | None = None  # a transparent film's (mode, η) (transparency.wall)
    grid: resources.RadianceGridTexture | None = None  # its SH half tabulated (policy.uses_grid)
    grid_source: str = ""  # the World content's key the grid was built from (WorldLighting.grid_source)
    grid_wanted: bool = False  # radiance_grids.applies: drawn from a grid once built


def _table_of(desc, allow_bake: bool, bake_later: bool):
    """The baked table of ``desc``: in memory, else baked (``allow_bake``) or asked for
    (``bake_later``)."""
    result = tables.peek_table(desc)
    if result is None and allow_bake:
        result = tables.get_table(desc)
    elif result is None and bake_later:
        bake_jobs.want(desc)
    return result


def _fallback_entry(bpy_material, why: str, lighting, allow_bake, bake_later, messages, errors):
    """Report why ``bpy_material`` cannot be drawn and draw it as FALLBACK (matte magenta)."""
    messages.append(f"{why}: drawn in magenta (the fallback) until it is fixed")
    if errors is not None:
        errors[bpy_material.name] = why
    result = _table_of(FALLBACK, allow_bake, bake_later)
    if result is None:
        return None
    key = description.description_key(FALLBACK)
    roughness = float(FALLBACK.roughness)
    return _MaterialEntry(
        FALLBACK,
        key,
        table_texture(key, result),
        lighting_for(lighting, result.sh_order, roughness, False),
        roughness,
        policy.sh_weight(roughness),
        fallback=True,
        sh_order=result.sh_order,
    )


def _material_entry(
    bpy_material, lighting: WorldLighting, allow_bake: bool, bake_later, messages, errors=None, lights=False
):
    """The material's description, table texture and lighting, or None (no film / not baked yet
    and never drawn before / its bake failed in the viewport).

    Invalid settings are reported in ``messages`` (and ``errors``, by material name) and the
    material is drawn as the fallback (matte magenta). A bake that failed is remembered by
    description key (:func:`.tables.failure`): it is not tried again, here or by the bake queue,
    until the description changes, and its error is in ``messages`` (and ``errors``) on every
    frame; a headless frame (``allow_bake``) draws it as the fallback, the viewport draws
    nothing for it (its header and material panel say why). A table that could not be saved to
    the disk cache is drawn, with the reason in ``messages``. ``lights``: the frame has light
    objects, so the film table is needed even without the World's lamps.

    In the viewport (``bake_later``) a table not in memory is asked of the bake queue
    (:func:`.bake_asks.ask`, for ``owner``: :func:`material_identity`, so a newer value
    replaces the older request) and the
    entry the material was last drawn with is drawn meanwhile (:func:`_previous_entry`), as it is
    while a linked thickness's Cycles bake is queued (:func:`.description.described`).
    """
    try:
        desc, pending = description.described(bpy_material)
    except ValueError as exc:  # description() names the material and the parameter
        return _fallback_entry(bpy_material, str(exc), lighting, allow_bake, bake_later, messages, errors)
    owner = material_identity(bpy_material)
    if desc is None:  # a linked thickness being baked: the material as last drawn meanwhile
        return _previous_entry(owner, lighting) if pending else None
    name = bpy_material.name
    key = description.description_key(desc)  # ≈ 1 ms: once per material per frame
    result = tables.MEMORY.get(key)  # tables.peek_table, by the key at hand
    if result is None:
        failed = tables.FAILURES.get(key)  # tables.failure
        if failed is None and allow_bake:
            try:
                result = tables.get_table(desc)
            except Exception as exc:  # one material's failure must not stop the others
                tables.record_failure(desc, exc)
                failed = tables.bake_failure(name, exc)  # a bug's traceback goes to a log file
        if failed is not None:
            why = f"material {name!r}: bake failed: {failed} (not retried until it changes)"
            if allow_bake:
                return _fallback_entry(bpy_material, why, lighting, allow_bake, bake_later, messages, errors)
            messages.append(why)
            if errors is not None:
                errors[name] = why
            return None
        if result is None:
            if bake_later:
                film = _needs_film(bpy_material, desc, lighting, lights)
                bake_asks.ask(desc, owner, CACHES.previous.get(owner), lighting, film)
            return _previous_entry(owner, lighting)
    problem = tables.CACHE_ERRORS.get(key)  # tables.cache_error
    if problem is not None:
        messages.append(f"material {name!r}: {problem}")
    entry = _fresh_entry(bpy_material, desc, key, result, lighting, lights, allow_bake, bake_later)
    CACHES.previous[owner] = entry
    return entry


def _needs_film(bpy_material, desc, lighting: WorldLighting, lights: bool) -> bool:
    """Whether the material's draw reads its film table: the World's lamps shaded per direction
    for it, or light objects in the frame."""
    env = lighting.environment
    return bool(lights or (uses_lamps(bpy_material, desc) and env is not None and env.lamps is not None))


def _fresh_entry(bpy_material, desc, key: str, result, lighting, lights, allow_bake, bake_later):
    """The entry of a material whose table ``result`` is in memory. Without its film table yet
    (being computed on the bake's worker) it draws the previous film, else folds the World's
    lamps back into the SH and prefilter (their light is kept, only not per direction)."""
    roughness = float(desc.roughness)
    owner = material_identity(bpy_material)
    wall = transparency.wall(bpy_material, desc)
    film = None
    diffuse = getattr(desc, "base_color", None) is not None
    lobe = policy.uses_lobe_grid(roughness, diffuse, wall is not None)  # reads the film table too
    if wall is not None or lobe or _needs_film(bpy_material, desc, lighting, lights):
        film = _film_for(desc, key, result, allow_bake, bake_later, owner)
    env = lighting.environment
    lamps = film is not None and uses_lamps(bpy_material, desc) and env is not None and env.lamps is not None
    props = getattr(bpy_material, "thinfilm_sh", None)
    props = props if props is not None and props.enabled else None
    thickness_key, linked_source = batches.thickness_source(bpy_material, props, desc)
    buffer = lighting_for(lighting, result.sh_order, roughness, lamps)
    film_table = tables.peek_film(key) if film is not None and lobe else None
    grid, lobe = radiance_grids.film_grid(key, desc, result, lighting, lamps, film_table, wait=allow_bake)
    return _MaterialEntry(
        desc,
        key,
        table_texture(key, result),
        buffer,
        roughness,
        policy.grid_weight(roughness, lobe and grid is not None),
        film,
        props,
        thickness_key,
        linked_source,
        lamps=lamps,
        sh_order=result.sh_order,
        wall=wall,
        grid=grid,
        grid_source=lighting.grid_source(lamps)[0],
        grid_wanted=radiance_grids.applies(desc, result, lighting, film_table is not None),
    )


def _previous_entry(owner, lighting: WorldLighting):
    """The entry the material ``owner`` was last drawn with, lit by the current World, or None
    (never drawn yet): what the viewport draws while the material's new table bakes."""
    last = CACHES.previous.get(owner)
    if last is None:
        return None
    env = lighting.environment
    lamps = last.lamps and env is not None and env.lamps is not None
    buffer = lighting_for(lighting, last.sh_order, last.roughness, lamps)
    # a grid holds the World's content it was built from (its strength and turn are the buffer's)
    grid = last.grid if lighting.grid_source(lamps)[0] == last.grid_source else None
    weight = last.sh_weight if grid is not None else policy.sh_weight(last.roughness)  # no grid: its weight
    return dataclasses.replace(last, lighting=buffer, lamps=lamps, grid=grid, sh_weight=weight)


def _prefiltered_for(lighting: WorldLighting, entry, compute: bool = True):
    """The prefilter the entry's draw reads, computed on first use; None when it reads none.

    With ``compute`` False (the draw callback) a prefilter not computed yet is asked of a worker
    (:func:`.world_state.prefilter`) and None is returned: the film draws from the SH until it
    is ready.

    Only the split sum reads a prefilter, and only below an SH weight of 1
    (variant.choose_variant): rough films draw from the SH alone and get none, so a scene of
    rough films computes no prefilter at all. A lamp-shaded film reads the prefilter with the
    lamps lifted out, any other the whole World's.
    """
    if lighting.textures is None or entry.sh_weight >= 1.0:
        return None
    # the World's lamps shaded per direction: the prefilter without them
    return world_state.prefilter(lighting, entry.lamps, compute)


@generated.one_pass()  # an object's orco key hashed once per collect
def collect(
    depsgraph, *, allow_bake: bool = True, allow_world: bool = True, bake_later: bool = False, errors=None
):
    """Draw items for every visible mesh object with a thin-film material, and messages.

    With ``allow_bake`` False (the draw callback), materials whose table is not in memory are
    drawn with the table they were last drawn with (skipped if there is none); with
    ``bake_later`` (the viewport's draw) they are also asked of the bakes room
    (:func:`.bake_asks.ask`: its queue bakes them outside drawing, :mod:`.bake_jobs`).

    A material that cannot be evaluated is drawn as :data:`precompute.materials.material.FALLBACK` (matte
    magenta, its items' ``fallback`` set), with a message naming it and the parameter; with an
    ``errors`` dict it is also recorded there as {material name: why}. The World's errors
    (``WorldLighting.sh.errors``) join the messages: it is lit by its fallback colour.

    Per frame, each material's description, table and lighting are worked out once
    (:func:`_material_entry`), not once per object using it; per object only the batch cache
    is checked (a few lengths, no mesh data read) and the matrix copied, so the work does not
    depend on the triangle count.
    """
    messages: list[str] = []
    items: list[DrawItem] = []
    scene = depsgraph.scene
    lighting = world_state.world_lighting(scene, allow_compute=allow_world)
    if lighting is None:
        return items, ["World lighting is being updated"]
    _keep_lightings_of(lighting.key)
    messages.extend(lighting.sh.warnings)
    messages.extend(lighting.sh.errors)
    found_lights = scene_lights.scene_lights(depsgraph)  # every frame: moving a light bakes nothing
    if len(found_lights) > layout.MAX_LIGHTS:
        messages.append(f"{len(found_lights)} lights: the first {layout.MAX_LIGHTS} light the films")
    linked = any(receivers is not None for _, receivers in found_lights)
    shared_lights = None if linked else resources.lights_content(scene_lights.lights_for(found_lights, ""))
    object_lights: dict = {}  # object name → lights content (light linking)
    entries: dict[int, _MaterialEntry | None] = {}  # material pointer → this frame's entry
    seen = set()
    used = set()  # this frame's batch keys
    for inst in depsgraph.object_instances:
        obj_eval = inst.object
        if obj_eval.type != "MESH":  # the depsgraph lists only what is visible in this view layer
            continue
        original = obj_eval.original
        for slot_index, slot in enumerate(obj_eval.material_slots):
            bpy_material = slot.material
            if bpy_material is None:
                continue
            source = bpy_material.original if hasattr(bpy_material, "original") else bpy_material
            pointer = source.as_pointer()
            if pointer not in entries:
                CACHES.make_room(materials=len(entries) + 1)
                entries[pointer] = _material_entry(
                    source, lighting, allow_bake, bake_later, messages, errors, lights=bool(found_lights)
                )
            entry = entries[pointer]
            if entry is None:
                continue
            key = (original.name, slot_index, inst.is_instance and inst.persistent_id[0])
            mesh = obj_eval.data
            thin_wall = entry.wall is not None and int(entry.wall[0]) != WALL_SOLID  # may have an inside
            signature = (
                mesh.name,
                len(mesh.vertices),
                len(mesh.loops),
                entry.desc.varies,
                entry.thickness_key,
                thin_wall,
            )
            cached = CACHES.batches.get(key)
            if cached is None or cached.signature != signature or original.name in CACHES.dirty:
                CACHES.make_room(batches=len(used | {key}))
                cached = batches.slot_batch(
                    original.name,
                    obj_eval,
                    mesh,
                    slot_index,
                    entry.props,
                    entry.desc,
                    signature,
                    entry.linked_source,
                    wall=thin_wall,
                )
                CACHES.batches[key] = cached
                CACHES.stats["batch_builds"] += cached.batch is not None
                seen.add(original.name)
            used.add(key)
            messages.extend(cached.notes)
            batch = cached.batch
            if batch is None:
                messages.append(
                    f"{original.name}: no faces with material '{bpy_material.name}': nothing to draw"
                )
                continue
            if linked and original.name not in object_lights:
                object_lights[original.name] = resources.lights_content(
                    scene_lights.lights_for(found_lights, original.name)
                )
            items.append(
                DrawItem(
                    batch,
                    np.array(inst.matrix_world, dtype=np.float64),
                    entry.table,
                    entry.lighting,
                    f"{original.name}/{bpy_material.name}",
                    prefiltered=_prefiltered_for(lighting, entry, allow_world),
                    roughness=entry.roughness,
                    sh_weight=entry.sh_weight,
                    film=entry.film,
                    fallback=entry.fallback,
                    lights=object_lights[original.name] if linked else shared_lights,
                    wall=entry.wall,
                    grid=entry.grid,
                    grid_pending=entry.grid_wanted and entry.grid is None,
                )
            )
    CACHES.dirty -= seen
    CACHES.fit(len(used), sum(entry is not None for entry in entries.values()))
    return items, messages


def batch_entry(object_name: str, slot: int = 0, instance=False) -> batches.BatchEntry | None:
    """The cached batch of an object's material slot as the last :func:`collect` built it."""
    return CACHES.batches.get((object_name, slot, instance))


def object_notes(object_name: str) -> list[str]:
    """What the last builds of ``object_name``'s batches found wrong (for the panel)."""
    return [note for key, entry in CACHES.batches.items() if key[0] == object_name for note in entry.notes]
