"""The shaders: GLSL chunks joined by their ``#include`` lines, and a Variant's create-info.

Each chunk of ``glsl/`` starts with ``#include "tf_x.glsl"`` lines naming the chunks it needs;
:func:`chunk_order` takes the transitive closure of a few root chunks, each once, in dependency
order, and :func:`join_chunks` joins them (the ``#include`` lines removed: Blender's compiler does
not resolve them). The variant's switches and the shading rules are ``#define``s
(:meth:`precompute.shading.variant.Variant.defines`); the generated code comes from
precompute/shading/codegen.py. :func:`mesh_shader_info` turns a :class:`Variant` into its
``GPUShaderCreateInfo`` (the only place that does); :class:`ShaderCache` compiles each variant
once. Slots, structs and resource names are those of :mod:`.layout`.
"""

from __future__ import annotations

import functools
import re
import time
from pathlib import Path

import gpu

from ...precompute.shading import policy
from ...precompute.shading.codegen import X90_GENERATED, banded_source, define_block
from ...precompute.shading.variant import NOISE_RAMP, NOISE_VALUE, Variant
from . import layout
from .context import ensure_gpu_context

#: The product's chunks.
GLSL_DIR = Path(__file__).resolve().parents[2] / "glsl"
#: The root of the shading library (``tf_shade`` and what it includes).
LIBRARY_ROOT = "tf_shade.glsl"

_INCLUDE = re.compile(r'#include\s+"([^"]+)"\s*')


class ChunkError(ValueError):
    """A chunk that cannot be joined: not found, an include cycle, or a misplaced ``#include``."""


@functools.cache
def _parse(path: Path) -> tuple[tuple[str, ...], str]:
    """(included names, body) of one chunk file: the leading ``#include`` lines, the rest."""
    lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
    includes = []
    while lines and (lines[0].strip() == "" or _INCLUDE.fullmatch(lines[0].strip())):
        line = lines.pop(0).strip()
        if line:
            includes.append(_INCLUDE.fullmatch(line).group(1))
    body = "".join(lines)
    if "#include" in re.sub(r"/\*.*?\*/", "", body, flags=re.S):
        raise ChunkError(f"{path.name}: #include lines belong at the top of the chunk")
    return tuple(includes), body


def _find(name: str, search: tuple[Path, ...], needed_by: str | None) -> Path:
    for folder in search:
        path = Path(folder) / name
        if path.is_file():
            return path
    by = f" (included by {needed_by})" if needed_by else ""
    raise ChunkError(f"GLSL chunk {name}{by} not found in {', '.join(str(s) for s in search)}")


def chunk_order(roots, search=(GLSL_DIR,), done=()) -> list[str]:
    """The chunks ``roots`` need, transitively, each once, every chunk after those it includes;
    roots in the given order. Chunks in ``done`` (joined before) are left out. Raises
    :class:`ChunkError` for a missing chunk or an include cycle."""
    search = tuple(search)
    order: list[str] = []
    placed = set(done)

    def visit(name: str, chain: tuple[str, ...]):
        if name in chain:
            raise ChunkError("GLSL include cycle: " + " → ".join((*chain[chain.index(name) :], name)))
        if name in placed:
            return
        includes, _ = _parse(_find(name, search, chain[-1] if chain else None))
        for dep in includes:
            visit(dep, (*chain, name))
        placed.add(name)
        order.append(name)

    for root in roots:
        visit(root, ())
    return order


def join_chunks(names, search=(GLSL_DIR,)) -> str:
    """The chunks' bodies in the order given, each under a ``/* ---- name ---- */`` line."""
    return "\n".join(f"/* ---- {n} ---- */\n{_parse(_find(n, tuple(search), None))[1]}" for n in names)


