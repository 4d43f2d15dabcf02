"""The rest of the scene, rendered by Blender: the background pass of the headless frame.

:func:`render_background` renders the scene through its camera with EEVEE (or Workbench or
Cycles) while the thin-film objects are invisible to the camera (``visible_camera`` off: they
still cast shadows and show in reflections), and returns its scene-linear RGBA and its depth
(view-space distance along the camera axis, the render's Z pass). The headless frame then draws
the films over it, depth-tested against that depth (:func:`composite`): outside the films the
frame is Blender's own render, pixel for pixel.

Every setting the pass changes (engine, resolution, output format, the Z pass, the films'
camera visibility) is restored afterwards, also when the render fails.
"""

from __future__ import annotations

import contextlib
import dataclasses
import pathlib
import tempfile
from dataclasses import dataclass

import bpy
import numpy as np

from ...precompute.optics.caustics import GlassOptics, plain_glass
from ...precompute.output import pixel_filter
from ...precompute.shading.policy import REFRACT_MAX_SIDE, REFRACT_OVERSCAN
from ...precompute.shading.transmit import WALL_SOLID
from ..gpu.draw import is_wall, render_offscreen
from ..gpu.glass_buffers import film_texture, render_glass_buffers, solid_glass
from ..gpu.resources import BehindTexture
from . import caustics
from .background_lamps import glass_shadows, world_lamps_as_suns
from .caustics import back_film

#: ``--engine`` → Blender's render engine identifier.
ENGINES = {"EEVEE": "BLENDER_EEVEE", "WORKBENCH": "BLENDER_WORKBENCH", "CYCLES": "CYCLES"}
#: The Z pass where nothing was hit (Blender writes 1e10).
FAR = 1e9


@dataclass
class Background:
    """A background pass: scene-linear RGBA (H, W, 4, premultiplied, top row first) in the
    working space, and depth (H, W): distance along the camera axis, ``inf`` where nothing is."""

    rgba: np.ndarray
    depth: np.ndarray
    engine: str
    seconds: float = 0.0
    #: Pixels rendered beyond the frame on each side (:func:`render_background`'s ``margin``), and
    #: the whole render with them (RGBA, depth), which solid glass refracts; None without.
    margin: int = 0
    wide: tuple | None = None


@contextlib.contextmanager
def _changed(pairs):
    """Set ``(owner, attribute, value)`` triples; restore them in reverse order on exit."""
    saved = []
    try:
        for owner, name, value in pairs:
            saved.append((owner, name, getattr(owner, name)))
            setattr(owner, name, value)
        yield
    finally:
        for owner, name, value in reversed(saved):
            try:
                setattr(owner, name, value)
            except (TypeError, ValueError, AttributeError):  # an enum the other setting refuses
                pass


def _read_layers(path, extra: bool = False) -> tuple:
    """(RGBA, Z) of a multilayer EXR Blender wrote (OpenEXR where installed, else OpenImageIO);
    with ``extra`` also (world normals, diffuse colour), each (H, W, 3)."""
    try:
        import OpenEXR
    except ImportError:
        OpenEXR = None
    channels = {}
    if OpenEXR is not None:
        with OpenEXR.File(str(path), separate_channels=True) as f:
            for part in f.parts:
                for name, channel in part.channels.items():
                    channels[name] = np.array(channel.pixels, dtype=np.float64)
    else:
        import OpenImageIO as oiio

        image = oiio.ImageInput.open(str(path))
        if image is None:
            raise OSError(f"{path}: {oiio.geterror()}")
        try:
            sub = 0
            while image.seek_subimage(sub, 0):
                pixels = image.read_image("float")
                for i, name in enumerate(image.spec().channelnames):
                    channels[name] = np.array(pixels[..., i], dtype=np.float64)
                sub += 1
        finally:
            image.close()

    def find(suffix):
        for name, pixels in channels.items():
            if name.endswith(suffix):
                return pixels
        raise OSError(f"{path}: no {suffix} channel in the background pass ({sorted(channels)})")

    rgba = np.stack([find(f"Combined.{c}") for c in "RGBA"], axis=-1)
    if not extra:
        return rgba, find("Depth.Z")
    normals = np.stack([find(f"Normal.{c}") for c in "XYZ"], axis=-1)
    albedo = np.stack([find(f"Diffuse Color.{c}") for c in "RGB"], axis=-1)
    return rgba, find("Depth.Z"), normals, albedo


