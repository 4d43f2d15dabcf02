"""Drawing: view and object uniforms, draw items grouped by variant, the background, off-screen.

:func:`prepare_draw` is the CPU half of a frame (variants, uniform buffers, grouping),
:func:`submit` the GPU half (state, binds, draw calls); :func:`draw_items` is both. Items are
made by addon/drawing/scene_draw.py (or tests): a :class:`.mesh.MeshBatch`, a model matrix, a
:class:`.resources.TableTexture` and :class:`.resources.Lighting`, optionally a
:class:`.resources.PrefilterTexture` and :class:`.resources.FilmTexture`.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import gpu
import numpy as np

from ...precompute.shading.transmit import WALL_SOLID, Inside, wall_tint, world_fit
from ...precompute.shading.variant import (
    NOISE_BLENDER,
    NOISE_RAMP,
    NOISE_VALUE,
    TRANSMIT_ADD,
    TRANSMIT_MULTIPLY,
    Variant,
    choose_variant,
    stand_in,
)
from . import layout, resources
from .context import ensure_gpu_context
from .mesh import MeshBatch
from .resources import EnvironmentTexture, UniformCache
from .shaders import SHADERS


def _matrix(m) -> np.ndarray:
    a = np.array(m, dtype=np.float64)  # mathutils.Matrix rows, numpy or nested lists
    if a.shape != (4, 4):
        raise ValueError(f"expected a 4×4 matrix, got shape {a.shape}")
    return a


def _columns(m: np.ndarray) -> np.ndarray:
    """Columns of a 4×4 as four vec4s (what mat4(c0, c1, c2, c3) takes)."""
    return np.ascontiguousarray(m.T).ravel()


def is_orthographic(projection_matrix) -> bool:
    """True for an orthographic projection matrix (last row 0, 0, 0, 1)."""
    p = _matrix(projection_matrix)
    return bool(p[3, 3] == 1.0 and p[3, 2] == 0.0)


def view_uniforms(view_matrix, projection_matrix, exposure: float = 0.0) -> np.ndarray:
    """:data:`.layout.VIEW` content, flat float32."""
    view, proj = _matrix(view_matrix), _matrix(projection_matrix)
    vp = proj @ view
    inv_view = np.linalg.inv(view)
    ortho = is_orthographic(proj)
    toward_viewer = inv_view[:3, 2] / max(np.linalg.norm(inv_view[:3, 2]), 1e-30)
    return layout.VIEW.pack(
        view_proj=_columns(vp),
        inv_view_proj=_columns(np.linalg.inv(vp)),
        camera=[*inv_view[:3, 3], 1.0 if ortho else 0.0],
        view_dir=[*toward_viewer, 0.0],
        params=[2.0 ** float(exposure), 0.0, 0.0, 0.0],
    ).reshape(-1)


def object_uniforms(
    model_matrix,
    roughness: float = 0.0,
    sh_weight: float = 1.0,
    wall: tuple = (0.0, 1.0),
    glass: int = -1,
    inside: Inside | None = None,
    noise: tuple | None = None,
) -> np.ndarray:
    """:data:`.layout.OBJECT` content, flat float32: model matrix, normal matrix (inverse
    transpose of its 3×3), material parameters (roughness, SH weight and a transparent film's
    ``wall``: its mode and relative index, precompute.shading.transmit), solid glass's id in
    the glass buffers (−1: none, its exit through the sphere about its origin), the wall's
    transmission tint (``wall``'s last three entries, :func:`~precompute.shading.transmit.wall_tint`;
    1 without) and what a closed wall's reflections inside read (``inside``, the mesh's
    :class:`~precompute.shading.transmit.Inside`; None: none drawn) and the noise computed per
    pixel (``noise``: ``MeshBatch.noise``)."""
    model = _matrix(model_matrix)
    m3 = model[:3, :3]
    try:
        normal3 = np.linalg.inv(m3).T
    except np.linalg.LinAlgError:
        normal3 = np.linalg.pinv(m3).T
    normal = np.eye(4)
    normal[:3, :3] = normal3
    return layout.OBJECT.pack(
        model=_columns(model),
        normal=_columns(normal),
        material=[float(roughness), float(sh_weight), float(wall[0]), float(wall[1])],
        glass=[float(glass), *(float(c) for c in wall_tint(wall))],
        fit=world_fit(inside.fit, model) if inside is not None else [0.0] * 4,
        inside=[float(inside is not None and inside.drawn), 0.0, 0.0, 0.0],
        **_noise_members(noise),
    ).reshape(-1)


def _noise_members(noise) -> dict:
    """The object block's noise members: a ``precompute.materials.perlin.NoiseSpec``'s, the
    value noise's (scale, seed), or zeros."""
    if hasattr(noise, "uniforms"):  # a NoiseSpec (tests import precompute under another package)
        return noise.uniforms()
    names = ("noise_fbm", "noise_map", "noise_space_x", "noise_space_y", "noise_space_z", "noise_offset")
    zeros = {name: [0.0] * 4 for name in names}
    head = [float(noise[0]), float(noise[1]), 0.0, 0.0] if noise is not None else [0.0] * 4
    return {"noise": head, **zeros}