def _library(
    l_max: int, reference_rotation: Path | None, grid: bool = False
) -> tuple[str, list[str], tuple[Path, ...]]:
    """(source, chunks joined, search folders) of :func:`shading_library`."""
    if reference_rotation is None:
        chunks = chunk_order([LIBRARY_ROOT])
        generated = banded_source(l_max) if l_max > 2 and not grid else ""
        source = "\n".join([define_block([X90_GENERATED]), join_chunks(chunks), generated])
        return source, chunks, (GLSL_DIR,)
    path = Path(reference_rotation)
    search = (path.parent, GLSL_DIR)
    chunks = chunk_order([path.name, LIBRARY_ROOT], search)
    return join_chunks(chunks, search), chunks, search


def shading_library(l_max: int, *, reference_rotation: Path | None = None, grid: bool = False) -> str:
    """The per-pixel shading functions (``tf_shade`` and what it needs) as one GLSL source.

    By default the product's library (``TF_X90_GENERATED``): for l_max ≤ 2 the rotation straight
    from the frame rows (``tf_local_coefficients_direct``), above it the rotation and sum
    generated band by band (codegen.banded_source). ``reference_rotation``: a chunk defining
    ``tf_local_coefficients`` (the generic z-y-z loops, tests/glsl/tf_sh_rotate_loops.glsl; never
    shipped), which ``tf_shade_at`` then calls at every order instead (same results, slower).
    ``grid``: the ``TF_RADIANCE_GRID`` library, whose SH sum is read from the outgoing-radiance
    grid: the generated code is left out (it is what makes high orders slow to compile).
    """
    return _library(l_max, reference_rotation, grid)[0]


def _declare(info, resource) -> None:
    """Declare a :class:`.layout.Block` or :class:`.layout.Sampler` on a create-info."""
    if isinstance(resource, layout.Block):
        info.uniform_buf(resource.slot, resource.struct, resource.name)
    else:
        info.sampler(resource.slot, resource.type, resource.name)


def declare_shading_resources(info, variant: Variant) -> None:
    """Defines (:meth:`Variant.defines`: the variant's switches and the shading rules), types, the
    lighting buffer and the table (sampler, or buffer with ``table_ubo``) that
    :func:`shading_library` uses."""
    if not 0 <= variant.l_max <= layout.MAX_L:
        raise ValueError(f"l_max must lie in 0…{layout.MAX_L}, got {variant.l_max}")
    for name, value in variant.defines():
        info.define(name, value)
    if variant.split_sum:
        _declare(info, layout.PREFILTERED_SAMPLER)
    if variant.film:
        _declare(info, layout.FILM if variant.film_ubo else layout.FILM_SAMPLER)
    if variant.lights:
        _declare(info, layout.LIGHTS)
    if variant.display_lut:
        _declare(info, layout.DISPLAY_LUT_SAMPLER)
    if variant.grid:
        _declare(info, layout.RADIANCE_GRID_SAMPLER)
    if variant.refract:
        _declare(info, layout.BEHIND)
        _declare(info, layout.BEHIND_SAMPLER)
        _declare(info, layout.GLASS_FRONT_SAMPLER)
        _declare(info, layout.GLASS_BACK_SAMPLER)
        _declare(info, layout.GLASS_FILM_SAMPLER)
        _declare(info, layout.GLASS_GEOM_SAMPLER)
        _declare(info, layout.PROBE_SAMPLER)
    info.typedef_source(layout.TYPEDEFS)
    _declare(info, layout.LIGHTING)
    _declare(info, layout.TABLE if variant.table_ubo else layout.TABLE_SAMPLER)


def declare_mesh_inputs(info, iface_name: str):
    """Declare what tf_main_vert.glsl reads (the view and object buffers, a mesh's position and
    normal) on ``info``; return the stage interface it writes (world position and normal), for the
    caller to extend and hand to ``info.vertex_out``."""
    _declare(info, layout.VIEW)
    _declare(info, layout.OBJECT)
    info.vertex_in(0, "VEC3", "pos")
    info.vertex_in(1, "VEC3", "nor")
    iface = gpu.types.GPUStageInterfaceInfo(iface_name)
    iface.smooth("VEC3", "tf_world_pos")
    iface.smooth("VEC3", "tf_world_nor")
    return iface


