"""The scene's colour management: OCIO display processors, the viewport's display LUT, and the
headless PNG through Blender's own save path.

Blender's display processor (``create_ocio_display_processor`` in Blender's OCIO layer) is, for
an SDR display: scene-linear in the file's working space × 2^exposure (white balance folded
into that matrix when on) → the look (``LookTransform`` into the look's process space) → the
``DisplayViewTransform`` of the display device and view → the exponent 1/gamma. :func:`processor`
builds the same chain with Blender's bundled PyOpenColorIO
(``bpy.utils.expose_bundled_modules()``) and Blender's own ``config.ocio``.

- The viewport overlay: :func:`baked_lut` bakes that processor without exposure into a
  :data:`~precompute.shading.policy.DISPLAY_LUT_SIZE`³ cube over a log shaper, with a 3 × 3
  input matrix (precompute/colour/display_lut.py, sampled per pixel by glsl/tf_display.glsl);
  exposure is applied to the scene-linear value first, in the shader.
- The headless PNG: :func:`save_png` hands the scene-linear frame to Blender
  (``Image.save_render(scene=…)``), which applies every view setting, curve mapping included.

Without PyOpenColorIO (an old Blender) the viewport keeps the Standard sRGB encoding.
"""

from __future__ import annotations

import functools
import logging
import os
import pathlib
from typing import NamedTuple

import bpy
import numpy as np

from ...precompute.colour import display_lut
from ...precompute.shading import policy
from .. import caches, workers
from ..colour_space import working_space
from ..gpu.resources import DisplayLUTTexture

log = logging.getLogger(__name__)

#: Display LUTs by :class:`DisplaySettings` (exposure left out): a handful per session.
LUTS = caches.register("display_luts", caches.LRU(8), scope=caches.SESSION)
#: Their GPU textures, by the same key.
TEXTURES = caches.register("display_lut_textures", caches.LRU(4), scope=caches.FILE)
#: The LUTs being baked in the background, by their key (:mod:`..workers`).
LUT_WORK = workers.Lane("display LUT")


class DisplaySettings(NamedTuple):
    """What the display transform of a scene depends on (hashable: the LUT cache's key)."""

    #: The blend file's working space ("Linear Rec.709", "Linear Rec.2020", "ACEScg").
    working_space: str
    #: Display device ("sRGB", "Display P3", …).
    display: str
    #: View transform ("Standard", "AgX", "Filmic", "False Color", "Khronos PBR Neutral", …).
    view: str
    #: Look ("None" or e.g. "AgX - Punchy").
    look: str
    #: Exposure in stops (applied in scene linear: × 2^exposure).
    exposure: float = 0.0
    #: Display gamma (the output is raised to 1/gamma).
    gamma: float = 1.0
    #: White balance (temperature K, tint) when the scene uses it, else None.
    white_balance: tuple[float, float] | None = None

    def without_exposure(self) -> DisplaySettings:
        """The same settings at exposure 0 (what a LUT is baked for)."""
        return self._replace(exposure=0.0)


def settings_of(scene) -> DisplaySettings:
    """The :class:`DisplaySettings` of ``scene`` (its Color Management panel, the file's working space)."""
    vs = scene.view_settings
    balance = None
    if getattr(vs, "use_white_balance", False):
        balance = (float(vs.white_balance_temperature), float(vs.white_balance_tint))
    return DisplaySettings(
        working_space(),
        scene.display_settings.display_device,
        vs.view_transform,
        vs.look or "None",
        float(vs.exposure),
        float(vs.gamma),
        balance,
    )


@functools.cache
def ocio():
    """Blender's bundled PyOpenColorIO module, or None where this Blender has none."""
    expose = getattr(bpy.utils, "expose_bundled_modules", None)
    if expose is not None:
        expose()
    try:
        import PyOpenColorIO
    except ImportError:
        return None
    return PyOpenColorIO


def config_path() -> pathlib.Path:
    """The OCIO config Blender uses: ``$OCIO`` when set, else Blender's bundled ``config.ocio``."""
    env = os.environ.get("OCIO")
    if env:
        return pathlib.Path(env)
    return pathlib.Path(bpy.utils.system_resource("DATAFILES", path="colormanagement")) / "config.ocio"