def _overscan(scene, width: int, height: int, margin: int) -> list:
    """The settings that widen the camera's picture by ``margin`` pixels on each side, its pixels
    unchanged: the resolution, and the sensor (or orthographic scale) and shift scaled by the
    fitted side's growth. Panoramic cameras are not widened."""
    cam = scene.camera.data if scene.camera is not None else None
    if margin <= 0 or cam is None or cam.type == "PANO":
        return []
    side = {"HORIZONTAL": width, "VERTICAL": height}.get(cam.sensor_fit, max(width, height))
    grow = (side + 2.0 * margin) / side
    changes = [(cam, "shift_x", cam.shift_x / grow), (cam, "shift_y", cam.shift_y / grow)]
    if cam.type == "ORTHO":
        return changes + [(cam, "ortho_scale", cam.ortho_scale * grow)]
    return changes + [
        (cam, "sensor_width", cam.sensor_width * grow),
        (cam, "sensor_height", cam.sensor_height * grow),
    ]


def render_background(
    scene,
    width: int,
    height: int,
    *,
    engine: str = "EEVEE",
    hidden=(),
    shadowless=(),
    transparent: bool = False,
    margin: int = 0,
    world=None,
    glass=None,
    messages=None,
) -> Background:
    """Render ``scene`` through its camera with ``engine`` (:data:`ENGINES`) at ``width`` ×
    ``height``, the objects named in ``hidden`` invisible to the camera, those in ``shadowless``
    casting no shadow either (transparent films, :func:`wall_objects`; not with Cycles, which
    traces light through them: their shadows and caustics on the ground); see the module.

    ``transparent``: the World is left out of the picture (film transparent; it still lights).
    ``margin``: render that many pixels more on each side (the camera widened, its pixels
    unchanged; not for panoramic cameras): the frame is the middle, the whole is ``wide``, what
    solid glass refracts beyond the frame's edges.
    ``world``: the World's panorama (radiance, world frame, top row first) or None; with EEVEE its
    lamps light the pass as sun lights (:func:`.background_lamps.world_lamps_as_suns`), as Cycles
    lights it, where None leaves EEVEE's own World lighting.
    ``glass``: {object name: relative index η or :class:`~precompute.optics.caustics.GlassOptics`}
    of solid glass (:func:`.caustics.glass_optics`), EEVEE only: where every light can be traced
    (:func:`.caustics.applies`: suns, and point, spot and area lights outside the glass) it casts
    EEVEE's opaque shadow and the lights' light through and off it is traced and added
    (:func:`.caustics.light_caustics`, its note appended to ``messages``); else the straight
    shadow through glass, 1 − F per face.
    """
    import time

    _check_engine(engine)
    render = scene.render
    layer = bpy.context.view_layer
    glass = dict(glass or {}) if engine == "EEVEE" else {}
    optics = {name: v if isinstance(v, GlassOptics) else plain_glass(float(v)) for name, v in glass.items()}
    etas = {name: o.eta for name, o in optics.items()}
    # Cycles traces the light through a film's own material (its shadow and caustics): only the
    # rasterisers' opaque shadow of a film is wrong (wall_objects)
    shadowless = set() if engine == "CYCLES" else set(shadowless) - set(glass)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="thinfilm_sh_bg_") as folder:
        path = pathlib.Path(folder) / "background.exr"
        changes = [
            *_overscan(scene, width, height, margin),
            *_pass_settings(scene, engine, (int(width) + 2 * margin, int(height) + 2 * margin), path),
            (render, "film_transparent", bool(transparent) or render.film_transparent),
            *_pass_visibility(hidden, shadowless),
        ]
        caustic = bool(etas) and caustics.applies(scene, etas)
        if caustic:
            changes += [(layer, "use_pass_normal", True), (layer, "use_pass_diffuse_color", True)]
        suns = world_lamps_as_suns(scene, world if engine == "EEVEE" else None)
        with _changed(changes), suns, glass_shadows(etas, opaque=caustic):
            bpy.ops.render.render(write_still=True, scene=scene.name, layer=layer.name)
            if caustic:
                rgba, z, normals, albedo = _read_layers(path, extra=True)
                depth = np.where(z >= FAR, np.inf, z)
                light = caustics.light_caustics(
                    scene, optics, depth, normals, albedo, skip=shadowless, messages=messages
                )
                rgba = rgba.copy()
                rgba[..., :3] += light * np.clip(rgba[..., 3:4], 0.0, 1.0)
            else:
                rgba, z = _read_layers(path)
    depth = np.where(z >= FAR, np.inf, z)
    m = margin if depth.shape == (height + 2 * margin, width + 2 * margin) else 0  # a panorama: none
    crop = (slice(m, m + height), slice(m, m + width))
    wide = (rgba, depth) if m else None
    return Background(rgba[crop], depth[crop], engine, time.perf_counter() - t0, m, wide)