def _batch_of(item):
    """(GPUBatch, has_thickness, thickness map texture or None) of a draw item whose ``batch``
    is a MeshBatch or a GPUBatch."""
    batch = item.batch
    if isinstance(batch, MeshBatch):
        return batch.batch, batch.has_thickness, batch.map_texture()
    return batch, bool(getattr(item, "has_thickness", False)), None


def _noise_variant(noise) -> int:
    """``Variant.thickness_noise`` of a batch's ``noise``: 0 none, the value noise's (scale,
    seed), or a Noise Texture (``precompute.materials.perlin.NoiseSpec``)."""
    if noise is None:
        return 0
    if not hasattr(noise, "uniforms"):
        return NOISE_VALUE
    return NOISE_RAMP if getattr(noise, "ramp", ()) else NOISE_BLENDER


def _noise_of(item):
    """The noise drawn per pixel (``MeshBatch.noise``), or None."""
    return getattr(item.batch, "noise", None) if isinstance(item.batch, MeshBatch) else None


class _SavedState:
    """The gpu.state values we change and can read back (face culling has no getter); restoring
    them also unbinds our shader (:func:`unbind_shader`)."""

    def __init__(self):
        self.depth_test = gpu.state.depth_test_get()
        self.depth_mask = gpu.state.depth_mask_get()
        self.blend = gpu.state.blend_get()

    def restore(self):
        gpu.state.depth_test_set(self.depth_test)
        gpu.state.depth_mask_set(self.depth_mask)
        gpu.state.blend_set(self.blend)
        unbind_shader()


def unbind_shader() -> None:
    """Leave no shader of ours bound after a draw. Blender keeps the last bound shader in its GPU
    context; once the add-on frees it (unregister, a cache's eviction) Blender's next bind
    calls into the freed shader: a headless frame, then the add-on unregistered, then Blender
    making an image's mipmaps crashed ("pure virtual method called")."""
    gpu.shader.unbind()


#: The shared uniform-buffer cache used when none is passed.
UNIFORMS = UniformCache()


def view_ubo(view_matrix, projection_matrix, exposure: float = 0.0, uniforms=None):
    """The :data:`.layout.VIEW` buffer of a view (from :class:`.resources.UniformCache`: reused
    while unchanged)."""
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
    draws: list  # (GPUBatch, object GPUUniformBuf, thickness map texture or None)
    film: gpu.types.GPUTexture | gpu.types.GPUUniformBuf | None = None  # texture, or UBO (film_ubo)
    lights: gpu.types.GPUUniformBuf | None = None  # Blender's light objects (variant.lights)
    grid: gpu.types.GPUTexture | None = None  # the outgoing-radiance grid (variant.grid)
    #: A transparent film's pass: face culling ("NONE", or "FRONT" to draw the back faces) and
    #: blend ("NONE" for opaque films; "MULTIPLY" then "ADDITIVE_PREMULT"); no depth writes.
    cull: str = "NONE"
    blend: str = "NONE"


