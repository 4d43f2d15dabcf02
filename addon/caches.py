"""Every cache the add-on keeps, in one registry, and the one :func:`clear` that empties them.

A cache is registered by the module that owns it (:func:`register`); :func:`clear` is called
when a blend file is loaded (``viewport``'s load_post handler, ``file_load=True``) and when the
add-on is unregistered (``addon.unregister``). A cache's *scope* says which of the two empties
it: ``FILE`` caches hold what belongs to the open file (object names, GPU objects of its
World) and are emptied on both; ``SESSION`` caches are keyed by content (a hash of everything
their value depends on), stay valid when another file is opened, and are emptied only on
unregister. The bounded ones use :class:`LRU`, the add-on's one least-recently-used type.

The caches (name in the registry — the object; keyed by; bound; filled by; scope):

- ``tables`` — ``tables.MEMORY``: baked SH tables (``bake.BakeResult``) by
  ``description.description_key`` (the material's parameters + the bake planner's version);
  LRU of ``tables.LRU_SIZE`` (32); filled by ``tables.get_table_with_source`` (disk cache or a
  bake; also from the bake operator's worker thread: the LRU is thread-safe); SESSION, also
  emptied by the Clear Cache operator (``tables.clear_caches``) with the disk cache.
- ``film_tables`` — ``tables.FILMS``: the film table (``film_colour.FilmTable``: the reflectance
  the World's lamps and the light objects are shaded with) of a baked table, by description
  key; LRU of ``tables.LRU_SIZE`` (32); filled by ``tables.get_film`` on the viewport bake's
  worker (and inline by a headless frame); SESSION, also emptied by Clear Cache.
- ``bake_failures`` — ``tables.FAILURES``: the error text of failed bakes by description key;
  LRU of ``tables.FAILURE_MEMORY`` (64); filled by ``viewport``'s bake worker, ``scene_draw``'s
  headless bakes and the Bake operator (``tables.record_failure``), emptied of a key when its
  bake succeeds; read by the viewport (no retry until the description changes) and the panel;
  SESSION, also emptied by Clear Cache.
- ``cache_errors`` — ``tables.CACHE_ERRORS``: why a description's table is not in the disk
  cache (an unusable folder, a full disk: the table is in memory and drawn); LRU of
  ``tables.FAILURE_MEMORY`` (64); filled by ``tables.get_table_with_source``; SESSION, also
  emptied by Clear Cache.
- ``material_outputs`` — ``props.OUTPUTS``: what the Bake button found for a material
  (``last_bake_ms``, ``last_plan``, ``last_error``, read through those properties' getters) by
  (material ``session_uid``, name); one entry per material baked (three short values); filled
  by the bake operator; FILE (the file's materials, kept out of the saved file on purpose).
- ``hidden_viewports`` — ``viewport.HIDDEN_IN``: the 3D viewports (their space's address)
  whose Thin Film SH overlay is switched off; a set, one entry per viewport switched off; filled
  by the *Thin Film SH* toggle in the Overlays popover; FILE.
- ``thickness_images`` — ``thickness._PRINTS``: pixel fingerprints of images with unsaved edits
  in a node graph linked into a film's thickness, by image name, refreshed at most every
  ``thickness.IMAGE_RECHECK_S``; LRU of 16; filled by ``thickness.image_stamp``; FILE.
- ``deferred_corners`` — ``corners.CORNERS``: the *Image* source's per-corner parameters (with
  the non-finite count, and a map of the pixels where they hold NaN or ±∞), and the *Blender
  Noise* source's on a mesh of more than ``linked_nodes.INLINE_VERTICES`` vertices, or why there are
  none, by (object name, its evaluated mesh's vertex and corner counts, geometry epoch,
  ``thickness.thickness_inputs``: the UV map and the image's identity, the noise's scale and
  seed); LRU of 16; filled by ``corners.image_parameters`` / ``corners.noise_parameters`` (at
  once in background mode or for a small mesh, else by the viewport's timer through
  ``linked.PENDING``); FILE.
- ``linked_thickness`` — ``linked.FIELDS``: a Principled BSDF's linked Thin Film Thickness
  per face corner (``linked.Field``: nm, how it was obtained) by (object name, its evaluated
  mesh's vertex and corner counts, a geometry epoch bumped on depsgraph geometry updates,
  ``linked.tree_key`` of the linked graph); LRU of 64; filled by ``linked.evaluate`` (direct
  numpy or a Cycles bake, the latter never inside the draw: ``linked.run_pending`` from the
  viewport's timer); FILE.
- ``generated_orco`` — ``generated.ORCOS``: a mesh's evaluated positions without its Deform
  modifiers and shape keys, where building modifiers follow them (its Generated coordinates) by
  ``generated.orco_key`` (the original mesh's name, sizes and a hash of its positions, the
  building modifiers' settings; not the deformation, so an animated rig reuses it); LRU of 16;
  filled by ``generated.evaluate_orco`` (a temporary scene: never inside the draw, queued on
  ``linked.PENDING`` there); FILE. The key itself is kept only for one pass
  (``generated.one_pass``: a ``scene_draw.collect`` or one link's evaluation), so an edit of
  the original mesh is seen at the next.
- ``thickness_maps`` — ``maps.MAPS``: a varying thickness per pixel (``maps.ThicknessMap``:
  nm at a map's texel centres over one UV map, or None and why not) by the key of the field it
  belongs to (a linked thickness's); LRU of 16 (a 1024² map is
  4 MB); filled by ``maps.field_map``: at once in background mode, else by the viewport's
  timer once the edits have settled (``maps.SETTLE_S``); FILE.
- ``world_sh`` — ``world.SH_CACHE``: the World's SH radiance (``world.WorldSH``) by
  ``world_key.world_key`` (the World's node tree, image files' path/size/mtime, l_max, working
  space); LRU of ``world.DEFAULT_CACHE_SIZE`` (16); filled by ``world.world_sh``; SESSION.
- ``eevee_moments`` — ``eevee.sync.MOMENTS``: a World's GGX prefilter with moments at 256
  texels across (``precompute.world.prefilter.Prefiltered``), for the EEVEE films' dominant-direction
  images when the overlay has not computed its own, by the id of the World's analysed
  ``Environment`` (kept with it, checked by identity); LRU of 2; filled by ``eevee.sync.compute``
  on its worker (or inline headless); FILE.
- ``plans`` — ``ui._PLANS``: the Plan panel's ``effects.MaterialPlan`` by description key; LRU
  of ``ui._PLAN_MEMO_SIZE`` (64); filled by ``ui.plan_for``; SESSION.
- ``plan_orders_seen`` — ``ui._ORDERS_SEEN``: roughness values whose automatic SH order has been
  planned (every roughness plans at once now: the order comes from a table); a set, one entry per
  roughness planned (a few floats); filled by ``ui.plan_for``; SESSION.
- ``scene_draw`` — ``scene_draw.CACHES``: what the draw collects per object and material:
  mesh batches (``scene_draw.BatchEntry``) by (object name, material slot, instance), rebuilt
  when the geometry or the thickness's inputs change; GPU table textures and film textures by
  description key; the entry each material (by ``session_uid``) was last drawn with, drawn
  again while its new table bakes (``scene_draw.Caches.previous``, LRU of ``TABLE_CACHE_SIZE``);
  lighting uniform buffers by (World lighting key, l_max, roughness, lamps), those of another
  World lighting dropped when it changes; LRUs of ``scene_draw.BATCH_CACHE_SIZE`` (256),
  ``TABLE_CACHE_SIZE`` and ``FILM_CACHE_SIZE`` (32, as ``tables.LRU_SIZE``) and
  ``LIGHTING_CACHE_SIZE`` (64) entries, or what the last frame used if more (so a long session
  of edits cannot grow them, and a large frame does not rebuild every frame); filled by
  ``scene_draw.collect``; FILE.
- ``world_lighting`` — ``world_state.STATE``: the World's lighting for the draw, the world
  room's state: the current World's lighting (``world_analysis.WorldLighting``: its SH, the
  analysed panorama, the prefilters on the GPU) for the current World key only; the analysed
  World contents (``world_analysis.Analysed``: SH, panorama, lamps, prefilter arrays) by
  ``world_params.world_parts``' content key, an LRU of ``world_state.CONTENT_CACHE_SIZE`` (3), filled
  by ``world_job``'s worker (the LRU is thread-safe; a result for a file loaded since is
  dropped by ``WorldState.generation``) and by ``world_state.world_lighting`` in headless
  renders; what the draw asked for (a content to analyse, prefilters to compute); FILE.
- ``radiance_grids`` — ``radiance_grids.GRIDS``: constant-thickness films' outgoing-radiance
  grids on the GPU (``gpu.resources.RadianceGridTexture``, 4.5–9 MiB each) by (description key,
  World key, l_max, roughness, lamps), with the worker's queue (at most
  ``radiance_grids.QUEUE_SIZE``, newest first) and its built grids awaiting upload; LRU of
  ``radiance_grids.GRID_CACHE_SIZE`` (8), and varying films' basis grids (80 MiB each, by World
  content and roughness) apart, an LRU of ``radiance_grids.BASIS_CACHE_SIZE`` (2); filled by
  ``scene_draw.collect`` through
  ``radiance_grids.grid_for`` (built on a worker thread; headless frames build in place); FILE.
- ``shaders`` — ``gpu.shaders.SHADERS``: compiled GPU shaders by variant; one per variant used
  (a few dozen at most); filled by ``gpu.draw.draw_items``; SESSION (registered by
  ``scene_draw``: the GPU layer keeps no registry).
- ``uniforms`` — ``gpu.draw.UNIFORMS``: view and object uniform buffers by the values they are
  made from; entries unused for ``keep_frames`` frames are recycled (at most ``max_spare``
  spare buffers per size); filled by ``gpu.draw.prepare_draw``; SESSION (registered by
  ``scene_draw``).
- ``fullscreen_triangle`` — ``gpu.draw.FULLSCREEN_TRIANGLE``: the ``functools.cache`` memo of the
  full-screen triangle batch (one); filled by the background and test draws; SESSION (registered
  by ``scene_draw``): a GPU batch left to interpreter exit is freed after Blender and crashes it.

- ``display_luts`` — ``display.LUTS``: the viewport's display LUT (N³ RGB, the scene's view,
  look, display and gamma baked through OCIO) by ``display.DisplaySettings`` without exposure;
  LRU of 8; filled by ``display.baked_lut`` (on a background thread for the viewport); SESSION.
- ``display_lut_textures`` — ``display.TEXTURES``: those LUTs on the GPU, same key; LRU of 4;
  filled by ``display.viewport_lut`` in the draw; FILE.

Not registered, because they never go stale: ``functools.cache`` memos of values computed from
the code alone (the parsed GLSL chunks of ``gpu.shaders``, ``banded_source``,
``x_rotation_scalars``) and the bounded
``functools.lru_cache`` kernels inside ``precompute``.
"""