@functools.cache
def config():
    """The OCIO config (:func:`config_path`), loaded once; None without PyOpenColorIO."""
    module = ocio()
    if module is None:
        return None
    return module.Config.CreateFromFile(str(config_path()))


def processor(settings: DisplaySettings, *, exposure: bool = True):
    """The OCIO CPU processor of ``settings`` (scene linear → display), as Blender builds it.

    ``exposure=False`` leaves the exposure out (the LUT's processor). White balance and curve
    mapping are not part of it (the headless PNG has them: :func:`save_png`). ``ValueError`` naming
    the setting when the config does not know a colour space, display, view or look, or when
    PyOpenColorIO is missing.
    """
    module, cfg = ocio(), config()
    if module is None or cfg is None:
        raise ValueError("PyOpenColorIO is not available in this Blender")
    group = module.GroupTransform()
    source = settings.working_space
    scale = 2.0 ** float(settings.exposure) if exposure else 1.0
    if scale != 1.0:
        m = np.diag([scale, scale, scale, 1.0]).ravel().tolist()
        group.appendTransform(module.MatrixTransform(matrix=m))
    look = settings.look if settings.look not in ("", "None") else ""
    if look:
        found = cfg.getLook(look)
        if found is None:
            raise ValueError(f"look {look!r} is not in the OCIO config")
        space = found.getProcessSpace()
        group.appendTransform(module.LookTransform(src=source, dst=space, looks=look))
        source = space
    group.appendTransform(
        module.DisplayViewTransform(
            src=source, display=settings.display, view=settings.view, looksBypass=bool(look)
        )
    )
    if settings.gamma != 1.0:
        e = 1.0 / float(settings.gamma)
        group.appendTransform(module.ExponentTransform(value=[e, e, e, 1.0]))
    try:
        return cfg.getProcessor(group).getDefaultCPUProcessor()
    except Exception as exc:  # OCIO's own exception types: name the settings
        raise ValueError(
            f"colour management {settings.display!r} / {settings.view!r} / look {settings.look!r} "
            f"in {settings.working_space!r}: {exc}"
        ) from None


def encode(rgb, settings: DisplaySettings) -> np.ndarray:
    """Display-referred RGB in [0, 1] of scene-linear ``rgb`` (…, 3) through :func:`processor`."""
    rgb = np.asarray(rgb)
    flat = np.ascontiguousarray(rgb.reshape(-1, 3), dtype=np.float32)
    processor(settings).applyRGB(flat)
    return np.clip(flat.reshape(rgb.shape).astype(np.float64), 0.0, 1.0)


#: The input spaces a LUT may be baked over (besides the working space itself): the linear
#: gamuts of Blender's displays. :func:`baked_lut` keeps the one that follows OCIO best.
LUT_INPUT_SPACES = ("Linear Rec.709", "Linear DCI-P3 D65", "Linear Rec.2020")


def _probe() -> np.ndarray:
    """Scene-linear colours the LUT candidates are scored on (fixed: the choice is repeatable)."""
    rng = np.random.default_rng(19)
    return (np.exp2(rng.uniform(-8.0, 4.0, (4096, 1))) * rng.uniform(0.0, 1.0, (4096, 3))).astype(np.float32)


def _matrix(source: str, target: str) -> np.ndarray:
    """The 3 × 3 matrix M (x ↦ M x) of OCIO's conversion between two linear spaces."""
    basis = np.eye(3, dtype=np.float32)
    config().getProcessor(source, target).getDefaultCPUProcessor().applyRGB(basis)
    return basis.astype(np.float64).T  # row i of ``basis`` is M e_i


def _bake(cpu, matrix) -> np.ndarray:
    lattice = display_lut.lattice(policy.DISPLAY_LUT_SIZE)
    points = lattice.reshape(-1, 3) @ np.linalg.inv(matrix).T  # the lattice, back in the working space
    flat = np.ascontiguousarray(points, dtype=np.float32)
    cpu.applyRGB(flat)
    return np.clip(flat.reshape(lattice.shape), 0.0, 1.0)