@dataclass
class PreparedDraw:
    """What :func:`submit` draws: the view's uniform buffer and the draws grouped by state."""

    view: gpu.types.GPUUniformBuf | None
    groups: list
    #: The display LUT's texture (``TF_DISPLAY_LUT`` variants), or None.
    display_lut: gpu.types.GPUTexture | None = None
    #: The scene behind the films (``TF_REFRACT`` variants, :class:`.resources.BehindTexture`), or None.
    behind: resources.BehindTexture | None = None

    @property
    def draw_count(self) -> int:
        """Number of draws over all groups."""
        return sum(len(g.draws) for g in self.groups)

    @property
    def shader_binds(self) -> int:
        """Shader binds :func:`submit` makes: one per change of variant between groups."""
        return sum(
            1 for i, g in enumerate(self.groups) if i == 0 or g.shader is not self.groups[i - 1].shader
        )


def _add_item(groups: dict, item, batch, has_thickness, options, transmit=0, thickness_map=None):
    """Add one item's draw to ``groups`` (keyed by what its group binds). ``options``:
    (display_srgb, shaders, uniforms, display_lut, compile_now) of :func:`prepare_draw`;
    ``transmit``: the blend pass of a transparent film (variant.TRANSMIT_PASSES), 0 for an opaque
    one; ``thickness_map``: the batch's thickness map texture (``TF_THICKNESS_MAP``), or None;
    ``behind`` (in ``options``): the scene-behind texture solid glass refracts, or None."""
    display_srgb, shaders, uniforms, display_lut, compile_now, behind = options
    table = item.table
    prefiltered = getattr(item, "prefiltered", None)
    sh_weight = float(getattr(item, "sh_weight", 1.0))
    table_ubo = getattr(table, "ubo", None)
    film = getattr(item, "film", None)
    lights = getattr(item, "lights", None)
    grid = getattr(item, "grid", None)
    noise = _noise_of(item)
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
        light_count=resources.light_count(lights),
        display_lut=display_lut is not None,
        transmit=transmit,
        grid=grid is not None,
        refract=behind is not None and transmit != 0 and int(item.wall[0]) == WALL_SOLID,
        thickness_map=thickness_map is not None,
        thickness_noise=_noise_variant(noise),
        noise_orco=bool(getattr(noise, "orco", False)),
    )
    if not compile_now and not shaders.compiled(variant):
        if not getattr(item, "grid_pending", False):  # a grid variant replaces it soon: not wanted
            shaders.want(variant)
        variant = stand_in(variant)
    split = variant.split_sum
    roughness = float(getattr(item, "roughness", 0.0))
    weight = sh_weight if split else 1.0
    wall = tuple(float(x) for x in item.wall) if variant.transmit else (0.0, 1.0)
    model = _matrix(item.model_matrix)
    glass = behind.ids.get(id(item), -1) if variant.refract else -1
    inside = getattr(item.batch, "inside", None) if variant.transmit else None  # both passes: one buffer
    noise = _noise_of(item) if variant.thickness_noise else None
    object_ubo = uniforms.get(
        ("object", model.tobytes(), roughness, weight, wall, glass, inside, noise),
        lambda: object_uniforms(model, roughness, weight, wall, glass, inside, noise),
    )
    table_data = table.ubo if variant.table_ubo else table.texture
    film_data = (film.ubo if variant.film_ubo else film.texture) if variant.film else None
    lights_ubo = None
    if variant.lights:
        content = np.asarray(lights, dtype=np.float32)
        lights_ubo = uniforms.get(("lights", content.tobytes()), lambda: content)
    key = (
        variant,
        id(item.lighting.ubo),
        id(table_data),
        id(prefiltered.texture) if split else None,
        id(film_data) if variant.film else None,
        id(lights_ubo) if variant.lights else None,
        id(grid.texture) if variant.grid else None,
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
            lights_ubo,
            grid=grid.texture if variant.grid else None,
        )
    texture = thickness_map if variant.thickness_map else None
    if variant.thickness_noise == NOISE_RAMP:
        texture = item.batch.ramp_texture()
    group.draws.append((batch, object_ubo, texture))


def _ordered(groups: dict) -> list:
    """Groups with equal variants next to each other, else in the order of their first item."""
    first = {}  # variant → rank of its first item
    for group in groups.values():
        first.setdefault(group.variant, len(first))
    return sorted(groups.values(), key=lambda g: first[g.variant])


