"""Solid glass's real faces for its refraction: the glass buffers of the headless frame.

The exit ray of solid glass (``TF_REFRACT``, glsl/tf_refract.glsl ``tf_glass_exit``, numpy twin
precompute/shading/refract.py ``mesh_exit``) leaves the object where its inner ray crosses the
object's real surface. The draw knows that surface per pixel from two off-screen passes over the
solid glass objects, drawn in the films' window before the films (:func:`render_glass_buffers`):

- **front**: the nearest front face per pixel (back faces culled), and
- **back**: the nearest back face per pixel (front faces culled),

each texel .xyz = the face's unit outward normal × (id + 1), .w = its depth along the camera
axis, 0 where no glass is (glsl/tf_glass_frag.glsl; decoded by ``refract.glass_texel``). The id
tells objects apart, so one glass does not exit through another's faces. For a convex object the
pixel's span [front, back] is exactly the object along that pixel's camera ray; a concave one (a
wine glass's bowl) is taken as its nearest front and back faces.

The same two passes drawn again with ``TF_GLASS_GEOMETRIC`` give those faces' geometric (flat)
normals, kept in one texture, **geom**: .xy the front face's, .zw the back face's, octahedral
(``refract.geometric_texel``). With them the march meets a smooth-shaded face as Cycles does
(``refract.valid_normal``): a wine glass's foot, shaded smooth across its rim, sends the light
Cycles sends, not straight through to the ground.
"""

from __future__ import annotations

import dataclasses
import itertools

import gpu
import numpy as np

from ...precompute.shading.transmit import WALL_SOLID
from . import layout
from .draw import _batch_of, _matrix, object_uniforms, read_framebuffer, view_ubo
from .resources import float_buffer
from .shaders import glass_shader_info

#: The glass buffers' passes: (name, the faces culled).
PASSES = (("front", "BACK"), ("back", "FRONT"))

_SHADERS = {}


def glass_shader(geometric: bool = False):
    """The glass buffers' shader (compiled once each): tf_main_vert.glsl, then
    tf_glass_frag.glsl; ``geometric``: the faces' geometric normals (``TF_GLASS_GEOMETRIC``)."""
    if geometric not in _SHADERS:
        info, iface = glass_shader_info(geometric)
        _SHADERS[geometric] = gpu.shader.create_from_info(info)
        del iface  # kept until the shader is compiled
    return _SHADERS[geometric]


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
    """The glass buffers (H, W, 4) float32, top row first: ``front``, ``back`` and their faces'
    geometric normals ``geom`` (see the module), and each glass item's ``id()`` → its id."""

    front: np.ndarray
    back: np.ndarray
    geom: np.ndarray
    ids: dict

    def textures(self) -> tuple:
        """(front, back, geom) as RGBA32F textures, row 0 at the bottom (as drawn)."""
        h, w = self.front.shape[:2]
        return tuple(
            gpu.types.GPUTexture((w, h), format="RGBA32F", data=float_buffer(a[::-1]))
            for a in (self.front, self.back, self.geom)
        )


def render_glass_buffers(
    items, view_matrix, projection_matrix, width: int, height: int
) -> GlassBuffers | None:
    """Draw the solid glass ``items`` into the glass buffers of a ``width`` × ``height`` window (the
    films' pass, the same matrices); None without solid glass. See the module."""
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
    out = {}
    offscreen = gpu.types.GPUOffScreen(int(width), int(height), format="RGBA32F")
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            for (name, cull), geometric in itertools.product(PASSES, (False, True)):
                shader = glass_shader(geometric)
                fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
                gpu.state.depth_test_set("LESS")
                gpu.state.depth_mask_set(True)
                gpu.state.blend_set("NONE")
                gpu.state.face_culling_set(cull)
                try:
                    shader.bind()
                    shader.uniform_block(layout.VIEW.name, view)
                    for item, ubo in zip(glass, ubos, strict=True):
                        shader.uniform_block(layout.OBJECT.name, ubo)
                        _batch_of(item)[0].draw(shader)
                finally:
                    gpu.state.face_culling_set("NONE")
                    gpu.state.depth_test_set("NONE")
                    gpu.state.depth_mask_set(False)
                out[name, geometric] = read_framebuffer(fb, int(width), int(height))
    finally:
        offscreen.free()
    geom = np.concatenate([out["front", True][..., :2], out["back", True][..., :2]], axis=-1)
    return GlassBuffers(out["front", False], out["back", False], geom, ids)


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
