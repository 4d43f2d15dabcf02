"""GPU drawing of thin-film SH materials: shaders, textures, uniform buffers, batches, read-back.

Only ``bpy``/``gpu`` glue lives here and no scene logic: callers hand in arrays, matrices and baked
tables. The per-pixel maths is in ``glsl/`` (joined here) and mirrors
:func:`precompute.shading.sh_sum.shade_sh` exactly; ``tests/test_gpu_draw.py`` checks one against the
other.

GPU resources
-------------
``tf_table`` (sampler slot 0, ``FLOAT_2D_ARRAY``, RGBA32F)
    width A = view angles θo (uniform 0…90° inclusive), height T = thickness rows, one layer per
    table row: spectral tables have 3 layers per kept coefficient i (layer 3i+k = row k of the
    3×3 matrix, .rgb = lighting RGB), per-channel tables 1 (layer i = the RGB factors).
    Interpolation in θo and thickness is done in the shader with ``texelFetch`` in full float32
    (hardware LINEAR filtering quantises the weights to 8 bits on common GPUs), so the texture's
    own filter mode is irrelevant.
``tf_table_data`` (UBO slot 3, ``TFTable``, instead of ``tf_table`` when the table fits, see
    :data:`TABLE_UBO_TEXELS`; variant define ``TF_TABLE_UBO``): ``vec4 size`` = (A, T, layers),
    then ``vec4 texel[1023]``, texel (row t, column a, layer j) at (t·A + a)·layers + j, .rgb as
    in the texture: one pixel's fetches are neighbours. Always 16 KiB (padded). Same values and
    the same interpolation as the texture; used on the devices of policy.TABLE_UBO_DEVICES
    (docs/tuning.md#table-ubo-devices).
``tf_lighting`` (UBO slot 0, :class:`Lighting`), std140, arrays of vec4 only, 14688 bytes:
    ``vec4 sh[169]`` windowed world radiance SH (rgb, w = 0), index l(l+1)+m, zero beyond the data;
    ``vec4 lamps[17]``: the World's lamps (x of the first = count K ≤ 8, then direction and power
    of each; glsl/tf_lamps.glsl), all zero when the material does not shade lamps;
    ``vec4 rx[732]``: the band blocks of the SH rotation for Rx(+90°), l = 0…12, each row-major,
    band l at scalar offset l(2l−1)(2l+1)/3 (2925 scalars, padded to 2928). Rx(−90°) is their
    transpose (a rotation's inverse), read with the indices swapped: one set fits l ≤ 12 in the
    16 KiB every backend guarantees (both sets needed 26 KiB).
``tf_film`` (sampler slot 4, ``FLOAT_2D_ARRAY``) or ``tf_film_data`` (UBO slot 4, ``TFFilm``, same
    layout as ``TFTable``, when it fits; ``TF_FILM_UBO``): the lamps' film table,
    :class:`FilmTexture` (variants with ``TF_LAMPS`` only).
``tf_view`` (UBO slot 1): view-projection and its inverse (columns), camera position (w = 1 for
    orthographic), the direction towards the viewer, and ``params.x`` = 2^exposure.
``tf_object`` (UBO slot 2): model matrix and normal matrix (inverse transpose), as columns.
``tf_environment`` (background shader, sampler slot 0, FLOAT_2D): the World's equirect image, top
    row first, hardware LINEAR filtering, REPEAT in u, EXTEND in v.

No push constants are used (Vulkan keeps only 128 bytes of them).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import bpy
import gpu
import numpy as np

from ..precompute.material import MAX_SH_ORDER
from ..precompute.shading import policy
from ..precompute.shading.codegen import (
    RX_PADDED,
    X90_GENERATED,
    banded_source,
    define_block,
    x_rotation_scalars,
)
from ..precompute.shading.variant import UBO_LIMIT_BYTES, UBO_TEXELS, Variant, choose_variant

GLSL_DIR = Path(__file__).resolve().parent.parent / "glsl"

#: Highest SH order the shaders support (the UBO always has room for it): material.MAX_SH_ORDER.
MAX_L = MAX_SH_ORDER
#: World SH coefficients in the lighting UBO: (MAX_L + 1)².
SH_SLOTS = (MAX_L + 1) ** 2
#: The World's lamps (precompute/lamps.py): a count, then direction and power per lamp.
MAX_LAMPS = policy.MAX_LAMPS
LAMP_VEC4 = 1 + 2 * MAX_LAMPS
LIGHTING_VEC4 = SH_SLOTS + LAMP_VEC4 + RX_PADDED // 4
#: Table texels (layers × T × A) that fit the table UBO next to its size header (UBO_LIMIT_BYTES:
#: the minimum uniform-buffer size every backend guarantees).
TABLE_UBO_TEXELS = UBO_TEXELS

#: Chunks of the shading library, in dependency order (counterparts in precompute/shading/).
LIBRARY_CHUNKS = ("tf_common.glsl", "tf_frame.glsl", "tf_sh_rotate.glsl", "tf_table.glsl", "tf_shade.glsl")

TYPEDEFS = f"""
struct TFLighting {{
  vec4 sh[{SH_SLOTS}];
  vec4 lamps[{LAMP_VEC4}];
  vec4 rx[{RX_PADDED // 4}];
}};
struct TFView {{
  vec4 view_proj[4];
  vec4 inv_view_proj[4];
  vec4 camera;
  vec4 view_dir;
  vec4 params;
}};
struct TFObject {{
  vec4 model[4];
  vec4 normal[4];
  vec4 material; /* x: roughness, y: SH weight of the split-sum blend */
}};
struct TFTable {{
  vec4 size; /* view angles A, thickness rows T, layers */
  vec4 texel[{TABLE_UBO_TEXELS}];
}};
struct TFFilm {{
  vec4 size; /* u samples U, thickness rows T, layers */
  vec4 texel[{TABLE_UBO_TEXELS}];
}};
"""

# Binding slots.
UBO_LIGHTING, UBO_VIEW, UBO_OBJECT, UBO_TABLE, UBO_FILM = 0, 1, 2, 3, 4
SAMPLER_TABLE = 0
SAMPLER_ENVIRONMENT = 0
SAMPLER_PREFILTERED = 3
SAMPLER_FILM = 4


# ----------------------------------------------------------------------------------------------
# GPU context
# ----------------------------------------------------------------------------------------------
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


# ----------------------------------------------------------------------------------------------
# Shaders
# ----------------------------------------------------------------------------------------------
@functools.cache
def glsl_chunk(name: str) -> str:
    """One file of ``glsl/``."""
    return (GLSL_DIR / name).read_text(encoding="utf-8")


def join_chunks(*names: str) -> str:
    return "\n".join(f"/* ---- {n} ---- */\n{glsl_chunk(n)}" for n in names)


def shading_library(l_max: int, *, generated_x90: bool = True) -> str:
    """The per-pixel shading functions (``tf_shade`` and what it needs) as one GLSL source.