def is_wall(item) -> bool:
    """Whether a draw item is a transparent film (its ``wall``: (mode, η) of
    precompute.shading.transmit) with the film table that its transmittance is read from."""
    return getattr(item, "wall", None) is not None and getattr(item, "film", None) is not None


#: A transparent film's passes, in order: back faces (the far wall of a closed bubble), then front
#: faces; for each, multiply what is behind by T, then add R·L.
WALL_PASSES = tuple(
    (cull, transmit, blend)
    for cull in ("FRONT", "BACK")
    for transmit, blend in ((TRANSMIT_MULTIPLY, "MULTIPLY"), (TRANSMIT_ADD, "ADDITIVE_PREMULT"))
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
    display_lut=None,
    compile_now: bool = True,
    behind=None,
) -> PreparedDraw:
    """The CPU half of :func:`draw_items`: variants, uniform buffers and the order of the draws.

    ``compile_now`` False (the viewport): a variant that is not compiled yet is not compiled
    here; it is asked for (``ShaderCache.want``, compiled later one per idle step) and the item
    is drawn with its stand-in meanwhile (variant.stand_in: order ≤ policy.STAND_IN_L, no grid).

    Items are grouped by (variant, lighting, table, prefiltered World) so that :func:`submit`
    binds each shader and resource once per group; the order within a group is kept. Uniform
    buffers come from ``uniforms`` (:class:`UniformCache`), keyed by the matrices and material
    parameters they hold: an unchanged view or object reuses its buffer. Transparent films
    (:func:`is_wall`) come after the opaque ones, in the :data:`WALL_PASSES`. Nothing is drawn.
    ``display_lut`` (a :class:`.resources.DisplayLUTTexture`, with ``display_srgb``): the
    scene's view transform instead of the Standard sRGB encoding. ``behind`` (a
    :class:`.resources.BehindTexture`: the frame drawn without the films, colour and depth):
    solid glass refracts it (``TF_REFRACT``, precompute/shading/glass/refract.py); None: solid glass
    sees the World along its exit ray.
    """
    ensure_gpu_context()
    shaders = SHADERS if shaders is None else shaders
    uniforms = UNIFORMS if uniforms is None else uniforms
    uniforms.next_frame()
    groups: dict = {}
    walls: dict = {TRANSMIT_MULTIPLY: {}, TRANSMIT_ADD: {}}
    for item in items:
        batch, has_thickness, thickness_map = _batch_of(item)
        if batch is None:
            continue
        options = (display_srgb, shaders, uniforms, display_lut, compile_now, behind)
        if is_wall(item):
            for transmit, found in walls.items():
                _add_item(found, item, batch, has_thickness, options, transmit, thickness_map)
        else:
            _add_item(groups, item, batch, has_thickness, options, thickness_map=thickness_map)
    if not groups and not walls[TRANSMIT_MULTIPLY]:
        return PreparedDraw(None, [])
    ordered = _ordered(groups)
    for cull, transmit, blend in WALL_PASSES:
        ordered += [dataclasses.replace(g, cull=cull, blend=blend) for g in _ordered(walls[transmit])]
    lut = display_lut.texture if (display_lut is not None and display_srgb) else None
    return PreparedDraw(view_ubo(view_matrix, projection_matrix, exposure, uniforms), ordered, lut, behind)


def _bind_group(shader, group: DrawGroup) -> None:
    """Bind what a group's draws read: lighting, table, prefilter, film, lights, grid (each that
    the group has), a table or film from its uniform buffer where the variant reads it there."""
    binds = (
        (layout.LIGHTING, group.lighting),
        (layout.TABLE if group.variant.table_ubo else layout.TABLE_SAMPLER, group.table),
        (layout.PREFILTERED_SAMPLER, group.prefiltered),
        (layout.FILM if group.variant.film_ubo else layout.FILM_SAMPLER, group.film),
        (layout.LIGHTS, group.lights),
        (layout.RADIANCE_GRID_SAMPLER, group.grid),
    )
    for resource, value in binds:
        if value is None:
            continue
        if isinstance(resource, layout.Block):
            shader.uniform_block(resource.name, value)
        else:
            shader.uniform_sampler(resource.name, value)