def _declare_thickness_inputs(info, iface, variant: Variant) -> None:
    """A varying thickness's vertex inputs, what they pass to the fragment stage, and its
    samplers: over the corners, a map at UVs, a noise per pixel (at positions, or before a
    deformation: ``orco``), a noise's Color Ramp."""
    if variant.vary_thickness:
        info.vertex_in(2, "FLOAT", "thickness")
        iface.smooth("FLOAT", "tf_thickness")
    if variant.thickness_map:
        info.vertex_in(3, "VEC2", "uv")
        iface.smooth("VEC2", "tf_uv")
        _declare(info, layout.THICKNESS_MAP_SAMPLER)
    if variant.thickness_noise:
        iface.smooth("VEC3", "tf_object_pos")
    if variant.noise_orco:
        info.vertex_in(4, "VEC3", "orco")
    if variant.thickness_noise == NOISE_RAMP:
        _declare(info, layout.THICKNESS_RAMP_SAMPLER)


def mesh_shader_info(variant: Variant, reference_rotation: Path | None = None):
    """(create-info, stage interface) of a variant's mesh shader; the interface must outlive the
    create-info until it is compiled."""
    info = gpu.types.GPUShaderCreateInfo()
    declare_shading_resources(info, variant)
    iface = declare_mesh_inputs(info, "tf_mesh_iface")
    _declare_thickness_inputs(info, iface, variant)
    info.vertex_out(iface)
    info.fragment_out(0, "VEC4", "tf_frag_color")
    info.vertex_source(join_chunks(chunk_order(["tf_main_vert.glsl"])))
    library, joined, search = _library(variant.l_max, reference_rotation, variant.grid)
    roots = []  # joined only where the variant declares their resources
    if variant.lamps:
        roots.append("tf_lamps.glsl")
    if variant.grid and variant.vary_thickness:
        roots.append("tf_grid_basis.glsl")  # and tf_lamps.glsl, which it includes
    if variant.lights:
        roots.append("tf_lights.glsl")
    if variant.split_sum:
        roots.append("tf_split_sum.glsl")
    if variant.transmit:
        roots.append("tf_transmit.glsl")
    if variant.thickness_noise:
        roots.append("tf_noise.glsl" if variant.thickness_noise == NOISE_VALUE else "tf_perlin.glsl")
    if variant.refract:
        roots.append("tf_glass_tails.glsl")  # and tf_glass_exit.glsl and tf_refract.glsl, which it includes
        roots.append("tf_probe.glsl")
    rest = chunk_order([*roots, "tf_main_frag.glsl"], search, done=joined)
    info.fragment_source(library + "\n" + join_chunks(rest, search))
    return info, iface


def glass_shader_info(geometric: bool = False, further: bool = False):
    """(create-info, stage interface) of the glass buffers' shader (:mod:`.glass_buffers`):
    tf_main_vert.glsl, then tf_glass_frag.glsl (a face's normal and depth, no shading;
    ``geometric``: its geometric normal, ``TF_GLASS_GEOMETRIC``; ``further``: a further layer's,
    behind the layer before, ``TF_GLASS_FURTHER``)."""
    info = gpu.types.GPUShaderCreateInfo()
    if geometric:
        info.define("TF_GLASS_GEOMETRIC", "1")
    if further:
        info.define("TF_GLASS_FURTHER", "1")
        _declare(info, layout.GLASS_PEEL_SAMPLER)
    for name, value in policy.glsl_defines():
        info.define(name, value)
    info.typedef_source(layout.TYPEDEFS)
    iface = declare_mesh_inputs(info, "tf_glass_iface")
    info.vertex_out(iface)
    info.fragment_out(0, "VEC4", "tf_frag_color")
    info.vertex_source(join_chunks(chunk_order(["tf_main_vert.glsl"])))
    info.fragment_source(join_chunks(chunk_order(["tf_glass_frag.glsl"])))
    return info, iface


