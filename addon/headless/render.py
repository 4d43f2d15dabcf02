"""The headless frame: the scene camera's view with the thin-film shader, off-screen.

:func:`render_scene` draws the scene camera's view into a float off-screen buffer with the same
collection and draw code as the viewport: the rest of the scene first (Blender's own Solid
drawing, for depth and for the objects we don't shade, or an engine's render,
:mod:`.background`), then the World as background, then every thin-film object, depth-tested.
Writes a scene-linear RGBA EXR in the file's working space (with its chromaticities) and an RGBA
PNG through Blender's own colour management of the scene (:func:`..drawing.display.save_png`:
display, view, look, exposure, gamma).

The frame is anti-aliased as Cycles' is: drawn :data:`SUPERSAMPLE` times larger (over a window
widened by the filter's support, so border pixels see beyond the frame) and filtered down with
the scene's Cycles pixel filter, type and width (``scene.cycles.pixel_filter_type`` /
``filter_width``; Cycles' defaults, Blackman–Harris of ±1.5 px, without the Cycles add-on):
:func:`pixel_filter_settings`, :mod:`precompute.output.pixel_filter`. The viewport keeps Blender's own
anti-aliasing.
"""

from __future__ import annotations

import dataclasses
import pathlib
import time

import bpy
import numpy as np
from mathutils import Matrix

from ...precompute.output import image_io, pixel_filter
from ...precompute.shading.policy import PROBE_FACE
from ..colour_space import working_space
from ..drawing import display, scene_draw
from ..gpu.context import ensure_gpu_context
from ..gpu.draw import render_offscreen
from ..ui import prefs
from ..world import world_state
from . import cli_args
from .background import (
    behind_texture,
    composite,
    film_layers,
    refraction_margin,
    render_background,
    view_depth,
    wall_objects,
)
from .caustics import glass_optics
from .probe import glass_centre, render_probe

#: The background engines the scene probe is rendered with (:func:`_probe`).
PROBE_ENGINES = ("EEVEE", "CYCLES")
#: The message of a render made while the *Show Thin Film Overlay* preference is off.
OVERLAY_OFF = "the Show Thin Film Overlay preference is off: no thin film is drawn"


def _hidden_in_render(item) -> bool:
    """Whether a draw item's object is ``hide_render`` (the viewport's depsgraph still lists it)."""
    obj = bpy.data.objects.get(item.name.split("/")[0])
    return obj is not None and obj.hide_render


def holdout_objects(view_layer) -> set:
    """Names of the objects ``view_layer`` renders as holdouts: the object's own *Holdout*
    (``is_holdout``) or a holdout collection of the view layer (``LayerCollection.holdout``)."""
    names = {o.name for o in view_layer.objects if o.is_holdout}
    stack = [view_layer.layer_collection]
    while stack:
        layer = stack.pop()
        if layer.holdout and not layer.exclude:
            names.update(o.name for o in layer.collection.all_objects)
        stack.extend(layer.children)
    return names


def _films_over(behind, items, view, proj, size, sampling, messages, probe=None):
    """The final frame over the background pass ``behind``: the films' layers (opaque, walls)
    depth-tested and filtered over it, holdout films cutting transparent holes (:func:`holdout_objects`);
    (RGBA, non-finite samples zeroed). ``size``: the films' pass (w, h); ``sampling``: (filter
    kind, width, supersampling factor, pad); ``probe``: the scene around solid glass
    (:class:`.probe.Probe`) or None."""
    ensure_gpu_context()
    holdouts = holdout_objects(bpy.context.view_layer)
    hole_items = [  # drawn as opaque surfaces: only their depth is used
        dataclasses.replace(item, wall=None) for item in items if item.name.split("/")[0] in holdouts
    ]
    items = [item for item in items if item.name.split("/")[0] not in holdouts]
    refracted = behind_texture(behind, items, sampling[3])
    if refracted is not None and probe is not None:
        refracted.with_probe(probe.image, probe.centre)
    films, transmit, depth = film_layers(items, view, proj, *size, behind=refracted)
    films, nonfinite = _finite(films.astype(np.float64), messages)
    holes = None
    if hole_items:  # holdout films cut a transparent hole where they are in front
        holes = view_depth(render_offscreen(hole_items, view, proj, *size, with_depth=True)[1], proj)
    return composite(behind, films, view_depth(depth, proj), *sampling, transmit, holes), nonfinite


def _view3d_for_depth():
    """A VIEW_3D space and WINDOW region from any screen (available in background mode)."""
    for screen in bpy.data.screens:
        for area in screen.areas:
            if area.type == "VIEW_3D":
                region = next((r for r in area.regions if r.type == "WINDOW"), None)
                if region is not None:
                    return area.spaces.active, region
    return None, None


