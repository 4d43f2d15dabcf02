"""Solid glass's real faces for its refraction: the glass buffers of the headless frame.

The exit ray of solid glass (``TF_REFRACT``, glsl/tf_glass_exit.glsl ``tf_glass_exit``, numpy twin
precompute/shading/glass/glass_exit.py ``mesh_exit``) leaves the object where its inner ray crosses the
object's real surface. The draw knows that surface per pixel from two off-screen passes over the
solid glass objects, drawn in the films' window before the films (:func:`render_glass_buffers`):

- **front**: the nearest front face per pixel (back faces culled), and
- **back**: the nearest back face per pixel (front faces culled),

each texel .xyz = the face's unit outward normal × (id + 1), .w = its depth along the camera
axis, 0 where no glass is (glsl/tf_glass_frag.glsl; decoded by ``glass_exit.glass_texel``). The id
tells objects apart, so one glass does not exit through another's faces. Each pass is peeled
``policy.GLASS_LAYERS`` deep (``TF_GLASS_FURTHER``: a further layer draws only the faces behind
the layer before): for a convex object the pixel's span [front, back] of layer 0 is exactly the
object along that pixel's camera ray; a concave one (a wine glass) has a further span per layer,
its far wall behind its near one, its foot behind its stem, which the exit ray enters again
(``glass_exit._march_enter``). The arrays are (layers, H, W, 4), the textures 2D arrays of as many
layers (the window's side may be the GPU's limit on a texture's side, so the layers do not share
one).

The same two passes drawn again with ``TF_GLASS_GEOMETRIC`` give those faces' geometric (flat)
normals, kept in one texture, **geom**: .xy the front face's, .zw the back face's, octahedral
(``glass_exit.geometric_texel``). With them the march meets a smooth-shaded face as Cycles does
(``glass_exit.valid_normal``): a wine glass's foot, shaded smooth across its rim, sends the light
Cycles sends, not straight through to the ground.
"""

from __future__ import annotations

import dataclasses
import itertools

import gpu
import numpy as np

from ...precompute.shading.policy import GLASS_LAYERS
from ...precompute.shading.transmit import WALL_SOLID
from . import layout
from .draw import _batch_of, _matrix, object_uniforms, read_framebuffer, unbind_shader, view_ubo
from .resources import float_buffer
from .shaders import glass_shader_info

#: The glass buffers' passes: (name, the faces culled).
PASSES = (("front", "BACK"), ("back", "FRONT"))

_SHADERS = {}


def glass_shader(geometric: bool = False, further: bool = False):
    """The glass buffers' shader (compiled once each): tf_main_vert.glsl, then
    tf_glass_frag.glsl; ``geometric``: the faces' geometric normals (``TF_GLASS_GEOMETRIC``);
    ``further``: a further layer's faces (``TF_GLASS_FURTHER``)."""
    key = (geometric, further)
    if key not in _SHADERS:
        info, iface = glass_shader_info(geometric, further)
        _SHADERS[key] = gpu.shader.create_from_info(info)
        del iface  # kept until the shader is compiled
    return _SHADERS[key]


def solid_glass(items) -> list:
    """The items drawn as solid glass (a wall of mode WALL_SOLID), in order: their ids."""
    return [
        item
        for item in items
        if getattr(item, "wall", None) is not None
        and getattr(item, "film", None) is not None
        and int(item.wall[0]) == WALL_SOLID
    ]


@dataclasses.dataclass
class GlassBuffers:
    """The glass buffers (layers, H, W, 4) float32, top row first: ``front``, ``back`` and their
    faces' geometric normals ``geom`` (see the module), and each glass item's ``id()`` → its id."""

    front: np.ndarray
    back: np.ndarray
    geom: np.ndarray
    ids: dict

    def textures(self) -> tuple:
        """(front, back, geom) as RGBA32F 2D-array textures, one array layer per layer, row 0 at
        the bottom (as drawn)."""
        layers, h, w = self.front.shape[:3]
        return tuple(
            gpu.types.GPUTexture((w, h), layers=layers, format="RGBA32F", data=float_buffer(a[:, ::-1]))
            for a in (self.front, self.back, self.geom)
        )