def baked_lut(settings: DisplaySettings):
    """(table (N, N, N, 3) in [0, 1], input matrix (3, 3)) of ``settings`` without exposure
    (cached); None where PyOpenColorIO is missing. ``ValueError`` as :func:`processor`.

    The table is baked over the working space and over each of :data:`LUT_INPUT_SPACES` (the
    matrix takes the working space there) and the one closest to OCIO on a fixed probe of
    colours is kept (99th percentile of |Δ|): a view that clips to the display's gamut is
    exact on the cube's faces of that gamut; AgX, which maps wide gamuts, keeps the working
    space (docs/tuning.md#display-lut).
    """
    if ocio() is None:
        return None
    key = settings.without_exposure()
    found = LUTS.get(key)
    if found is None:
        cpu = processor(key, exposure=False)
        probe = _probe()
        expected = np.ascontiguousarray(probe.copy())
        cpu.applyRGB(expected)
        expected = np.clip(expected, 0.0, 1.0)
        best = None
        spaces = [key.working_space, *(s for s in LUT_INPUT_SPACES if s != key.working_space)]
        for space in spaces:
            matrix = np.eye(3) if space == key.working_space else _matrix(key.working_space, space)
            table = _bake(cpu, matrix)
            error = float(np.percentile(np.abs(display_lut.apply(table, probe, 0.0, matrix) - expected), 99))
            if best is None or error < best[0]:
                best = (error, table, matrix)
        found = LUTS[key] = (best[1], best[2])
    return found


def _set_image_settings(settings, values: dict) -> dict:
    """Set ``values`` on ``scene.render.image_settings``; returns the previous values."""
    saved = {name: getattr(settings, name) for name in values if hasattr(settings, name)}
    for name, value in values.items():
        if hasattr(settings, name):
            setattr(settings, name, value)
    return saved


def save_png(path, rgba, scene) -> None:
    """Write the scene-linear frame ``rgba`` (H, W, 4, premultiplied, top row first, in the
    working space) as an 8-bit RGBA PNG through Blender's own colour management
    (``Image.save_render(scene=…)``: the scene's display, view, look, exposure, gamma, white
    balance and curves)."""
    rgba = np.asarray(rgba, dtype=np.float32)
    h, w = rgba.shape[:2]
    image = bpy.data.images.new("thinfilm_sh_frame", w, h, alpha=True, float_buffer=True)
    settings = scene.render.image_settings
    saved = {}
    try:
        image.colorspace_settings.name = working_space()
        image.alpha_mode = "PREMUL"  # the frame is premultiplied, as an EXR is
        image.pixels.foreach_set(np.ascontiguousarray(rgba[::-1]).ravel())
        saved = _set_image_settings(
            settings, {"media_type": "IMAGE", "file_format": "PNG", "color_mode": "RGBA", "color_depth": "8"}
        )
        image.save_render(str(path), scene=scene)
    finally:
        # file_format before media_type: each setter validates against the other
        for name in ("media_type", "file_format", "color_mode", "color_depth"):
            if name in saved:
                try:
                    setattr(settings, name, saved[name])
                except (TypeError, ValueError):  # a combination only the other order accepts
                    pass
        bpy.data.images.remove(image)


def _bake_worker(key: DisplaySettings) -> None:
    try:
        baked_lut(key)
    except Exception as exc:  # a look or view the config lacks: the Standard encoding stays
        log.error("Thin Film SH: display transform: %s", exc)
        LUTS[key] = None


def viewport_lut(settings: DisplaySettings) -> DisplayLUTTexture | None:
    """The display LUT texture of ``settings`` for the viewport's draw; never slow.

    On a miss its LUT is baked on a background thread (OCIO, about a second the first time) and
    None is returned: the overlay draws the Standard sRGB encoding until then (poll
    :func:`baking` and :func:`take_finished` from a timer to redraw). None as well where
    PyOpenColorIO is missing or the settings cannot be processed (logged once).
    """
    key = settings.without_exposure()
    texture = TEXTURES.get(key)
    if texture is not None:
        return texture
    if key in LUTS:
        found = LUTS[key]
        if found is None:
            return None
        texture = TEXTURES[key] = DisplayLUTTexture.from_table(*found)
        return texture
    if ocio() is None:
        return None
    with LUT_WORK.lock:
        if key not in LUT_WORK.running:
            LUT_WORK.start(workers.Job(key, _bake_worker, key))
    return None


def baking() -> bool:
    """Whether a display LUT is being baked in the background."""
    return LUT_WORK.busy()


def take_finished() -> bool:
    """Whether a background LUT bake finished since the last call (then the viewport redraws)."""
    return LUT_WORK.take_finished()
