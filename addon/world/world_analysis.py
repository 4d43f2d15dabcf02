"""The World's lighting for the draw: its content analysed once, its parameters applied per edit.

A World is *content* (an Environment Texture's pixels, a procedural World's panorama, a colour:
what :func:`.world_params.world_parts`' content key covers) and *parameters* (the Background's
Strength, the Mapping's rotation: :class:`.world_params.WorldParams`). The content's analysis is slow
and runs on a worker thread in the viewport (:mod:`.world_job`); the parameters are applied in
milliseconds on the main thread, so a Strength or rotation edit recomputes nothing:

- :func:`analyse_content` (any thread, pure numpy): the content's SH (:func:`.world.analyse_read`),
  a 512 × 256 panorama of it, its lamps and their SH (:func:`precompute.world.environment.analyse_world`);
- :meth:`Analysed.compute` (any thread): one prefilter (the whole World, or the World with its
  lamps lifted out), resampled to the GPU texture's size in float32; only those a drawn material
  reads;
- :func:`lighting_from` (main thread): the :class:`WorldLighting` of the content under the
  parameters: the SH turned and scaled (:func:`.world.finish`), the lamps turned and scaled
  (:func:`world_lamps`), and the prefilter looked up through the parameters by the shader
  (``tf_lighting.world``: :meth:`.gpu.resources.Lighting.from_sh`). The prefilter textures are
  uploaded on first use (:class:`PrefilterTextures`) and shared by every parameter of a content.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import numpy as np

from ...precompute.materials.material import MAX_SH_ORDER
from ...precompute.world import hdri, prefilter
from ...precompute.world.environment import Environment, analyse_world
from ...precompute.world.lamps import Lamps
from ..gpu import layout, resources
from . import world, world_params

__all__ = [
    "LIFTED",
    "PANORAMA_WIDTH",
    "PREFILTER_WIDTH",
    "WHOLE",
    "Analysed",
    "PrefilterTextures",
    "WorldLighting",
    "analyse_content",
    "lighting_from",
    "world_lamps",
]

#: Panorama size for the split sum's prefilter and the headless background.
PANORAMA_WIDTH = 512
#: Width of the prefilter texture: level 0 is the panorama itself.
PREFILTER_WIDTH = prefilter.LEVEL_WIDTH
#: The narrowest width the prefilter's sharpest levels are filtered at (a tiny source image).
_POW2_MIN = 64
#: The prefilter with the lamps lifted out (lamp-shaded glossy films).
LIFTED = "lifted"
#: The prefilter of the whole World (glossy films the lamps do not apply to).
WHOLE = "whole"


def _equirect(image: np.ndarray, width: int) -> np.ndarray:
    """``image`` (top row first) as a ``width`` × ``width``/2 equirect: solid-angle-exact 2×
    reductions while it is wider and even, then bilinear resampling to the exact size."""
    img = np.asarray(image, dtype=np.float64)
    while img.shape[1] >= 2 * width and img.shape[1] % 2 == 0 and img.shape[0] % 2 == 0:
        img = hdri.downsample(img, 2)
    if img.shape[:2] != (width // 2, width):
        img = hdri.equirect_lookup(img, hdri.equirect_directions(width // 2, width))
    return np.ascontiguousarray(img, dtype=np.float32)


def _constant_panorama(coeffs) -> np.ndarray:
    """A panorama of the constant radiance whose SH band 0 is ``coeffs[0]`` (= √(4π)·c)."""
    rgb = np.asarray(coeffs[0], dtype=np.float32) / np.float32(np.sqrt(4.0 * np.pi))
    return np.ascontiguousarray(np.broadcast_to(rgb, (PANORAMA_WIDTH // 2, PANORAMA_WIDTH, 3)))


@dataclass(eq=False)
class Analysed:
    """A World's content analysed for the draw (:func:`analyse_content`).

    ``content``: :class:`.world.WorldContent` (SH in the content's frame); ``environment``: the
    content's panorama with its lamps (:class:`precompute.world.environment.Environment`), None when
    it could not be analysed; ``arrays``: the prefilters computed so far, by kind (:data:`LIFTED`,
    :data:`WHOLE`), each the texture's content (2J, 256, 512, 4) float32, ready to upload.
    """

    content_key: str
    content: world.WorldContent
    environment: Environment | None
    arrays: dict = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def kind(self, kind: str) -> str:
        """The prefilter that serves ``kind``: without lamps the two are one (:data:`WHOLE`)."""
        if kind not in (LIFTED, WHOLE):
            raise ValueError(f"prefilter kind must be {LIFTED!r} or {WHOLE!r}, got {kind!r}")
        env = self.environment
        return WHOLE if env is None or env.lamps is None else kind

    def compute(self, kind: str) -> np.ndarray:
        """The ``kind`` prefilter, computed (seconds: call it on a worker), packed for the texture
        (:meth:`.gpu.resources.PrefilterTexture.pack`) and kept."""
        kind = self.kind(kind)
        with self.lock:  # one computation per kind, whichever thread asks first
            found = self.arrays.get(kind)
            if found is None:
                env = self.environment
                pre = env.prefiltered if kind == LIFTED else env.prefiltered_whole
                # packed for the texture here (numpy): the main thread only uploads it
                found = resources.PrefilterTexture.pack(
                    pre.resampled(PREFILTER_WIDTH), pre.resampled_moments(PREFILTER_WIDTH)
                )
                self.arrays[kind] = found
        return found


def analyse_content(content_key: str, read: world.WorldRead, fallback_rgb, kinds=()) -> Analysed:
    """Analyse a World's content (pure numpy, any thread): SH, panorama, lamps, and the prefilters
    of ``kinds``.

    ``fallback_rgb``: the radiance to analyse when the content is not finite (the World then
    draws its fallback colour, :func:`.world.fallback_colour`).
    """
    content = world.analyse_read(read, MAX_SH_ORDER)
    usable = bool(
        np.all(np.isfinite(content.coeffs)) and np.all(np.abs(content.coeffs) <= world_params.MAX_COEFFICIENT)
    )
    width = PREFILTER_WIDTH
    if not usable:
        image = _constant_panorama(world.constant_sh(0, fallback_rgb))
    elif content.image is None:
        image = _constant_panorama(content.coeffs)
    else:
        image = _equirect(content.image, PANORAMA_WIDTH)
        # a smaller source (a procedural World's 256-wide Cycles panorama) has no detail for
        # sharper levels to keep: they are filtered at its width and resampled for the texture
        width = min(width, max(_POW2_MIN, 1 << (int(content.image.shape[1]).bit_length() - 1)))
    coeffs = content.coeffs if usable else world.constant_sh(MAX_SH_ORDER, fallback_rgb)
    env = analyse_world(image, coeffs, l_max=layout.MAX_L, width=width)
    found = Analysed(content_key, content, env)
    for kind in kinds:
        found.compute(kind)
    return found


def world_lamps(lamps: Lamps | None, matrix: np.ndarray | None, scale: float | None) -> Lamps | None:
    """The content's lamps in the World: directions turned (Qᵀ e: image direction e = Q d) and
    powers scaled."""
    if lamps is None or (matrix is None and scale is None):
        return lamps
    directions = lamps.directions if matrix is None else lamps.directions @ np.asarray(matrix)
    power = lamps.power if scale is None else lamps.power * scale
    return Lamps(directions, power, lamps.pixels, lamps.share)


class PrefilterTextures:
    """An :class:`Analysed` content's prefilters on the GPU, each uploaded the first time a drawn
    material reads it (``scene_draw._prefiltered_for``); shared by every parameter of the content.

    :meth:`prefiltered`: the split-sum levels with the World's lamps lifted out from
    lamps.LAMP_LEVEL on, for glossy materials that shade the lamps per light;
    :meth:`prefiltered_whole`: the whole World in every level, for the glossy materials the lamps
    do not apply to (a diffuse base under the film, "World Lamps" off). Without lamps they are one
    texture. With ``compute`` False (the draw callback) a prefilter not computed yet gives None:
    the caller asks a worker for it (``.world_job``).
    """

    def __init__(self, analysed: Analysed):
        self.analysed = analysed
        self.environment = analysed.environment
        self._uploaded: dict[str, resources.PrefilterTexture] = {}

    def get(self, kind: str, compute: bool = True) -> resources.PrefilterTexture | None:
        """The ``kind`` prefilter's texture: uploaded now if computed, computed first if
        ``compute``, else None."""
        kind = self.analysed.kind(kind)
        found = self._uploaded.get(kind)
        if found is not None:
            return found
        arrays = self.analysed.arrays.get(kind)
        if arrays is None:
            if not compute:
                return None
            arrays = self.analysed.compute(kind)
        found = resources.PrefilterTexture.from_packed(arrays)
        self._uploaded[kind] = found
        return found

    def prefiltered(self, compute: bool = True) -> resources.PrefilterTexture | None:
        """The prefilter with the lamps lifted out (the whole World when it has none)."""
        return self.get(LIFTED, compute)

    def prefiltered_whole(self, compute: bool = True) -> resources.PrefilterTexture | None:
        """The prefilter with the lamps in every level."""
        return self.get(WHOLE, compute)


@dataclass(frozen=True)
class WorldLighting:
    """The scene's World as the draw lights with it (:func:`.world_state.world_lighting`).

    ``key``: the content key and the parameters; ``sh``: the World's SH radiance in its frame
    and strength (:class:`.world.WorldSH`); ``environment``: the content's panorama analysed
    (lamps, prefilters, the lamps' SH) in the *content's* frame and strength, or None (glossy
    films then fall back to the SH path); ``textures``: its prefilters on the GPU;
    ``params``, ``scale``, ``turned``: how the content becomes the World (scale None: 1;
    ``turned``: the content is the image as read, turned by ``params``).
    """

    key: str
    sh: world.WorldSH
    environment: Environment | None = None
    textures: PrefilterTextures | None = None
    image_tried: bool = True
    content_key: str = ""
    params: world_params.WorldParams = field(default_factory=world_params.WorldParams)
    scale: float | None = None
    turned: bool = False
    #: The content's SH (its frame and strength; None for the fallback colour): what the
    #: radiance grids are built from (:meth:`grid_source`).
    content_sh: np.ndarray | None = None

    @property
    def matrix(self) -> np.ndarray | None:
        """Q (image direction = Q · world direction) when the content is turned, else None."""
        return self.params.matrix if self.turned and self.params.turned else None

    def lamps(self) -> Lamps | None:
        """The World's lamps in its frame and strength (None without lamps)."""
        env = self.environment
        return None if env is None else world_lamps(env.lamps, self.matrix, self.scale)

    def sh_without_lamps(self) -> np.ndarray:
        """The World's SH without its lamps, in its frame and strength."""
        env = self.environment
        return world_params.apply_params(env.sh_without_lamps, self.params, self.scale, self.turned)

    def grid_source(self, lamps: bool) -> tuple[str, np.ndarray]:
        """(key, SH) a radiance grid is built from: the content's SH, without its lamps when
        ``lamps``, keyed by the content alone, so that a Strength or rotation edit (the lighting
        buffer's ``world`` block turns and scales the grid lookup) rebuilds no grid; the World's
        own SH where there is no content (the fallback colour, neither turned nor scaled)."""
        env = self.environment
        lamps = bool(lamps and env is not None)
        if self.content_sh is None:
            own = self.sh_without_lamps() if lamps else self.sh.coeffs
            return self.key, np.asarray(own, dtype=np.float64)
        if lamps:
            return f"{self.content_key}|lamps", np.asarray(env.sh_without_lamps, dtype=np.float64)
        return self.content_key, np.asarray(self.content_sh, dtype=np.float64)

    def background(self) -> np.ndarray | None:
        """The World's panorama (top row first) in its frame and strength, for a headless
        frame's background; None without an environment."""
        env = self.environment
        if env is None:
            return None
        image = np.asarray(env.panorama)
        q = self.matrix
        if q is not None:
            dirs = hdri.equirect_directions(*image.shape[:2])
            image = hdri.equirect_lookup(image, dirs @ q.T)
        return image * self.scale if self.scale is not None else image


def lighting_from(
    scene, analysed: Analysed, params: world_params.WorldParams, key: str, reuse=None
) -> WorldLighting:
    """The :class:`WorldLighting` of ``analysed`` under ``params`` (main thread, milliseconds).

    ``reuse``: the lighting drawn so far; its textures are kept when it shows the same content.
    """
    sh = world.finish(scene, analysed.content, params, world.world_key(scene, MAX_SH_ORDER), MAX_SH_ORDER)
    env = analysed.environment
    textures = None
    if env is not None:
        same = reuse is not None and reuse.textures is not None and reuse.textures.analysed is analysed
        textures = reuse.textures if same else PrefilterTextures(analysed)
    if sh.errors:  # the fallback colour: its environment is that constant, neither turned nor scaled
        return WorldLighting(key, sh, env, textures, True, analysed.content_key, params, None, False)
    scale = world.content_scale(analysed.content, params)
    return WorldLighting(
        key,
        sh,
        env,
        textures,
        True,
        analysed.content_key,
        params,
        scale,
        analysed.content.read.turned,
        np.asarray(analysed.content.coeffs, dtype=np.float64),
    )