def camera_matrices(scene, depsgraph, width: int, height: int):
    """View and projection matrices of the scene's camera for a *width* × *height* frame."""
    cam = scene.camera
    if cam is None:
        raise ValueError(f"scene '{scene.name}' has no camera: set one to render")
    view = np.array(cam.matrix_world.inverted(), dtype=np.float64)
    proj = np.array(cam.calc_matrix_camera(depsgraph, x=width, y=height), dtype=np.float64)
    return view, proj


#: Samples per pixel along each axis of the headless frame (4 × 4 per pixel), filtered with the
#: scene's pixel filter. Against Cycles (issue 22's spheres under studio HDRIs) 4× lowered the
#: mean ΔE2000 from 1.36 to 1.20 (edges, lamp highlights and reflected detail alias without).
SUPERSAMPLE = cli_args.SUPERSAMPLE


def pixel_filter_settings(scene) -> tuple[str, float]:
    """The scene's Cycles pixel filter (type, width in pixels), Cycles' defaults without the add-on."""
    cycles = getattr(scene, "cycles", None)
    kind = getattr(cycles, "pixel_filter_type", pixel_filter.DEFAULT_FILTER)
    width = float(getattr(cycles, "filter_width", pixel_filter.DEFAULT_WIDTH))
    if kind not in pixel_filter.FILTERS:
        kind = pixel_filter.DEFAULT_FILTER
    return kind, width


def widened_projection(projection, width: int, height: int, pad: int) -> np.ndarray:
    """The projection of the window ``pad`` pixels wider on each side: the frame's pixel grid
    continues outside it (NDC scaled by W/(W + 2 pad) and H/(H + 2 pad))."""
    scale = np.diag([width / (width + 2.0 * pad), height / (height + 2.0 * pad), 1.0, 1.0])
    return scale @ np.asarray(projection, dtype=np.float64)


def _max_texture_size() -> int:
    import gpu

    try:
        return int(gpu.capabilities.max_texture_size_get())
    except (AttributeError, SystemError):
        return 16384