def _opaque_state(depth_write: bool) -> None:
    """Depth test LESS_EQUAL (writing depth when ``depth_write``), no face culling, no blending."""
    gpu.state.depth_test_set("LESS_EQUAL")
    gpu.state.depth_mask_set(depth_write)
    gpu.state.face_culling_set("NONE")
    gpu.state.blend_set("NONE")


def submit(prepared: PreparedDraw) -> None:
    """The GPU half of :func:`draw_items`: state, binds and draw calls; the GPU state is restored.

    Depth test LESS_EQUAL with depth writes, no blending, no face culling; a transparent film's
    passes (:data:`WALL_PASSES`) blend and cull as their group says, without depth writes. Face
    culling cannot be read back from ``gpu.state`` and is left off (Blender's default); depth test,
    depth mask and blend are restored.
    """
    if not prepared.groups:
        return
    saved = _SavedState()
    try:
        _opaque_state(depth_write=True)
        shader = None
        state = ("NONE", "NONE")
        for group in prepared.groups:
            if (group.cull, group.blend) != state:
                state = (group.cull, group.blend)
                gpu.state.face_culling_set(group.cull)
                gpu.state.blend_set(group.blend)
                gpu.state.depth_mask_set(group.blend == "NONE")
            if group.shader is not shader:
                shader = group.shader
                shader.bind()
                shader.uniform_block(layout.VIEW.name, prepared.view)
                if group.variant.display_lut:
                    shader.uniform_sampler(layout.DISPLAY_LUT_SAMPLER.name, prepared.display_lut)
                if group.variant.refract:
                    shader.uniform_block(layout.BEHIND.name, prepared.behind.ubo)
                    shader.uniform_sampler(layout.BEHIND_SAMPLER.name, prepared.behind.texture)
                    front, back, film, geom = prepared.behind.glass_textures()
                    shader.uniform_sampler(layout.GLASS_FRONT_SAMPLER.name, front)
                    shader.uniform_sampler(layout.GLASS_BACK_SAMPLER.name, back)
                    shader.uniform_sampler(layout.GLASS_FILM_SAMPLER.name, film)
                    shader.uniform_sampler(layout.GLASS_GEOM_SAMPLER.name, geom)
                    shader.uniform_sampler(layout.PROBE_SAMPLER.name, prepared.behind.probe_texture())
            _bind_group(shader, group)
            ramp = group.variant.thickness_noise == NOISE_RAMP
            sampler = (layout.THICKNESS_RAMP_SAMPLER if ramp else layout.THICKNESS_MAP_SAMPLER).name
            for batch, object_ubo, texture in group.draws:
                shader.uniform_block(layout.OBJECT.name, object_ubo)
                if texture is not None:  # the thickness map, or a ramp variant's table
                    shader.uniform_sampler(sampler, texture)
                batch.draw(shader)
    finally:
        gpu.state.face_culling_set("NONE")
        saved.restore()


def draw_items(items, view_matrix, projection_matrix, **options):
    """Draw thin-film items into the bound framebuffer, depth-tested, and restore the GPU state.

    ``items``: objects with ``.batch`` (:class:`.mesh.MeshBatch` or a GPUBatch),
    ``.model_matrix`` (4×4), ``.table`` (:class:`.resources.TableTexture`) and ``.lighting``
    (:class:`.resources.Lighting`); optionally ``.prefiltered``
    (:class:`.resources.PrefilterTexture`), ``.film`` (:class:`.resources.FilmTexture`),
    ``.lights`` (:func:`.resources.lights_content`: Blender's light objects, shaded with the
    film), ``.grid`` (:class:`.resources.RadianceGridTexture`: the SH half of a constant-thickness
    film, variant.choose_variant), ``.roughness`` and ``.sh_weight`` (the split sum), ``.wall`` (a
    transparent film: (mode, η) of precompute.shading.transmit, drawn with its ``.film`` in blend
    passes over what the framebuffer holds). ``display_lut``: the scene's view transform
    (:class:`.resources.DisplayLUTTexture`). ``compile_now`` False: uncompiled variants are drawn
    by their stand-in (:func:`prepare_draw`). ``behind``: the scene behind that solid glass
    refracts (:func:`prepare_draw`). ``options``: :func:`prepare_draw`'s (``display_srgb``
    is required). :func:`prepare_draw` then :func:`submit`; see there.
    """
    submit(prepare_draw(items, view_matrix, projection_matrix, **options))


