"""What to draw: visible objects with a thin-film material → GPU draw items, with caches.

Shared by the viewport draw handler and the headless render, so both draw the same thing.

:data:`CACHES` (registered in :mod:`.caches` as ``scene_draw``, emptied on file load) holds:

- batches per (object, material slot), rebuilt only when the object's geometry changed
  (a depsgraph handler marks it) — moving an object only changes the matrix passed at draw time;
- GPU table textures per material description key (equal materials share one);
- lighting UBOs per (World key, SH order, roughness, lamps or not);
- film textures (the lamps' reflectance table) per material description key;
- the World's lighting (:class:`WorldLighting`: SH, analysed panorama, prefilter textures) for
  the current World key.

gpu_draw's shader and uniform-buffer caches are registered in :mod:`.caches` here too.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import bpy
import numpy as np

from ..precompute import film_colour, prefilter
from ..precompute.environment import Environment, analyse_world
from ..precompute.shading import policy
from . import caches, description, gpu_draw, panorama, tables, world, world_key
from .thickness import thickness_per_vertex

log = logging.getLogger(__name__)


@dataclass
class DrawItem:
    """One (object, material slot) to draw: what :func:`gpu_draw.draw_items` needs."""

    batch: gpu_draw.MeshBatch
    model_matrix: np.ndarray
    table: gpu_draw.TableTexture
    lighting: gpu_draw.Lighting
    name: str
    prefiltered: gpu_draw.PrefilterTexture | None = None
    roughness: float = 0.0
    sh_weight: float = 1.0
    film: gpu_draw.FilmTexture | None = None


@dataclass
class Caches:
    batches: dict = field(default_factory=dict)  # (object name, slot) → (signature, MeshBatch | None)
    tables: dict = field(default_factory=dict)  # description key → TableTexture
    films: dict = field(default_factory=dict)  # description key → FilmTexture (lamps)
    lightings: dict = field(default_factory=dict)  # (world key, l_max, roughness, lamps) → Lighting
    world: WorldLighting | None = None  # the current World's lighting
    dirty: set = field(default_factory=set)  # object names whose geometry changed
    stats: dict = field(default_factory=lambda: {"batch_builds": 0, "table_uploads": 0})

    def clear(self):
        self.batches.clear()
        self.tables.clear()
        self.films.clear()
        self.lightings.clear()
        self.world = None
        self.dirty.clear()


CACHES = caches.register("scene_draw", Caches(), scope=caches.FILE)
caches.register("shaders", gpu_draw.SHADERS, scope=caches.SESSION)
caches.register("uniforms", gpu_draw.UNIFORMS, scope=caches.SESSION)


def on_depsgraph_update(scene, depsgraph) -> None:
    """Mark objects whose geometry changed (transform-only updates keep their batch)."""
    for update in depsgraph.updates:
        data = update.id
        if isinstance(data, bpy.types.Object) and update.is_updated_geometry:
            CACHES.dirty.add(data.original.name if hasattr(data, "original") else data.name)
        elif isinstance(data, bpy.types.Mesh):
            for obj in scene.objects:
                if obj.data is not None and obj.data.name == data.name:
                    CACHES.dirty.add(obj.name)
        elif isinstance(data, bpy.types.Material):
            # Thickness sources (noise scale, image) live on the material: rebuild its users' batches.
            for obj in scene.objects:
                if any(
                    slot.material is not None and slot.material.name == data.name
                    for slot in obj.material_slots
                ):
                    CACHES.dirty.add(obj.name)


# ----------------------------------------------------------------------------------------------
#: Panorama size for the split sum's prefilter and the headless background.
PANORAMA_WIDTH = 512
PREFILTER_WIDTH = prefilter.LEVEL_WIDTH  # 512: level 0 is the panorama itself


def _prefilter_texture(pre) -> gpu_draw.PrefilterTexture:
    return gpu_draw.PrefilterTexture.from_levels(
        pre.resampled(PREFILTER_WIDTH), pre.resampled_moments(PREFILTER_WIDTH)
    )


class PrefilterTextures:
    """An :class:`~precompute.environment.Environment`'s prefilters on the GPU, each computed and
    uploaded the first time a drawn material reads it (:func:`_prefiltered_for`).

    :meth:`prefiltered`: the split-sum levels with the World's lamps lifted out from
    lamps.LAMP_LEVEL on, for glossy materials that shade the lamps per light;
    :meth:`prefiltered_whole`: the whole World in every level, for the glossy materials the lamps
    do not apply to (a diffuse base under the film, "World Lamps" off). Without lamps they are one
    texture.
    """

    def __init__(self, analysed: Environment):
        self.environment = analysed
        self._lifted: gpu_draw.PrefilterTexture | None = None
        self._whole: gpu_draw.PrefilterTexture | None = None

    def prefiltered(self) -> gpu_draw.PrefilterTexture:
        """The prefilter with the lamps lifted out (the whole World when it has none)."""
        if self.environment.lamps is None:
            return self.prefiltered_whole()
        if self._lifted is None:
            self._lifted = _prefilter_texture(self.environment.prefiltered)
        return self._lifted

    def prefiltered_whole(self) -> gpu_draw.PrefilterTexture:
        """The prefilter with the lamps in every level."""
        if self._whole is None:
            self._whole = _prefilter_texture(self.environment.prefiltered_whole)
        return self._whole


@dataclass(frozen=True)
class WorldLighting:
    """The scene's World as the draw lights with it (:func:`world_lighting`).

    ``key``: :func:`.world_key.world_key` of the World; ``sh``: its SH radiance
    (:class:`.world.WorldSH`); ``environment``: its panorama analysed
    (:func:`precompute.environment.analyse_world`: lamps, prefiltered levels, the lamps' SH),
    or None when not asked for, without a World, or when the panorama render failed (glossy
    films then fall back to the SH path); ``textures``: the environment's prefilters on the GPU
    (None when ``environment`` is).
    """

    key: str
    sh: world.WorldSH
    environment: Environment | None = None
    textures: PrefilterTextures | None = None


def world_lighting(scene, *, allow_compute: bool = True, need_image: bool = True) -> WorldLighting | None:
    """The :class:`WorldLighting` of the scene's World, recomputed only when its key changes.

    The environment (and so the split sum for glossy films) needs a small Cycles panorama render
    of the World; without a World, or if that render fails, glossy films fall back to the SH path.
    With ``allow_compute`` False (the draw callback) a World whose lighting is not cached gives
    None.
    """
    key = world_key.world_key(scene)
    cached = CACHES.world
    if cached is not None and cached.key == key and (cached.environment is not None or not need_image):
        return cached
    if not allow_compute:
        return None
    result = (
        cached.sh
        if cached is not None and cached.key == key
        else world.world_sh(scene)  # every band a table may use (MAX_SH_ORDER)
    )
    analysed = textures = None
    if need_image and scene.world is not None:
        try:
            image = panorama.render_world_panorama(scene.world, width=PANORAMA_WIDTH)
            found = analyse_world(image, result.coeffs, l_max=gpu_draw.MAX_L, width=PREFILTER_WIDTH)
            analysed, textures = found, PrefilterTextures(found)
        except (RuntimeError, ValueError) as exc:
            log.warning("Thin Film SH: no split sum for glossy films (World panorama failed: %s)", exc)
    CACHES.world = WorldLighting(key, result, analysed, textures)
    CACHES.lightings = {k: v for k, v in CACHES.lightings.items() if k[0] == key}
    return CACHES.world


def lighting_for(
    lighting: WorldLighting, l_max: int, roughness: float, lamps: bool = False
) -> gpu_draw.Lighting:
    """The lighting UBO; with ``lamps`` (and a World that has some) the SH without the lamps and
    the lamps themselves."""
    env = lighting.environment
    lamps = bool(lamps and env is not None and env.lamps is not None)
    key = (lighting.key, int(l_max), round(float(roughness), 6), lamps)
    if key not in CACHES.lightings:
        coeffs = env.sh_without_lamps if lamps else np.asarray(lighting.sh.coeffs, dtype=np.float64)
        CACHES.lightings[key] = gpu_draw.Lighting.from_sh(
            coeffs, l_max, roughness, env.lamps if lamps else None
        )
    return CACHES.lightings[key]


def film_texture(desc_key: str, result) -> gpu_draw.FilmTexture:
    if desc_key not in CACHES.films:
        CACHES.films[desc_key] = gpu_draw.FilmTexture.from_film(film_colour.film_table(result))
    return CACHES.films[desc_key]


def uses_lamps(bpy_material, desc) -> bool:
    """Whether the World's lamps are shaded per light direction for this material: its
    "World Lamps" setting (on by default, also for Principled previews), and not under a
    diffuse base, whose lamp light the analytic specular lobe does not carry (it keeps the
    whole World in its SH and prefilter)."""
    props = getattr(bpy_material, "thinfilm_sh", None)
    return bool(getattr(props, "world_lamps", True)) and getattr(desc, "base_color", None) is None


def lamps_summary(enabled: bool) -> str:
    """One line for the Surface panel: what the current World's lamps are and how they are shaded."""
    lighting = CACHES.world
    env = lighting.environment if lighting is not None else None
    if env is None:
        return "World lamps: World not analysed yet"
    if env.lamps is None:
        return "World lamps: none (no small, very bright sources)"
    lamps = env.lamps
    how = "shaded per lamp" if enabled else "off: through SH and prefilter"
    return f"World lamps: {lamps.count}, {100 * lamps.share:.0f} % of the light ({how})"


def table_texture(desc_key: str, result) -> gpu_draw.TableTexture:
    if desc_key not in CACHES.tables:
        CACHES.tables[desc_key] = gpu_draw.TableTexture.from_result(result)
        CACHES.stats["table_uploads"] += 1
    return CACHES.tables[desc_key]


def _slot_batch(obj_eval, mesh, slot: int, bpy_material, desc, messages):
    """MeshBatch of the triangles of material slot ``slot`` (None if it has none)."""
    arrays = gpu_draw.mesh_arrays(mesh)
    if arrays is None:
        return None
    positions, normals, triangles, _ = arrays
    if len(obj_eval.material_slots) > 1:
        tri_poly = np.empty(len(mesh.loop_triangles), dtype=np.int32)
        mesh.loop_triangle_polygons.foreach_get("value", tri_poly)  # an array copy, not per item
        poly_mat = np.zeros(len(mesh.polygons), dtype=np.int32)
        attr = mesh.attributes.get("material_index")  # absent: every face uses slot 0
        if attr is not None and attr.domain == "FACE" and attr.data_type == "INT":
            attr.data.foreach_get("value", poly_mat)
        triangles = triangles[poly_mat[tri_poly] == slot]
    if triangles.shape[0] == 0:
        return None
    thickness = None
    if (
        desc.varies
        and getattr(bpy_material, "thinfilm_sh", None) is not None
        and bpy_material.thinfilm_sh.enabled
    ):
        try:
            thickness = thickness_per_vertex(obj_eval, mesh, bpy_material.thinfilm_sh)
        except ValueError as exc:
            messages.append(f"{obj_eval.name}: {exc}; using the middle of the thickness range")
    if desc.varies and thickness is None:
        thickness = np.full(positions.shape[0], 0.5, dtype=np.float32)
    if thickness is not None:
        thickness = np.nan_to_num(np.clip(np.asarray(thickness, dtype=np.float32), 0.0, 1.0), nan=0.5)
    CACHES.stats["batch_builds"] += 1
    return gpu_draw.MeshBatch.from_arrays(positions, normals, triangles, thickness)


@dataclass
class _MaterialEntry:
    """What one material contributes to a frame, worked out once per frame however many use it."""

    desc: object  # precompute Material
    key: str  # description.description_key(desc)
    table: gpu_draw.TableTexture
    lighting: gpu_draw.Lighting
    roughness: float
    sh_weight: float
    film: gpu_draw.FilmTexture | None = None


def _material_entry(bpy_material, lighting: WorldLighting, allow_bake: bool, want_bake, messages):
    """The material's description, table texture and lighting, or None (no film / not baked yet)."""
    try:
        desc = description.description(bpy_material)
    except ValueError as exc:
        messages.append(str(exc))  # description() names the material
        return None
    if desc is None:
        return None
    result = tables.peek_table(desc)
    if result is None:
        if not allow_bake:
            if want_bake is not None:
                want_bake(desc)
            return None
        result = tables.get_table(desc)
    key = description.description_key(desc)
    roughness = float(desc.roughness)
    env = lighting.environment
    lamps = uses_lamps(bpy_material, desc) and env is not None and env.lamps is not None
    return _MaterialEntry(
        desc,
        key,
        table_texture(key, result),
        lighting_for(lighting, result.sh_order, roughness, lamps),
        roughness,
        policy.sh_weight(roughness),
        film_texture(key, result) if lamps else None,
    )


def _prefiltered_for(lighting: WorldLighting, entry):
    """The prefilter the entry's draw reads, computed on first use; None when it reads none.

    Only the split sum reads a prefilter, and only below an SH weight of 1
    (variant.choose_variant): rough films draw from the SH alone and get none, so a scene of
    rough films computes no prefilter at all. A lamp-shaded film reads the prefilter with the
    lamps lifted out, any other the whole World's.
    """
    textures = lighting.textures
    if textures is None or entry.sh_weight >= 1.0:
        return None
    if entry.film is not None:
        return textures.prefiltered()
    return textures.prefiltered_whole()


def collect(depsgraph, *, allow_bake: bool = True, allow_world: bool = True, want_bake=None):
    """Draw items for every visible mesh object with a thin-film material, and messages.

    With ``allow_bake`` False (the draw callback), materials whose table is not in memory are
    skipped and passed to ``want_bake(desc)`` so the caller can bake them outside drawing.

    Per frame, each material's description, table and lighting are worked out once
    (:func:`_material_entry`), not once per object using it; per object only the batch cache
    is checked (a few lengths, no mesh data read) and the matrix copied, so the work does not
    depend on the triangle count.
    """
    messages: list[str] = []
    items: list[DrawItem] = []
    scene = depsgraph.scene
    lighting = world_lighting(scene, allow_compute=allow_world)
    if lighting is None:
        return items, ["World lighting is being updated"]
    messages.extend(lighting.sh.warnings)
    entries: dict[int, _MaterialEntry | None] = {}  # material pointer → this frame's entry
    seen = set()
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
                entries[pointer] = _material_entry(source, lighting, allow_bake, want_bake, messages)
            entry = entries[pointer]
            if entry is None:
                continue
            key = (original.name, slot_index, inst.is_instance and inst.persistent_id[0])
            mesh = obj_eval.data
            signature = (mesh.name, len(mesh.vertices), len(mesh.loops), entry.key)
            cached = CACHES.batches.get(key)
            if cached is None or cached[0] != signature or original.name in CACHES.dirty:
                batch = _slot_batch(obj_eval, mesh, slot_index, bpy_material, entry.desc, messages)
                CACHES.batches[key] = (signature, batch)
                seen.add(original.name)
            batch = CACHES.batches[key][1]
            if batch is None:
                messages.append(
                    f"{original.name}: no faces with material '{bpy_material.name}': nothing to draw"
                )
                continue
            items.append(
                DrawItem(
                    batch,
                    np.array(inst.matrix_world, dtype=np.float64),
                    entry.table,
                    entry.lighting,
                    f"{original.name}/{bpy_material.name}",
                    prefiltered=_prefiltered_for(lighting, entry),
                    roughness=entry.roughness,
                    sh_weight=entry.sh_weight,
                    film=entry.film,
                )
            )
    CACHES.dirty -= seen
    return items, messages