def render_scene(
    scene,
    out_path,
    width: int | None = None,
    height: int | None = None,
    background: bool = True,
    supersample: int | None = None,
    engine: str | None = None,
    scene_probe: bool = True,
) -> dict:
    """Render the camera view with the thin-film shader; writes ``out_path`` (.png) and a .exr beside it.

    ``supersample``: samples per pixel along each axis (default :data:`SUPERSAMPLE`; lowered when
    the enlarged buffer would exceed the GPU's texture size), filtered with the scene's Cycles
    pixel filter; 1 draws one sample per pixel, unfiltered.

    ``engine`` ("EEVEE", "WORKBENCH", "CYCLES"): the rest of the scene is that engine's render
    (:func:`.background.render_background`, the films invisible to its camera) and the films
    are drawn over it, depth-tested per sample (:func:`.background.composite`); ``background``
    False makes its film transparent. None: Blender's Solid drawing and the World's panorama
    behind the films (the preview's look, what the tests' reference images hold).
    ``scene_probe``: where the frame has solid glass, render the scene around it for the paths
    that leave the picture (:func:`.probe.render_probe`); False: they see the World.
    """
    ensure_gpu_context()
    scale = scene.render.resolution_percentage / 100.0
    width = int(width or round(scene.render.resolution_x * scale))
    height = int(height or round(scene.render.resolution_y * scale))
    depsgraph = bpy.context.evaluated_depsgraph_get()
    view, proj = camera_matrices(scene, depsgraph, width, height)
    kind, filter_width = pixel_filter_settings(scene)
    factor = max(1, int(SUPERSAMPLE if supersample is None else supersample))
    pad = pixel_filter.margin(kind, filter_width) if factor > 1 else 0
    limit = _max_texture_size()
    while factor > 1 and factor * (max(width, height) + 2 * pad) > limit:
        factor -= 1
    if factor == 1:
        pad = 0
    proj = widened_projection(proj, width, height, pad)
    frame_w, frame_h = factor * (width + 2 * pad), factor * (height + 2 * pad)
    t0 = time.perf_counter()
    errors: dict[str, str] = {}  # materials drawn as the magenta fallback, and why
    if prefs.overlay_enabled():
        items, messages = scene_draw.collect(depsgraph, allow_bake=True, allow_world=True, errors=errors)
        items = [item for item in items if not _hidden_in_render(item)]
    else:  # the artist's off switch holds for renders too: Blender's own drawing only
        items, messages = [], [OVERLAY_OFF]
    env = None
    lighting = world_state.current()
    if background and lighting is not None and lighting.environment is not None:
        env = lighting.background()  # the panorama the split sum was prefiltered from, turned and scaled
    space, region = _view3d_for_depth()

    film_objects = {item.name.split("/")[0] for item in items}

    def depth_from(offscreen):
        """Blender's Solid drawing of everything else, for depth and for the other objects.

        Thin-film objects and ``hide_render`` objects are hidden during it (film objects: drawn
        twice, Blender's and our vertex transforms round differently and the depth test would let
        the grey Solid surface speckle through). Instances of excluded collections are not in the
        view layer and cannot be hidden: they stay in this pass.
        """
        if space is None:
            return
        shading = space.shading
        saved = (shading.type, shading.light, shading.color_type)
        layer_objects = bpy.context.view_layer.objects  # instances from excluded collections are not
        hidden = [o for o in layer_objects if (o.name in film_objects or o.hide_render) and not o.hide_get()]
        try:
            for o in hidden:
                o.hide_set(True)
            bpy.context.view_layer.update()  # draw_view3d reads the evaluated depsgraph
            shading.type, shading.light, shading.color_type = "SOLID", "STUDIO", "MATERIAL"
            offscreen.draw_view3d(
                scene,
                bpy.context.view_layer,
                space,
                region,
                _mathutils_matrix(view),
                _mathutils_matrix(proj),
                do_color_management=False,
            )
        finally:
            shading.type, shading.light, shading.color_type = saved
            for o in hidden:
                o.hide_set(False)
            if hidden:
                bpy.context.view_layer.update()

    if engine is None:
        rgba = render_offscreen(items, view, proj, frame_w, frame_h, background=env, depth_from=depth_from)
        rgba, nonfinite = _finite(rgba.astype(np.float64), messages)
        if factor > 1:
            rgba = pixel_filter.downsample(rgba, kind, filter_width, factor, pad)
    else:
        behind = render_background(
            scene,
            width,
            height,
            engine=engine,
            hidden=film_objects,
            shadowless=wall_objects(items),
            transparent=not background,
            margin=refraction_margin(items, width, height),
            world=lighting.background() if lighting is not None else None,
            glass=glass_optics(items, messages),
            messages=messages,
        )
        around = _probe(scene, items, engine, film_objects, lighting, messages) if scene_probe else None
        rgba, nonfinite = _films_over(
            behind, items, view, proj, (frame_w, frame_h), (kind, filter_width, factor, pad), messages, around
        )
    out = pathlib.Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    space = working_space()
    display.ocio()  # exposes Blender's bundled modules: OpenImageIO writes the EXR inside Blender
    image_io.write_exr(out.with_suffix(".exr"), rgba, image_io.CHROMATICITIES.get(space))
    display.save_png(out.with_suffix(".png"), rgba, scene)
    return {
        "png": str(out.with_suffix(".png")),
        "exr": str(out.with_suffix(".exr")),
        "size": [width, height],
        "supersample": factor,
        "pixel_filter": [kind, filter_width] if factor > 1 else None,
        "engine": engine or "SOLID",
        "objects": [item.name for item in items if not item.fallback],
        "fallback_objects": [item.name for item in items if item.fallback],
        "errors": errors,
        "world_errors": list(lighting.sh.errors) if lighting is not None else [],
        "nonfinite_pixels": nonfinite,
        "working_space": space,
        "view_transform": scene.view_settings.view_transform,
        "messages": messages,
        "seconds": time.perf_counter() - t0,
    }


def _probe(scene, items, engine, film_objects, lighting, messages):
    """The scene around the frame's solid glass (:func:`.probe.render_probe` at their centre),
    or None where there is none or the engine is Workbench (which draws the objects hidden from
    its camera: the probe would see the glass); its time noted in ``messages``."""
    centre = glass_centre(items)
    if centre is None or engine not in PROBE_ENGINES:
        return None
    try:
        around = render_probe(
            scene,
            centre,
            engine=engine,
            hidden=film_objects,
            shadowless=film_objects,  # the glass too: its light through to the floor is not traced here
            world=lighting.background() if lighting is not None else None,
        )
    except RuntimeError as error:  # the frame is still drawn, its paths off the picture seeing the World
        messages.append(f"scene probe not rendered ({error}): paths that leave the picture see the World")
        return None
    messages.append(f"scene probe: six {PROBE_FACE}² views from the glass's centre, {around.seconds:.1f} s")
    return around


def _finite(rgba, messages) -> tuple[np.ndarray, int]:
    """``rgba`` with non-finite samples set to 0 (counted in ``messages``), and their count."""
    bad = ~np.isfinite(rgba)
    count = int(bad.any(axis=-1).sum())
    if count:
        messages.append(f"{count} non-finite samples set to 0")
        rgba = np.where(bad, 0.0, rgba)
    return rgba, count


def _mathutils_matrix(m):
    return Matrix(np.asarray(m).tolist())