    ``generated_x90`` (default): the fast library (``TF_X90_GENERATED``): for l_max ≤ 2 the
    rotation straight from the frame rows (``tf_local_coefficients_direct``), above it the rotation
    and sum generated band by band (:func:`banded_source`). False: the generic z-y-z loops of
    tf_sh_rotate.glsl at every order, the readable reference (same results, slower).
    """
    if not generated_x90:
        return join_chunks(*LIBRARY_CHUNKS)
    return "\n".join(
        [
            define_block([X90_GENERATED]),
            join_chunks(*LIBRARY_CHUNKS),
            banded_source(l_max) if l_max > 2 else "",
        ]
    )


def declare_shading_resources(info, variant: Variant) -> None:
    """Defines (:meth:`Variant.defines`: the variant's switches and the shading rules), types, the
    lighting UBO and the table (sampler, or UBO with ``table_ubo``) that :func:`shading_library`
    uses."""
    if not 0 <= variant.l_max <= MAX_L:
        raise ValueError(f"l_max must lie in 0…{MAX_L}, got {variant.l_max}")
    for name, value in variant.defines():
        info.define(name, value)
    if variant.split_sum:
        info.sampler(SAMPLER_PREFILTERED, "FLOAT_3D", "tf_prefiltered")
    if variant.lamps:
        if variant.film_ubo:
            info.uniform_buf(UBO_FILM, "TFFilm", "tf_film_data")
        else:
            info.sampler(SAMPLER_FILM, "FLOAT_2D_ARRAY", "tf_film")
    info.typedef_source(TYPEDEFS)
    info.uniform_buf(UBO_LIGHTING, "TFLighting", "tf_lighting")
    if variant.table_ubo:
        info.uniform_buf(UBO_TABLE, "TFTable", "tf_table_data")
    else:
        info.sampler(SAMPLER_TABLE, "FLOAT_2D_ARRAY", "tf_table")


def _mesh_shader_info(variant: Variant, generated_x90: bool = True):
    info = gpu.types.GPUShaderCreateInfo()
    declare_shading_resources(info, variant)
    info.uniform_buf(UBO_VIEW, "TFView", "tf_view")
    info.uniform_buf(UBO_OBJECT, "TFObject", "tf_object")
    info.vertex_in(0, "VEC3", "pos")
    info.vertex_in(1, "VEC3", "nor")
    iface = gpu.types.GPUStageInterfaceInfo("tf_mesh_iface")
    iface.smooth("VEC3", "tf_world_pos")
    iface.smooth("VEC3", "tf_world_nor")
    if variant.vary_thickness:
        info.vertex_in(2, "FLOAT", "thickness")
        iface.smooth("FLOAT", "tf_thickness")
    info.vertex_out(iface)
    info.fragment_out(0, "VEC4", "tf_frag_color")
    info.vertex_source(glsl_chunk("tf_main_vert.glsl"))
    split = ("\n" + glsl_chunk("tf_split_sum.glsl")) if variant.split_sum else ""
    lamps = ("\n" + glsl_chunk("tf_lamps.glsl")) if variant.lamps else ""
    info.fragment_source(
        shading_library(variant.l_max, generated_x90=generated_x90)
        + lamps
        + split
        + "\n"
        + glsl_chunk("tf_main_frag.glsl")
    )
    return info, iface


def _background_shader_info(display: bool):
    info = gpu.types.GPUShaderCreateInfo()
    if display:
        info.define("TF_DISPLAY_SRGB", "1")
    info.typedef_source(TYPEDEFS)
    info.uniform_buf(UBO_VIEW, "TFView", "tf_view")
    info.sampler(SAMPLER_ENVIRONMENT, "FLOAT_2D", "tf_environment")
    info.vertex_in(0, "VEC2", "pos")
    iface = gpu.types.GPUStageInterfaceInfo("tf_background_iface")
    iface.smooth("VEC2", "tf_ndc")
    info.vertex_out(iface)
    info.fragment_out(0, "VEC4", "tf_frag_color")
    info.vertex_source(glsl_chunk("tf_background_vert.glsl"))
    info.fragment_source(join_chunks("tf_common.glsl", "tf_background_frag.glsl"))
    return info, iface


class ShaderCache:
    """Compiled shaders keyed by variant: each is compiled once and reused.

    ``compile_count`` counts compilations (for tests and diagnostics). ``generated_x90=False``
    uses the generic rotation loops instead of the fast library (same results, slower; see
    :func:`shading_library`).
    """

    def __init__(self, *, generated_x90: bool = True):
        self._shaders: dict = {}
        self.compile_count = 0
        self.generated_x90 = bool(generated_x90)

    def _compile(self, key, make_info):
        shader = self._shaders.get(key)
        if shader is None:
            ensure_gpu_context()
            info, _iface = make_info()  # the interface must outlive the create-info until compiled
            shader = gpu.shader.create_from_info(info)
            self.compile_count += 1
            self._shaders[key] = shader
        return shader

    def get(
        self,
        l_max: int,
        spectral: bool,
        vary_thickness: bool,
        display: bool,
        split_sum: bool = False,
        table_ubo: bool = False,
        split_only: bool = False,
        lamps: bool = False,
        film_ubo: bool = False,
    ):
        """The mesh shader of a variant given field by field (see :class:`Variant`)."""
        return self.mesh(
            Variant(
                l_max, spectral, vary_thickness, display, split_sum, table_ubo, split_only, lamps, film_ubo
            )
        )

    def mesh(self, variant: Variant):
        """The mesh shader of a :class:`Variant` (``TF_L_MAX``, ``TF_SPECTRAL``, ``TF_SPLIT_SUM``, …)."""
        variant = variant.normalised()
        return self._compile(variant, lambda: _mesh_shader_info(variant, self.generated_x90))

    def background(self, display: bool):
        """The environment background shader."""
        return self._compile(("background", bool(display)), lambda: _background_shader_info(bool(display)))

    def __len__(self):
        return len(self._shaders)

    def clear(self) -> None:
        self._shaders.clear()


#: The shared cache used when none is passed.
SHADERS = ShaderCache()


# ----------------------------------------------------------------------------------------------
# Data on the GPU
# ----------------------------------------------------------------------------------------------
def float_buffer(array) -> gpu.types.Buffer:
    """A flat FLOAT Buffer from any array (converted to contiguous float32 first)."""
    data = np.ascontiguousarray(np.asarray(array, dtype=np.float32).ravel())
    return gpu.types.Buffer("FLOAT", data.size, data)


def uses_table_ubo(device_type: str) -> bool:
    """Whether a device of this ``gpu.platform.device_type_get()`` type draws tables from the
    uniform buffer (policy.TABLE_UBO_DEVICES)."""
    return str(device_type).upper() in policy.TABLE_UBO_DEVICES


def table_ubo_preferred() -> bool:
    """:func:`uses_table_ubo` for the GPU Blender draws with."""
    ensure_gpu_context()
    return uses_table_ubo(gpu.platform.device_type_get())


@dataclass
class TableTexture:
    """A baked table on the GPU (see the module docstring for the layout) and its metadata."""

    texture: gpu.types.GPUTexture
    l_max: int
    view_samples: int
    thickness_count: int
    spectral: bool
    layers: int
    #: The same table as a ``TFTable`` uniform buffer when it fits (:meth:`uniform_array`).
    ubo: gpu.types.GPUUniformBuf | None = None

    @staticmethod
    def uniform_array(layers: np.ndarray) -> np.ndarray | None:
        """``TFTable`` content (1024 × 4 float32) from :meth:`layer_array`'s output, or None when
        layers × T × A exceeds :data:`TABLE_UBO_TEXELS`."""
        n_layers, t, a = layers.shape[:3]
        if n_layers * t * a > TABLE_UBO_TEXELS:
            return None
        out = np.zeros((TABLE_UBO_TEXELS + 1, 4), dtype=np.float32)
        out[0, :3] = (a, t, n_layers)
        out[1 : 1 + n_layers * t * a] = layers.transpose(1, 2, 0, 3).reshape(-1, 4)  # (t, a, layer)
        return out

    @staticmethod
    def layer_array(data) -> np.ndarray:
        """(layers, T, A, 4) float32 texture content from a table (T, A, K, 3[, 3])."""
        data = np.asarray(data, dtype=np.float32)
        t, a, k = data.shape[:3]
        if data.ndim == 5:  # (T, A, K, 3 out, 3 light) → layer 3i + out
            rows = data.transpose(2, 3, 0, 1, 4).reshape(3 * k, t, a, 3)
        elif data.ndim == 4:
            rows = data.transpose(2, 0, 1, 3)
        else:
            raise ValueError(f"table data must be (T, A, K, 3) or (T, A, K, 3, 3), got {data.shape}")
        out = np.zeros(rows.shape[:3] + (4,), dtype=np.float32)
        out[..., :3] = rows
        return out

    @classmethod
    def from_result(cls, result, *, uniform: bool | None = None) -> TableTexture:
        """Upload a :class:`precompute.bake.BakeResult` (or anything with ``data``, ``sh_order``).

        ``uniform``: also make the uniform-buffer copy when the table fits (drawn from there);
        None (default): where this device draws faster from it (:func:`table_ubo_preferred`).
        """
        if uniform is None:
            uniform = table_ubo_preferred()
        data = np.asarray(result.data)
        l_max = int(result.sh_order)
        if not 0 <= l_max <= MAX_L:
            raise ValueError(f"sh_order must lie in 0…{MAX_L}, got {l_max}")
        kept = (l_max + 1) * (l_max + 2) // 2
        if data.ndim not in (4, 5) or data.shape[2] != kept or data.shape[3] != 3:
            raise ValueError(
                f"table of shape {data.shape} does not match sh_order {l_max} ({kept} coefficients)"
            )
        if data.shape[1] < 2:
            raise ValueError("the table needs at least 2 view angles")
        if not np.all(np.isfinite(data)):
            raise ValueError("the table holds non-finite values")
        layers = cls.layer_array(data)
        ensure_gpu_context()
        n_layers, t, a = layers.shape[:3]
        limit = gpu.capabilities.max_texture_layers_get()
        if n_layers > limit:
            raise ValueError(f"{n_layers} table layers exceed this GPU's limit of {limit}")
        texture = gpu.types.GPUTexture((a, t), layers=n_layers, format="RGBA32F", data=float_buffer(layers))
        packed = cls.uniform_array(layers) if uniform else None
        ubo = gpu.types.GPUUniformBuf(float_buffer(packed)) if packed is not None else None
        return cls(texture, l_max, a, t, data.ndim == 5, n_layers, ubo)


@dataclass
class Lighting:
    """The World's radiance SH, windowed for one material, in a UBO with the rotation constants."""

    ubo: gpu.types.GPUUniformBuf
    coefficients: np.ndarray  # ((l_max+1)², 3) float64, windowed: what the shader sees
    l_max: int
    roughness: float
    #: The World's lamps (precompute.lamps.Lamps) the coefficients were taken without, or None.
    lamps: object = None

    @property
    def lamp_count(self) -> int:
        return 0 if self.lamps is None else int(self.lamps.count)

    @staticmethod
    def pack(coefficients, lamps=None) -> np.ndarray:
        """UBO content (LIGHTING_VEC4 × 4 float32) for windowed coefficients (≤ SH_SLOTS, 3)
        and up to MAX_LAMPS lamps (tf_lamps.glsl's layout)."""
        c = np.asarray(coefficients, dtype=np.float64)
        sh_part = np.zeros((SH_SLOTS, 4), dtype=np.float64)
        sh_part[: c.shape[0], :3] = c[:, :3]
        lamp_part = np.zeros((LAMP_VEC4, 4), dtype=np.float64)
        if lamps is not None and lamps.count:
            if lamps.count > MAX_LAMPS:
                raise ValueError(f"{lamps.count} lamps exceed the shader's {MAX_LAMPS}")
            if not (np.all(np.isfinite(lamps.directions)) and np.all(np.isfinite(lamps.power))):
                raise ValueError("lamp directions and power must be finite")
            lamp_part[0, 0] = lamps.count
            lamp_part[1 : 1 + 2 * lamps.count : 2, :3] = lamps.directions
            lamp_part[2 : 2 + 2 * lamps.count : 2, :3] = lamps.power
        data = np.concatenate([sh_part.ravel(), lamp_part.ravel(), x_rotation_scalars()]).astype(np.float32)
        assert data.size == 4 * LIGHTING_VEC4 and data.nbytes <= UBO_LIMIT_BYTES
        return data

    @classmethod
    def from_sh(cls, world_coeffs, l_max: int, roughness: float, lamps=None) -> Lighting:
        """World SH (≥ 1, 3) → windowed by policy.lighting_window for ``l_max``/``roughness``.

        Missing coefficients (fewer than (l_max+1)²) are zero; extra ones are dropped.
        ``lamps``: the World's lamps, when ``world_coeffs`` are those of the World without them.
        """
        l_max = int(l_max)
        if not 0 <= l_max <= MAX_L:
            raise ValueError(f"l_max must lie in 0…{MAX_L}, got {l_max}")
        c = np.asarray(world_coeffs, dtype=np.float64)
        if c.ndim != 2 or c.shape[1] < 3 or not np.all(np.isfinite(c)):
            raise ValueError(f"world_coeffs must be finite, shape (K, 3), got {c.shape}")
        k = (l_max + 1) ** 2
        full = np.zeros((k, 3))
        n = min(k, c.shape[0])
        full[:n] = c[:n, :3]
        windowed = full * np.asarray(policy.lighting_window(l_max, float(roughness)))[:k, None]
        ensure_gpu_context()
        ubo = gpu.types.GPUUniformBuf(float_buffer(cls.pack(windowed, lamps)))
        return cls(
            ubo, windowed, l_max, float(roughness), lamps if lamps is not None and lamps.count else None
        )


@dataclass
class MeshBatch:
    """A triangle batch with attributes ``pos``, ``nor`` and optionally ``thickness`` (in [0, 1])."""

    batch: gpu.types.GPUBatch
    vertex_count: int
    triangle_count: int
    has_thickness: bool

    @classmethod
    def from_arrays(cls, positions, normals, indices, thickness=None) -> MeshBatch | None:
        """Build from (V, 3) positions and normals, (F, 3) triangle indices, optional (V,) thickness.

        Everything is converted to float32 / int32. Returns None for an empty mesh.
        """
        pos = np.ascontiguousarray(np.asarray(positions, dtype=np.float32).reshape(-1, 3))
        nor = np.ascontiguousarray(np.asarray(normals, dtype=np.float32).reshape(-1, 3))
        idx = np.ascontiguousarray(np.asarray(indices).reshape(-1, 3).astype(np.int32))
        if pos.shape[0] == 0 or idx.shape[0] == 0:
            return None
        if nor.shape != pos.shape:
            raise ValueError(f"normals {nor.shape} must match positions {pos.shape}")
        if idx.min() < 0 or idx.max() >= pos.shape[0]:
            raise ValueError("triangle indices out of range")
        fmt = gpu.types.GPUVertFormat()
        fmt.attr_add(id="pos", comp_type="F32", len=3, fetch_mode="FLOAT")
        fmt.attr_add(id="nor", comp_type="F32", len=3, fetch_mode="FLOAT")
        th = None
        if thickness is not None:
            th = np.ascontiguousarray(np.asarray(thickness, dtype=np.float32).reshape(-1))
            if th.shape[0] != pos.shape[0]:
                raise ValueError(f"thickness {th.shape} must have one value per vertex ({pos.shape[0]})")
            fmt.attr_add(id="thickness", comp_type="F32", len=1, fetch_mode="FLOAT")
        ensure_gpu_context()
        vbo = gpu.types.GPUVertBuf(fmt, pos.shape[0])
        vbo.attr_fill("pos", pos)
        vbo.attr_fill("nor", nor)
        if th is not None:
            vbo.attr_fill("thickness", th)
        ibo = gpu.types.GPUIndexBuf(type="TRIS", seq=idx)
        batch = gpu.types.GPUBatch(type="TRIS", buf=vbo, elem=ibo)
        return cls(batch, pos.shape[0], idx.shape[0], th is not None)


def _attribute_array(mesh, name: str, domain: str, data_type: str, size: int, dtype):
    """A mesh attribute's values read in one block, or None where the attribute is not there.

    ``foreach_get`` on the attribute copies the array; on ``mesh.loops`` / ``mesh.vertices`` it
    goes through RNA item by item, far slower (docs/tuning.md#mesh-attributes).
    """
    attr = mesh.attributes.get(name)
    if attr is None or attr.domain != domain or attr.data_type != data_type:
        return None
    out = np.empty(size, dtype=dtype)
    attr.data.foreach_get("vector" if data_type == "FLOAT_VECTOR" else "value", out)
    return out


def mesh_arrays(mesh, thickness_attribute: str | None = None):
    """(positions, normals, triangles, thickness | None) of a mesh, one vertex per face corner.

    Positions and split/custom normals (``mesh.corner_normals``) per corner (loop), triangles
    from the loop triangulation as corner indices, and the named FLOAT attribute (point, corner
    or face domain) per corner, raw (the caller maps it to [0, 1]); None when it is missing or of
    another type. Returns None for a mesh without triangles.
    """
    tris = mesh.loop_triangles
    if len(tris) == 0:
        mesh.calc_loop_triangles()
        tris = mesh.loop_triangles
    n_tri, n_loop = len(tris), len(mesh.loops)
    if n_tri == 0 or n_loop == 0:
        return None
    loop_vert = _attribute_array(mesh, ".corner_vert", "CORNER", "INT", n_loop, np.int32)
    if loop_vert is None:
        loop_vert = np.empty(n_loop, dtype=np.int32)
        mesh.loops.foreach_get("vertex_index", loop_vert)
    co = _attribute_array(mesh, "position", "POINT", "FLOAT_VECTOR", 3 * len(mesh.vertices), np.float32)
    if co is None:
        co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
        mesh.vertices.foreach_get("co", co)
    positions = co.reshape(-1, 3)[loop_vert]
    normals = np.empty(n_loop * 3, dtype=np.float32)
    mesh.corner_normals.foreach_get("vector", normals)
    triangles = np.empty(n_tri * 3, dtype=np.int32)
    tris.foreach_get("loops", triangles)
    thickness = None
    if thickness_attribute:
        attr = mesh.attributes.get(thickness_attribute)
        if attr is not None and attr.data_type == "FLOAT":
            values = np.empty(len(attr.data), dtype=np.float32)
            attr.data.foreach_get("value", values)
            if attr.domain == "POINT":
                thickness = values[loop_vert]
            elif attr.domain == "CORNER":
                thickness = values
            elif attr.domain == "FACE":
                totals = np.empty(len(mesh.polygons), dtype=np.int32)
                mesh.polygons.foreach_get("loop_total", totals)
                thickness = np.repeat(values, totals)  # polygons own consecutive loop ranges
    return positions, normals.reshape(-1, 3), triangles.reshape(-1, 3), thickness


@dataclass
class EnvironmentTexture:
    """The World's equirect image (H, W, C ≥ 3, top row first) as a filtered RGBA32F texture."""

    texture: gpu.types.GPUTexture
    width: int
    height: int

    @classmethod
    def from_image(cls, image) -> EnvironmentTexture:
        img = np.asarray(image, dtype=np.float32)
        if img.ndim != 3 or img.shape[2] < 3:
            raise ValueError(f"environment image must be (H, W, 3|4), got {img.shape}")
        h, w = img.shape[:2]
        rgba = np.ones((h, w, 4), dtype=np.float32)
        rgba[..., :3] = img[..., :3]
        ensure_gpu_context()
        texture = gpu.types.GPUTexture((w, h), format="RGBA32F", data=float_buffer(rgba))
        texture.filter_mode(True)
        texture.extend_mode_x("REPEAT")
        texture.extend_mode_y("EXTEND")
        return cls(texture, w, h)


@dataclass
class PrefilterTexture:
    """The World prefiltered by GGX at J roughness levels and their direction moments: a 3-D
    texture of depth 2J (see tf_split_sum.glsl)."""

    texture: gpu.types.GPUTexture
    levels: int
    width: int
    height: int

    @classmethod
    def from_levels(cls, levels, moments=None) -> PrefilterTexture:
        """From (J, H, W, 3) radiance, J ≥ 2 levels at roughness (j / (J − 1))², top row first.

        ``moments``: the levels' luminance × direction prefilter, same shape
        (prefilter.Prefiltered.resampled_moments), stored as layers J … 2J − 1; None stores
        zeros, and the shader then reads the film's albedo at the view angle.
        """
        data = np.asarray(levels, dtype=np.float32)
        if data.ndim != 4 or data.shape[0] < 2 or data.shape[3] < 3:
            raise ValueError(f"prefiltered levels must be (J ≥ 2, H, W, 3), got {data.shape}")
        if not np.all(np.isfinite(data)):
            raise ValueError("prefiltered levels contain NaN or Inf")
        j, h, w = data.shape[:3]
        rgba = np.zeros((2 * j, h, w, 4), dtype=np.float32)
        rgba[:j, ..., :3] = data[..., :3]
        if moments is not None:
            mom = np.asarray(moments, dtype=np.float32)
            if mom.shape[:3] != data.shape[:3] or mom.shape[3] < 3:
                raise ValueError(f"prefiltered moments must be {data.shape[:3] + (3,)}, got {mom.shape}")
            if not np.all(np.isfinite(mom)):
                raise ValueError("prefiltered moments contain NaN or Inf")
            rgba[j:, ..., :3] = mom[..., :3]
        ensure_gpu_context()
        # A 3-D texture, not an array: the level blend is one linear fetch
        # (docs/tuning.md#prefilter-texture).
        texture = gpu.types.GPUTexture((w, h, 2 * j), format="RGBA32F", data=float_buffer(rgba))
        texture.filter_mode(True)
        texture.extend_mode("EXTEND")
        texture.extend_mode_x("REPEAT")
        return cls(texture, j, w, h)


@dataclass
class FilmTexture:
    """A film's reflectance against u = cos θ and its multiple-scattering factor, for the lamps
    (precompute.film_colour.FilmTable; layout in tf_lamps.glsl)."""

    texture: gpu.types.GPUTexture
    samples: int
    thickness_count: int
    spectral: bool
    #: The same texels as a ``TFFilm`` uniform buffer when they fit: drawn from there on every
    #: device (docs/tuning.md#table-ubo-devices).
    ubo: gpu.types.GPUUniformBuf | None = None

    @staticmethod
    def layer_array(film) -> np.ndarray:
        """(layers, T, U, 4) float32: the reflectance rows, then the multiple-scattering factor."""
        r = np.asarray(film.reflectance, dtype=np.float32)
        rows = [r[:, :, k, :] for k in range(3)] if r.ndim == 4 else [r]
        rows.append(np.asarray(film.multiscatter, dtype=np.float32))
        out = np.zeros((len(rows),) + r.shape[:2] + (4,), dtype=np.float32)
        for i, row in enumerate(rows):
            out[i, ..., :3] = row
        return out

    @classmethod
    def from_film(cls, film) -> FilmTexture:
        layers = cls.layer_array(film)
        if not np.all(np.isfinite(layers)):
            raise ValueError("the film table holds non-finite values")
        n_layers, t, u = layers.shape[:3]
        if u < 2:
            raise ValueError("the film table needs at least 2 samples in u")
        ensure_gpu_context()
        texture = gpu.types.GPUTexture((u, t), layers=n_layers, format="RGBA32F", data=float_buffer(layers))
        packed = TableTexture.uniform_array(layers)  # same layout: (row * U + column) * layers + layer
        ubo = gpu.types.GPUUniformBuf(float_buffer(packed)) if packed is not None else None
        return cls(texture, u, t, film.reflectance.ndim == 4, ubo)


# ----------------------------------------------------------------------------------------------
# Drawing
# ----------------------------------------------------------------------------------------------
def _matrix(m) -> np.ndarray:
    a = np.array(m, dtype=np.float64)  # mathutils.Matrix rows, numpy or nested lists
    if a.shape != (4, 4):
        raise ValueError(f"expected a 4×4 matrix, got shape {a.shape}")
    return a


def _columns(m: np.ndarray) -> np.ndarray:
    """Columns of a 4×4 as four vec4s (what mat4(c0, c1, c2, c3) takes)."""
    return np.ascontiguousarray(m.T).ravel()


def is_orthographic(projection_matrix) -> bool:
    p = _matrix(projection_matrix)
    return bool(p[3, 3] == 1.0 and p[3, 2] == 0.0)


def view_uniforms(view_matrix, projection_matrix, exposure: float = 0.0) -> np.ndarray:
    """TFView content (11 vec4, float32)."""
    view, proj = _matrix(view_matrix), _matrix(projection_matrix)
    vp = proj @ view
    inv_view = np.linalg.inv(view)
    ortho = is_orthographic(proj)
    toward_viewer = inv_view[:3, 2] / max(np.linalg.norm(inv_view[:3, 2]), 1e-30)
    return np.concatenate(
        [
            _columns(vp),
            _columns(np.linalg.inv(vp)),
            [*inv_view[:3, 3], 1.0 if ortho else 0.0],
            [*toward_viewer, 0.0],
            [2.0 ** float(exposure), 0.0, 0.0, 0.0],
        ]
    ).astype(np.float32)


def object_uniforms(model_matrix, roughness: float = 0.0, sh_weight: float = 1.0) -> np.ndarray:
    """TFObject content: model matrix, normal matrix (inverse transpose of its 3×3), material params."""
    model = _matrix(model_matrix)
    m3 = model[:3, :3]
    try:
        normal3 = np.linalg.inv(m3).T
    except np.linalg.LinAlgError:
        normal3 = np.linalg.pinv(m3).T
    normal = np.eye(4)
    normal[:3, :3] = normal3
    material = np.array([float(roughness), float(sh_weight), 0.0, 0.0])
    return np.concatenate([_columns(model), _columns(normal), material]).astype(np.float32)


def _batch_of(item):
    """(GPUBatch, has_thickness) of a draw item whose ``batch`` is a MeshBatch or a GPUBatch."""
    batch = item.batch
    if isinstance(batch, MeshBatch):
        return batch.batch, batch.has_thickness
    return batch, bool(getattr(item, "has_thickness", False))


class _SavedState:
    """The gpu.state values we change and can read back (face culling has no getter)."""

    def __init__(self):
        self.depth_test = gpu.state.depth_test_get()
        self.depth_mask = gpu.state.depth_mask_get()
        self.blend = gpu.state.blend_get()

    def restore(self):
        gpu.state.depth_test_set(self.depth_test)
        gpu.state.depth_mask_set(self.depth_mask)
        gpu.state.blend_set(self.blend)


class UniformCache:
    """Uniform buffers keyed by what they are made from, kept across frames.

    :meth:`get` returns the buffer made for an equal key before (no upload, no allocation), else
    fills one from ``make()`` (a float32 array): a buffer that no frame has used for
    ``keep_frames`` frames is updated in place, and only when there is none is a new one
    allocated. :meth:`next_frame` (called by :func:`prepare_draw`) ages the entries. So a frame
    in which nothing moved allocates and uploads nothing, and a moving view or object recycles
    old buffers instead of allocating one per frame. A buffer is updated only ``keep_frames``
    frames after its last use, when those draws have long been submitted.

    ``stats``: ``allocations`` (new GPUUniformBuf), ``uploads`` (updates of a recycled one),
    ``hits`` (reused unchanged).
    """

    def __init__(self, keep_frames: int = 4, max_spare: int = 256):
        self.keep_frames = int(keep_frames)
        self.max_spare = int(max_spare)
        self.frame = 0
        self._entries: dict = {}  # key → [ubo, nbytes, last frame used]
        self._spare: dict[int, list] = {}  # nbytes → buffers free for reuse
        self.stats = {"allocations": 0, "uploads": 0, "hits": 0}

    def next_frame(self) -> None:
        self.frame += 1
        oldest = self.frame - self.keep_frames
        stale = [key for key, entry in self._entries.items() if entry[2] < oldest]
        for key in stale:
            ubo, nbytes, _last = self._entries.pop(key)
            spare = self._spare.setdefault(nbytes, [])
            if len(spare) < self.max_spare:
                spare.append(ubo)

    def get(self, key, make) -> gpu.types.GPUUniformBuf:
        entry = self._entries.get(key)
        if entry is not None:
            entry[2] = self.frame
            self.stats["hits"] += 1
            return entry[0]
        data = float_buffer(make())
        nbytes = 4 * len(data)
        spare = self._spare.get(nbytes)
        if spare:
            ubo = spare.pop()
            ubo.update(data)
            self.stats["uploads"] += 1
        else:
            ubo = gpu.types.GPUUniformBuf(data)
            self.stats["allocations"] += 1
        self._entries[key] = [ubo, nbytes, self.frame]
        return ubo

    def __len__(self):
        return len(self._entries)

    def clear(self) -> None:
        self._entries.clear()
        self._spare.clear()


#: The shared uniform-buffer cache used when none is passed.
UNIFORMS = UniformCache()


def view_ubo(view_matrix, projection_matrix, exposure: float = 0.0, uniforms=None):
    """The TFView uniform buffer of a view (from :class:`UniformCache`: reused while unchanged)."""
    uniforms = UNIFORMS if uniforms is None else uniforms
    view, proj = _matrix(view_matrix), _matrix(projection_matrix)
    key = ("view", view.tobytes(), proj.tobytes(), float(exposure))
    return uniforms.get(key, lambda: view_uniforms(view, proj, exposure))


@dataclass
class DrawGroup:
    """Consecutive draws that share a shader variant, lighting, table and prefiltered World."""

    variant: Variant
    shader: gpu.types.GPUShader
    lighting: gpu.types.GPUUniformBuf
    table: gpu.types.GPUTexture | gpu.types.GPUUniformBuf  # the texture, or the UBO (table_ubo)
    prefiltered: gpu.types.GPUTexture | None
    draws: list  # (GPUBatch, object GPUUniformBuf)
    film: gpu.types.GPUTexture | gpu.types.GPUUniformBuf | None = None  # texture, or UBO (film_ubo)


@dataclass
class PreparedDraw:
    """What :func:`submit` draws: the view's uniform buffer and the draws grouped by state."""

    view: gpu.types.GPUUniformBuf | None
    groups: list

    @property
    def draw_count(self) -> int:
        return sum(len(g.draws) for g in self.groups)

    @property
    def shader_binds(self) -> int:
        """Shader binds :func:`submit` makes: one per change of variant between groups."""
        return sum(
            1 for i, g in enumerate(self.groups) if i == 0 or g.shader is not self.groups[i - 1].shader
        )


def prepare_draw(
    items,
    view_matrix,
    projection_matrix,
    *,
    display_srgb: bool,
    exposure: float = 0.0,
    shaders=None,
    uniforms=None,
) -> PreparedDraw:
    """The CPU half of :func:`draw_items`: variants, uniform buffers and the order of the draws.

    Items are grouped by (variant, lighting, table, prefiltered World) so that :func:`submit`
    binds each shader and resource once per group; the order within a group is kept. Uniform
    buffers come from ``uniforms`` (:class:`UniformCache`), keyed by the matrices and material
    parameters they hold: an unchanged view or object reuses its buffer. Nothing is drawn.
    """
    ensure_gpu_context()
    shaders = SHADERS if shaders is None else shaders
    uniforms = UNIFORMS if uniforms is None else uniforms
    uniforms.next_frame()
    groups: dict = {}
    for item in items:
        batch, has_thickness = _batch_of(item)
        if batch is None:
            continue
        table = item.table
        prefiltered = getattr(item, "prefiltered", None)
        sh_weight = float(getattr(item, "sh_weight", 1.0))
        table_ubo = getattr(table, "ubo", None)
        film = getattr(item, "film", None)
        variant = choose_variant(
            l_max=table.l_max,
            spectral=table.spectral,
            thickness_rows=table.thickness_count,
            has_thickness=has_thickness,
            display=display_srgb,
            prefiltered=prefiltered is not None,
            sh_weight=sh_weight,
            lamp_count=getattr(item.lighting, "lamp_count", 0),
            film=film is not None,
            film_ubo=film is not None and film.ubo is not None,
            table_ubo=table_ubo is not None,
        )
        split = variant.split_sum
        roughness = float(getattr(item, "roughness", 0.0))
        weight = sh_weight if split else 1.0
        model = _matrix(item.model_matrix)
        object_ubo = uniforms.get(
            ("object", model.tobytes(), roughness, weight),
            lambda model=model, roughness=roughness, weight=weight: object_uniforms(model, roughness, weight),
        )
        table_data = table.ubo if variant.table_ubo else table.texture
        lamps = variant.lamps
        film_data = (film.ubo if variant.film_ubo else film.texture) if lamps else None
        key = (
            variant,
            id(item.lighting.ubo),
            id(table_data),
            id(prefiltered.texture) if split else None,
            id(film_data) if lamps else None,
        )
        group = groups.get(key)
        if group is None:
            group = groups[key] = DrawGroup(
                variant,
                shaders.mesh(variant),
                item.lighting.ubo,
                table_data,
                prefiltered.texture if split else None,
                [],
                film_data,
            )
        group.draws.append((batch, object_ubo))
    if not groups:
        return PreparedDraw(None, [])
    first = {}  # variant → rank of its first item: equal variants next to each other, else item order
    for group in groups.values():
        first.setdefault(group.variant, len(first))
    ordered = sorted(groups.values(), key=lambda g: first[g.variant])
    return PreparedDraw(view_ubo(view_matrix, projection_matrix, exposure, uniforms), ordered)


def submit(prepared: PreparedDraw) -> None:
    """The GPU half of :func:`draw_items`: state, binds and draw calls; the GPU state is restored.

    Depth test LESS_EQUAL with depth writes, no blending, no face culling. Face culling cannot be
    read back from ``gpu.state`` and is left off (Blender's default); depth test, depth mask and
    blend are restored.
    """
    if not prepared.groups:
        return
    saved = _SavedState()
    try:
        gpu.state.depth_test_set("LESS_EQUAL")
        gpu.state.depth_mask_set(True)
        gpu.state.face_culling_set("NONE")
        gpu.state.blend_set("NONE")
        shader = None
        for group in prepared.groups:
            if group.shader is not shader:
                shader = group.shader
                shader.bind()
                shader.uniform_block("tf_view", prepared.view)
            shader.uniform_block("tf_lighting", group.lighting)
            if group.variant.table_ubo:
                shader.uniform_block("tf_table_data", group.table)
            else:
                shader.uniform_sampler("tf_table", group.table)
            if group.prefiltered is not None:
                shader.uniform_sampler("tf_prefiltered", group.prefiltered)
            if group.film is not None:
                if group.variant.film_ubo:
                    shader.uniform_block("tf_film_data", group.film)
                else:
                    shader.uniform_sampler("tf_film", group.film)
            for batch, object_ubo in group.draws:
                shader.uniform_block("tf_object", object_ubo)
                batch.draw(shader)
    finally:
        saved.restore()


def draw_items(
    items,
    view_matrix,
    projection_matrix,
    *,
    display_srgb: bool,
    exposure: float = 0.0,
    shaders=None,
    uniforms=None,
):
    """Draw thin-film items into the bound framebuffer, depth-tested, and restore the GPU state.

    ``items``: objects with ``.batch`` (:class:`MeshBatch` or a GPUBatch), ``.model_matrix``
    (4×4), ``.table`` (:class:`TableTexture`) and ``.lighting`` (:class:`Lighting`); optionally
    ``.prefiltered`` (:class:`PrefilterTexture`), ``.roughness`` and ``.sh_weight`` (the split
    sum). :func:`prepare_draw` then :func:`submit`; see there.
    """
    submit(
        prepare_draw(
            items,
            view_matrix,
            projection_matrix,
            display_srgb=display_srgb,
            exposure=exposure,
            shaders=shaders,
            uniforms=uniforms,
        )
    )


@functools.cache
def _fullscreen_triangle():
    fmt = gpu.types.GPUVertFormat()
    fmt.attr_add(id="pos", comp_type="F32", len=2, fetch_mode="FLOAT")
    vbo = gpu.types.GPUVertBuf(fmt, 3)
    vbo.attr_fill("pos", np.array([[-1.0, -1.0], [3.0, -1.0], [-1.0, 3.0]], dtype=np.float32))
    return gpu.types.GPUBatch(type="TRIS", buf=vbo)


def draw_background(
    environment,
    view_matrix,
    projection_matrix,
    *,
    display_srgb: bool = False,
    exposure: float = 0.0,
    shaders=None,
) -> None:
    """Draw the equirect environment at the far plane where nothing has been drawn (depth = 1).

    ``environment``: an :class:`EnvironmentTexture` or an image array (H, W, 3|4).
    """
    ensure_gpu_context()
    if not isinstance(environment, EnvironmentTexture):
        environment = EnvironmentTexture.from_image(environment)
    shaders = SHADERS if shaders is None else shaders
    shader = shaders.background(display_srgb)
    view = view_ubo(view_matrix, projection_matrix, exposure)
    saved = _SavedState()
    try:
        gpu.state.depth_test_set("LESS_EQUAL")
        gpu.state.depth_mask_set(False)
        gpu.state.face_culling_set("NONE")
        gpu.state.blend_set("NONE")
        shader.bind()
        shader.uniform_block("tf_view", view)
        shader.uniform_sampler("tf_environment", environment.texture)
        _fullscreen_triangle().draw(shader)
    finally:
        saved.restore()


def read_framebuffer(framebuffer, width: int, height: int) -> np.ndarray:
    """RGBA float32 (H, W, 4), top row first, of a bound framebuffer."""
    buf = framebuffer.read_color(0, 0, width, height, 4, 0, "FLOAT")
    buf.dimensions = width * height * 4
    return np.asarray(buf, dtype=np.float32).reshape(height, width, 4)[::-1].copy()


def render_offscreen(
    items,
    view_matrix,
    projection_matrix,
    width: int,
    height: int,
    *,
    background=None,
    depth_from=None,
    shaders=None,
) -> np.ndarray:
    """Render to an RGBA32F off-screen buffer; scene-linear (H, W, 4) float32, top row first.

    Order: clear (colour 0, depth 1) → ``depth_from(offscreen)`` if given (draws the rest of the
    scene with depth, e.g. through ``offscreen.draw_view3d``; called while the off-screen buffer is
    bound) → the ``background`` equirect image where depth is still 1 → the items, depth-tested.
    Alpha is 1 where anything was drawn and 0 elsewhere (without a background).
    """
    ensure_gpu_context()
    width, height = int(width), int(height)
    if width < 1 or height < 1:
        raise ValueError(f"size must be positive, got {width}×{height}")
    offscreen = gpu.types.GPUOffScreen(width, height, format="RGBA32F")
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            with gpu.matrix.push_pop(), gpu.matrix.push_pop_projection():
                if depth_from is not None:
                    depth_from(offscreen)
                if background is not None:
                    draw_background(background, view_matrix, projection_matrix, shaders=shaders)
                draw_items(items, view_matrix, projection_matrix, display_srgb=False, shaders=shaders)
            return read_framebuffer(fb, width, height)
    finally:
        offscreen.free()