def _pass_settings(scene, engine: str, size: tuple, path) -> list:
    """The render settings of a pass by ``engine`` of ``size`` (w, h) pixels written to ``path``
    (a 32-bit multilayer EXR with its Z pass), as :func:`_changed` triples."""
    render = scene.render
    settings = render.image_settings
    return [
        (render, "engine", ENGINES[engine]),
        (render, "resolution_x", int(size[0])),
        (render, "resolution_y", int(size[1])),
        (render, "resolution_percentage", 100),
        (render, "use_border", False),
        (render, "filepath", str(path)),
        (render, "use_file_extension", False),
        (settings, "media_type", "MULTI_LAYER_IMAGE"),
        (settings, "file_format", "OPEN_EXR_MULTILAYER"),
        (settings, "color_depth", "32"),
        (bpy.context.view_layer, "use_pass_z", True),
    ]


def _check_engine(engine: str) -> None:
    """A ValueError naming the engines where ``engine`` is none of :data:`ENGINES`."""
    if engine not in ENGINES:
        raise ValueError(f"--engine must be one of {', '.join(ENGINES)}, got {engine!r}")


def _pass_visibility(hidden, shadowless) -> list:
    """The objects named in ``hidden`` hidden from the pass's camera, those also named in
    ``shadowless`` casting no shadow, as :func:`_changed` triples."""
    objects = [bpy.data.objects[name] for name in sorted(set(hidden)) if name in bpy.data.objects]
    return [
        *((obj, "visible_camera", False) for obj in objects),
        *((obj, "visible_shadow", False) for obj in objects if obj.name in shadowless),
    ]


def render_views(scene, size: int, cameras, *, engine="EEVEE", hidden=(), shadowless=(), world=None) -> list:
    """[(RGBA, depth), …] of ``scene`` seen by its camera placed at each of the ``cameras``
    (4 × 4 world matrices, mathutils) in turn, ``size``² pixels each, as one setup of
    :func:`render_background` (the World's lamps as suns, the objects named in ``hidden`` and
    ``shadowless``; no overscan, no caustics): the suns and the settings are made once, not per
    view (addon/headless/probe.py's six views)."""
    _check_engine(engine)
    shadowless = set() if engine == "CYCLES" else set(shadowless)
    out = []
    with tempfile.TemporaryDirectory(prefix="thinfilm_sh_bg_") as folder:
        path = pathlib.Path(folder) / "view.exr"
        changes = [*_pass_settings(scene, engine, (size, size), path), *_pass_visibility(hidden, shadowless)]
        layer = bpy.context.view_layer
        with _changed(changes), world_lamps_as_suns(scene, world if engine == "EEVEE" else None):
            for matrix in cameras:
                scene.camera.matrix_world = matrix
                bpy.ops.render.render(write_still=True, scene=scene.name, layer=layer.name)
                rgba, z = _read_layers(path)
                out.append((rgba, np.where(z >= FAR, np.inf, z)))
    return out