@functools.cache
def _fullscreen_triangle():
    fmt = gpu.types.GPUVertFormat()
    fmt.attr_add(id="pos", comp_type="F32", len=2, fetch_mode="FLOAT")
    vbo = gpu.types.GPUVertBuf(fmt, 3)
    vbo.attr_fill("pos", np.array([[-1.0, -1.0], [3.0, -1.0], [-1.0, 3.0]], dtype=np.float32))
    return gpu.types.GPUBatch(type="TRIS", buf=vbo)


class _Memo:
    """``clear()`` of a ``functools.cache`` memo (the add-on's cache registry calls it)."""

    def __init__(self, memo):
        self.memo = memo

    def clear(self) -> None:
        self.memo.cache_clear()


#: The full-screen triangle's memo: a GPU batch, which must be freed while Blender runs (one
#: collected at interpreter exit, after Blender's own, crashes the process: exit code -11), so
#: it is emptied with the SESSION caches on unregister (registered by ``scene_draw``).
FULLSCREEN_TRIANGLE = _Memo(_fullscreen_triangle)


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

    ``environment``: an :class:`.resources.EnvironmentTexture` or an image array (H, W, 3|4).
    """
    ensure_gpu_context()
    if not isinstance(environment, EnvironmentTexture):
        environment = EnvironmentTexture.from_image(environment)
    shaders = SHADERS if shaders is None else shaders
    shader = shaders.background(display_srgb)
    view = view_ubo(view_matrix, projection_matrix, exposure)
    saved = _SavedState()
    try:
        _opaque_state(depth_write=False)
        shader.bind()
        shader.uniform_block(layout.VIEW.name, view)
        shader.uniform_sampler(layout.ENVIRONMENT_SAMPLER.name, environment.texture)
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
    with_depth: bool = False,
    clear=(0.0, 0.0, 0.0, 0.0),
    behind=None,
    compile_now: bool = True,
):
    """Render to an RGBA32F off-screen buffer; scene-linear (H, W, 4) float32, top row first
    (with ``with_depth``: and the depth buffer, (H, W) window depth in [0, 1], 1 where nothing).

    Order: clear (colour ``clear``, depth 1) → ``depth_from(offscreen)`` if given (draws the rest of the
    scene with depth, e.g. through ``offscreen.draw_view3d``; called while the off-screen buffer is
    bound) → the ``background`` equirect image where depth is still 1 → the items, depth-tested.
    Alpha is 1 where anything was drawn and 0 elsewhere (without a background). ``behind``: the
    scene behind that solid glass refracts (:func:`prepare_draw`). ``compile_now`` False: a
    variant not compiled yet is drawn by its stand-in, as in the viewport (:func:`draw_items`).
    """
    ensure_gpu_context()
    width, height = int(width), int(height)
    if width < 1 or height < 1:
        raise ValueError(f"size must be positive, got {width}×{height}")
    offscreen = gpu.types.GPUOffScreen(width, height, format="RGBA32F")
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=tuple(float(c) for c in clear), depth=1.0)
            with gpu.matrix.push_pop(), gpu.matrix.push_pop_projection():
                if depth_from is not None:
                    depth_from(offscreen)
                if background is not None:
                    draw_background(background, view_matrix, projection_matrix, shaders=shaders)
                draw_items(
                    items,
                    view_matrix,
                    projection_matrix,
                    display_srgb=False,
                    shaders=shaders,
                    behind=behind,
                    compile_now=compile_now,
                )
            rgba = read_framebuffer(fb, width, height)
            if not with_depth:
                return rgba
            depth = fb.read_depth(0, 0, width, height)
            depth.dimensions = width * height
            return rgba, np.asarray(depth, dtype=np.float32).reshape(height, width)[::-1].copy()
    finally:
        offscreen.free()