def _draw_pass(fb, glass, ubos, view, cull: str, geometric: bool, peel) -> None:
    """One pass of the glass buffers into ``fb``: the faces not culled by ``cull``, nearest first;
    ``peel``: the same side's layer before (a texture), whose faces it draws behind."""
    shader = glass_shader(geometric, peel is not None)
    fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
    gpu.state.depth_test_set("LESS")
    gpu.state.depth_mask_set(True)
    gpu.state.blend_set("NONE")
    gpu.state.face_culling_set(cull)
    try:
        shader.bind()
        shader.uniform_block(layout.VIEW.name, view)
        if peel is not None:
            shader.uniform_sampler(layout.GLASS_PEEL_SAMPLER.name, peel)
        for ubo, item in zip(ubos, glass, strict=True):
            shader.uniform_block(layout.OBJECT.name, ubo)
            _batch_of(item)[0].draw(shader)
    finally:
        unbind_shader()
        gpu.state.face_culling_set("NONE")
        gpu.state.depth_test_set("NONE")
        gpu.state.depth_mask_set(False)


def render_glass_buffers(
    items, view_matrix, projection_matrix, width: int, height: int, layers: int = GLASS_LAYERS
) -> GlassBuffers | None:
    """Draw the solid glass ``items`` into the glass buffers of a ``width`` × ``height`` window (the
    films' pass, the same matrices), ``layers`` deep; None without solid glass. See the module."""
    glass = solid_glass(items)
    if not glass:
        return None
    ids = {id(item): k for k, item in enumerate(glass)}
    view = view_ubo(view_matrix, projection_matrix)
    # kept alive until drawn: a buffer freed before its draw call is not bound
    ubos = [
        gpu.types.GPUUniformBuf(
            float_buffer(object_uniforms(_matrix(item.model_matrix), glass=ids[id(item)]))
        )
        for item in glass
    ]
    w, h = int(width), int(height)
    out = {}
    offscreen = gpu.types.GPUOffScreen(w, h, format="RGBA32F")
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            for layer, (name, cull) in itertools.product(range(int(layers)), PASSES):
                peel = None
                if layer > 0:
                    before = out[name, False, layer - 1]
                    if not np.any(before[..., 3] > 0.0):  # nothing left to peel
                        out[name, False, layer] = out[name, True, layer] = np.zeros_like(before)
                        continue
                    peel = gpu.types.GPUTexture((w, h), format="RGBA32F", data=float_buffer(before[::-1]))
                for geometric in (False, True):
                    _draw_pass(fb, glass, ubos, view, cull, geometric, peel)
                    out[name, geometric, layer] = read_framebuffer(fb, w, h)
    finally:
        offscreen.free()

    def stack(name, geometric):
        return np.stack([out[name, geometric, k] for k in range(int(layers))])

    geom = np.concatenate([stack("front", True)[..., :2], stack("back", True)[..., :2]], axis=-1)
    return GlassBuffers(stack("front", False), stack("back", False), geom, ids)


def film_texture(tables) -> gpu.types.GPUTexture | None:
    """The glass's back-face films as one texture: row k = glass id k's table (U, 3) with .a = 1,
    or .a = 0 where its entry is None (the front film stands in); None without any table."""
    if not any(t is not None for t in tables):
        return None
    samples = max(np.asarray(t).shape[0] for t in tables if t is not None)
    rows = np.zeros((len(tables), samples, 4), dtype=np.float32)
    for k, table in enumerate(tables):
        if table is not None and np.asarray(table).shape[0] == samples:
            rows[k, :, :3] = table
            rows[k, :, 3] = 1.0
    return gpu.types.GPUTexture((samples, len(tables)), format="RGBA32F", data=float_buffer(rows))