def view_depth(ndc_depth, projection) -> np.ndarray:
    """Distance along the camera axis of a depth buffer's values (window depth in [0, 1]);
    ``inf`` where the buffer is still cleared (1)."""
    p = np.asarray(projection, dtype=np.float64)
    d = np.asarray(ndc_depth, dtype=np.float64)
    ndc = 2.0 * d - 1.0
    if p[3, 3] == 1.0 and p[3, 2] == 0.0:  # orthographic: ndc = P22 z + P23, distance = −z
        dist = -(ndc - p[2, 3]) / p[2, 2]
    else:  # perspective: ndc = (P22 z + P23) / (−z)
        dist = p[2, 3] / (ndc + p[2, 2])
    return np.where(d >= 1.0, np.inf, dist)


def composite(
    background: Background,
    films,
    film_depth,
    kind: str,
    width: float,
    factor: int,
    pad: int,
    transmit=None,
    hole_depth=None,
):
    """The final frame (H, W, 4): the films over the background, depth-tested per sample.

    ``films`` (H', W', 4) and ``film_depth`` (H', W', distance along the camera axis) are the
    films' pass at ``factor`` samples per pixel over the window widened by ``pad`` pixels; a
    sample shows its film where the film is nearer than the background's depth (the nearest
    background pixel's). ``transmit`` (H', W', 3) or None: what each sample lets through of what
    is behind (:func:`film_layers`: T of transparent films, 0 under an opaque film, 1 where no
    film is); None: 0 wherever a film shows. Film colour and transmittance are filtered down with
    the pixel filter (``kind``, ``width``) and laid over the background:
    C = C_film + T C_background, α = 1 − (1 − α_background) mean T. Where no film sample shows,
    the frame is the background exactly. ``hole_depth`` (H', W') or None: the depth of holdout
    films; where one is the nearest surface the sample is transparent black (C = 0, α = 0), as
    Blender renders a holdout.
    """
    h, w = background.depth.shape
    rows = np.clip((np.arange(films.shape[0]) // factor) - pad, 0, h - 1)
    cols = np.clip((np.arange(films.shape[1]) // factor) - pad, 0, w - 1)
    behind = background.depth[np.ix_(rows, cols)]
    hole = np.zeros(film_depth.shape + (1,), dtype=bool)
    if hole_depth is not None:
        hole = ((hole_depth < behind) & (hole_depth < film_depth))[..., None]
    shown = ((films[..., 3] > 0.0) & (film_depth < behind))[..., None] & ~hole
    through = np.where(shown | hole, 0.0 if transmit is None else transmit, 1.0) * np.ones(3)
    through = np.where(hole, 0.0, through)
    layer = np.concatenate([films[..., :3] * shown, through, hole], axis=-1)
    if factor > 1:
        layer = pixel_filter.downsample(layer, kind, width, factor, pad)
    through = np.clip(layer[..., 3:6], 0.0, 1.0)
    holes = np.clip(layer[..., 6:7], 0.0, 1.0)
    out = np.empty_like(background.rgba)
    out[..., :3] = layer[..., :3] + through * background.rgba[..., :3]
    alpha = 1.0 - through.mean(axis=-1, keepdims=True) * (1.0 - background.rgba[..., 3:]) - holes
    out[..., 3:] = np.clip(alpha, 0.0, 1.0)
    return out


def film_layers(items, view, proj, width: int, height: int, behind=None):
    """The films' pass for :func:`composite`: (colour over black (H, W, 4), transmittance (H, W, 3)
    or None, window depth (H, W)).

    Opaque films only: one render, no transmittance. With transparent films (walls,
    :func:`.gpu.draw.is_wall`) the frame behind them is linear in what they composite over
    (multiply by T, then add R·L, back walls then front): so rendered once over black and once
    over white, T = white − black per channel, exactly; their depth (they write none) comes from
    a third render of the walls drawn as opaque surfaces. ``behind`` (a
    :class:`.gpu.resources.BehindTexture` of the background pass, or None): what solid glass
    refracts (its T is 0: the refracted scene is part of its colour); the solid glass's faces are
    drawn into its glass buffers first (:func:`.gpu.glass_buffers.render_glass_buffers`), so the
    glass refracts out through its real surface.
    """
    if behind is not None:
        buffers = render_glass_buffers(items, view, proj, width, height)
        if buffers is not None:
            behind.front, behind.back, behind.geom = buffers.textures()
            behind.ids = buffers.ids
            behind.film = film_texture([back_film(item) for item in solid_glass(items)])
    black, depth = render_offscreen(items, view, proj, width, height, with_depth=True, behind=behind)
    if not any(is_wall(item) for item in items):
        return black, None, depth
    white = render_offscreen(items, view, proj, width, height, clear=(1.0, 1.0, 1.0, 1.0), behind=behind)
    solid = [dataclasses.replace(item, wall=None) if is_wall(item) else item for item in items]
    _, wall_depth = render_offscreen(solid, view, proj, width, height, with_depth=True)
    transmit = np.clip(white[..., :3].astype(np.float64) - black[..., :3], 0.0, 1.0)
    return black, transmit, np.minimum(depth, wall_depth)


def wall_objects(items) -> set:
    """The objects of transparent films (:func:`.gpu.draw.is_wall`): hidden from the background
    pass's camera, they cast no shadow in it either (solid glass under EEVEE casts the lamps'
    shadow through glass instead, :func:`render_background`'s ``glass``; a Cycles pass keeps
    every film's shadow,
    :func:`render_background`). EEVEE's shadow of a glass ball or a bubble is that of an opaque
    object; Cycles' lets most light through, bent into caustics. The glass benchmark
    (docs/transparent-films.md#figures): mean ΔE2000 over the ball 4.50 with EEVEE's opaque
    shadows, 3.93 without; over the ground around it 5.11 and 3.35."""
    return {item.name.split("/")[0] for item in items if is_wall(item)}


def refraction_margin(items, width: int, height: int) -> int:
    """Pixels of overscan the background pass needs on each side (:func:`render_background`'s
    ``margin``): policy.REFRACT_OVERSCAN of the frame's longer side where an item is solid
    glass, else 0; the pass's longer side kept within policy.REFRACT_MAX_SIDE."""
    if not any(is_wall(item) and int(item.wall[0]) == WALL_SOLID for item in items):
        return 0
    side = max(int(width), int(height))
    return max(0, min(int(round(REFRACT_OVERSCAN * side)), (REFRACT_MAX_SIDE - side) // 2))


def behind_texture(background: Background, items, pad: int) -> BehindTexture | None:
    """The background pass as the texture solid glass refracts (its colour and depth, placed in
    the films' window widened by ``pad`` pixels), or None when no item is solid glass."""
    if not any(is_wall(item) and int(item.wall[0]) == WALL_SOLID for item in items):
        return None
    rgba, depth = background.wide if background.wide is not None else (background.rgba, background.depth)
    h, w = background.depth.shape
    screen = BehindTexture.screen(w, h, pad, background.margin)
    return BehindTexture.from_image(rgba[..., :3], depth, screen)