def background_shader_info(display: bool):
    """(create-info, stage interface) of the environment background shader."""
    info = gpu.types.GPUShaderCreateInfo()
    if display:
        info.define("TF_DISPLAY_SRGB", "1")
    for name, value in policy.glsl_defines():  # tf_common.glsl's guards
        info.define(name, value)
    info.typedef_source(layout.TYPEDEFS)
    _declare(info, layout.VIEW)
    _declare(info, layout.ENVIRONMENT_SAMPLER)
    info.vertex_in(0, "VEC2", "pos")
    iface = gpu.types.GPUStageInterfaceInfo("tf_background_iface")
    iface.smooth("VEC2", "tf_ndc")
    info.vertex_out(iface)
    info.fragment_out(0, "VEC4", "tf_frag_color")
    info.vertex_source(join_chunks(chunk_order(["tf_background_vert.glsl"])))
    info.fragment_source(join_chunks(chunk_order(["tf_background_frag.glsl"])))
    return info, iface


class ShaderCache:
    """Compiled shaders keyed by variant: each is compiled once and reused.

    ``compile_count`` counts compilations (for tests and diagnostics). ``reference_rotation``:
    compile the library with that reference chunk instead of the generated rotation (see
    :func:`shading_library`; tests and benchmarks only).
    """

    def __init__(self, *, reference_rotation: Path | None = None):
        self._shaders: dict = {}
        self._wanted: dict = {}  # variants asked for ahead, in order (a dict as an ordered set)
        self.compile_count = 0
        self.reference_rotation = reference_rotation
        #: Seconds each compilation took, by key (docs/performance.md: first compile per variant).
        self.compile_seconds: dict = {}

    def compiled(self, variant: Variant) -> bool:
        """Whether the mesh shader of ``variant`` is compiled."""
        return variant.normalised() in self._shaders

    def want(self, variant: Variant) -> None:
        """Ask for ``variant`` to be compiled later (:meth:`compile_next`), not now."""
        variant = variant.normalised()
        if variant not in self._shaders:
            self._wanted[variant] = None

    def wanted(self) -> list:
        """The variants asked for and not compiled yet, oldest first."""
        return [v for v in self._wanted if v not in self._shaders]

    def compile_next(self) -> Variant | None:
        """Compile the oldest variant asked for (one per call: an idle step's work); None if none."""
        while self._wanted:
            variant = next(iter(self._wanted))
            del self._wanted[variant]
            if variant not in self._shaders:
                self.mesh(variant)
                return variant
        return None

    def _compile(self, key, make_info):
        shader = self._shaders.get(key)
        if shader is None:
            ensure_gpu_context()
            info, _iface = make_info()  # the interface must outlive the create-info until compiled
            start = time.perf_counter()
            shader = gpu.shader.create_from_info(info)
            self.compile_seconds[key] = time.perf_counter() - start
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
        lights: bool = False,
        display_lut: bool = False,
        transmit: int = 0,
        grid: bool = False,
        refract: bool = False,
    ):
        """The mesh shader of a variant given field by field (see :class:`Variant`)."""
        return self.mesh(
            Variant(
                l_max,
                spectral,
                vary_thickness,
                display,
                split_sum,
                table_ubo,
                split_only,
                lamps,
                film_ubo,
                lights,
                display_lut,
                transmit,
                grid,
                refract,
            )
        )

    def mesh(self, variant: Variant):
        """The mesh shader of a :class:`Variant` (``TF_L_MAX``, ``TF_SPECTRAL``, ``TF_SPLIT_SUM``, …)."""
        variant = variant.normalised()
        return self._compile(variant, lambda: mesh_shader_info(variant, self.reference_rotation))

    def background(self, display: bool):
        """The environment background shader."""
        return self._compile(("background", bool(display)), lambda: background_shader_info(bool(display)))

    def __len__(self):
        return len(self._shaders)

    def clear(self) -> None:
        """Forget every compiled shader (they are rebuilt on next use) and every wish."""
        self._shaders.clear()
        self._wanted.clear()


#: The shared cache used when none is passed.
SHADERS = ShaderCache()