from __future__ import annotations

import collections
import threading
from dataclasses import dataclass

__all__ = ["FILE", "LRU", "SESSION", "Registered", "clear", "register", "registered"]

#: Scope of a cache emptied whenever a blend file is loaded (and on unregister).
FILE = "file"
#: Scope of a content-keyed cache, valid across files: emptied on unregister only.
SESSION = "session"


class LRU:
    """A thread-safe least-recently-used mapping of at most ``maxsize`` entries.

    ``get``, ``[]``, ``[]=``, ``pop``, ``in``, ``len``, ``items`` (a snapshot) and ``clear``;
    reading an entry (``get`` or ``[]``) makes it the most recent, storing one beyond ``maxsize``
    drops the least recent. :meth:`resize` changes the bound (dropping the least recent entries
    at once when it shrinks). A dropped value is only dereferenced: GPU objects in it are freed
    when nothing else holds them.
    """

    def __init__(self, maxsize: int):
        if maxsize < 1:
            raise ValueError(f"maxsize must be ≥ 1, got {maxsize}")
        self.maxsize = int(maxsize)
        self._data: collections.OrderedDict = collections.OrderedDict()
        self._lock = threading.RLock()

    def get(self, key, default=None):
        """Value for *key*, marked most recently used; *default* when absent."""
        with self._lock:
            if key not in self._data:
                return default
            self._data.move_to_end(key)
            return self._data[key]

    def __getitem__(self, key):
        with self._lock:
            value = self._data[key]
            self._data.move_to_end(key)
            return value

    def __setitem__(self, key, value):
        with self._lock:
            self._data[key] = value
            self._data.move_to_end(key)
            while len(self._data) > self.maxsize:
                self._data.popitem(last=False)

    def pop(self, key, default=None):
        """Remove *key* and return its value, or *default* when absent."""
        with self._lock:
            return self._data.pop(key, default)

    def __contains__(self, key):
        with self._lock:
            return key in self._data

    def items(self) -> list:
        """(key, value) pairs, least recent first (a copy: safe to iterate while others store)."""
        with self._lock:
            return list(self._data.items())

    def resize(self, maxsize: int) -> None:
        """Bound the mapping to ``maxsize`` (≥ 1) entries, dropping the least recent beyond it."""
        if maxsize < 1:
            raise ValueError(f"maxsize must be ≥ 1, got {maxsize}")
        with self._lock:
            self.maxsize = int(maxsize)
            while len(self._data) > self.maxsize:
                self._data.popitem(last=False)

    def __len__(self):
        with self._lock:
            return len(self._data)

    def clear(self) -> None:
        """Drop every entry (the size limit stays)."""
        with self._lock:
            self._data.clear()


@dataclass(frozen=True)
class Registered:
    """One registered cache: its ``name``, the object (anything with ``clear()``), its scope."""

    name: str
    cache: object
    scope: str


_REGISTRY: dict[str, Registered] = {}


def register(name: str, cache, *, scope: str):
    """Add ``cache`` (anything with ``clear()``) to the registry under ``name``; returns it.

    ``scope`` is :data:`FILE` or :data:`SESSION` (see the module docstring, which must describe
    every name). Registering a name again replaces the entry (a reloaded module's new object).
    """
    if scope not in (FILE, SESSION):
        raise ValueError(f"scope must be {FILE!r} or {SESSION!r}, got {scope!r}")
    if not callable(getattr(cache, "clear", None)):
        raise TypeError(f"cache {name!r} has no clear()")
    _REGISTRY[name] = Registered(name, cache, scope)
    return cache


def registered() -> dict[str, Registered]:
    """Name → :class:`Registered`, in registration order."""
    return dict(_REGISTRY)


def clear(*, file_load: bool = False) -> None:
    """Empty the caches: after a file load (``file_load``) the FILE ones, otherwise all."""
    for entry in _REGISTRY.values():
        if entry.scope == FILE or not file_load:
            entry.cache.clear()
