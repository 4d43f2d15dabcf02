"""The World's lighting for the draw: its state, and the API the draw reads it through.

:data:`STATE` (registered in :mod:`..caches` as ``world_lighting``, emptied on file load) holds
the current World's :class:`.world_analysis.WorldLighting` (SH, analysed panorama, prefilter
textures) for the current World key, the analysed contents by content key (a Strength or
rotation edit, or a swap back to a recent HDRI, recomputes nothing), and what the draw asked
for that is not there yet: a World content to analyse, prefilters to compute. It is written in
this room only: here on the main thread, and by :mod:`.world_job`'s worker (the analysed
contents, an LRU that is thread-safe; a result for a file loaded since is dropped by
:attr:`WorldState.generation`).

The draw reads it through :func:`world_lighting` (the scene's lighting: the old one while a new
content is analysed), :func:`prefilter` (a glossy film's prefilter, or None while a worker
computes it) and :func:`current`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .. import caches
from ..gpu import resources
from . import world, world_analysis, world_params
from .world_analysis import WorldLighting

__all__ = [
    "CONTENT_CACHE_SIZE",
    "STATE",
    "WorldState",
    "current",
    "lamps_summary",
    "prefilter",
    "world_lighting",
]

#: Analysed World contents kept (each holds a 512-wide panorama and up to two prefilters,
#: ≈ 60 MB): the current World and two recent ones.
CONTENT_CACHE_SIZE = 3


@dataclass
class WorldState:
    """The World's lighting and its analysis's bookkeeping (see the module docstring)."""

    lighting: WorldLighting | None = None  # the current World's lighting
    #: Analysed World contents (world_analysis.Analysed) by content key.
    contents: caches.LRU = field(default_factory=lambda: caches.LRU(CONTENT_CACHE_SIZE))
    wanted: bool = False  # the draw met a World content not analysed yet (.world_job)
    prefilters_wanted: set = field(default_factory=set)  # (content key, kind) the draw asked for
    prefilters_used: set = field(default_factory=set)  # kinds the frames' glossy films read
    generation: int = 0  # bumped by clear(): a worker's result for an older file is dropped

    def clear(self) -> None:
        """Forget the lighting, the analysed contents and what was asked for."""
        self.lighting = None
        self.contents.clear()
        self.wanted = False
        self.prefilters_wanted.clear()
        self.prefilters_used.clear()
        self.generation += 1


STATE = caches.register("world_lighting", WorldState(), scope=caches.FILE)


def _lighting_key(content_key: str, params: world_params.WorldParams) -> str:
    """The drawn lighting's key: the World's content key and its parameters."""
    return (
        f"{content_key}|{params.strength!r}|{params.parity}|{','.join(f'{v:.17g}' for v in params.rotation)}"
    )


def current() -> WorldLighting | None:
    """The lighting last made for the scene's World (None before the first)."""
    return STATE.lighting


def world_lighting(scene, *, allow_compute: bool = True) -> WorldLighting | None:
    """The :class:`WorldLighting` of the scene's World: the content analysed once per content key,
    the parameters (Strength, Mapping rotation) applied per edit without recomputation.

    With ``allow_compute`` False (the draw callback) a World whose content is not analysed yet
    is asked for (:attr:`WorldState.wanted`, served by :mod:`.world_job` on a worker) and the
    lighting drawn so far is returned meanwhile: the old World until the new one is ready (None
    before the first). With ``allow_compute`` (headless renders) it is analysed here.
    """
    content_key, params = world_params.world_parts(scene)
    key = _lighting_key(content_key, params)
    last = STATE.lighting
    if last is not None and last.key == key:
        return last
    analysed = STATE.contents.get(content_key)
    if analysed is None:
        if not allow_compute:
            STATE.wanted = True
            return last
        read = world.read_world(scene, params=params)
        fallback = world.fallback_colour(scene.world)[0]
        analysed = world_analysis.analyse_content(content_key, read, fallback)
        STATE.contents[content_key] = analysed
    STATE.lighting = world_analysis.lighting_from(scene, analysed, params, key, last)
    return STATE.lighting


def prefilter(
    lighting: WorldLighting, lamps: bool, compute: bool = True
) -> resources.PrefilterTexture | None:
    """The prefilter a glossy film reads under ``lighting``: the World with its lamps lifted out
    when the film shades them per direction (``lamps``), else the whole World; computed on first
    use, or, with ``compute`` False (the draw callback), asked of a worker
    (:attr:`WorldState.prefilters_wanted`) and None meanwhile: the film draws from the SH until
    it is ready. None too when the World has no prefilters."""
    textures = lighting.textures
    if textures is None:
        return None
    kind = world_analysis.LIFTED if lamps else world_analysis.WHOLE
    STATE.prefilters_used.add(kind)
    found = textures.get(kind, compute)
    if found is None:  # asked of a worker (.world_job)
        STATE.prefilters_wanted.add((lighting.content_key, kind))
    else:
        STATE.prefilters_wanted.discard((lighting.content_key, kind))
    return found


def lamps_summary(enabled: bool) -> str:
    """One line for the Surface panel: what the current World's lamps are and how they are shaded,
    or why the World could not be evaluated (it is then lit by its fallback colour)."""
    lighting = STATE.lighting
    if lighting is not None and lighting.sh.errors:
        return lighting.sh.errors[0]
    env = lighting.environment if lighting is not None else None
    if env is None:
        return "World lamps: World not analysed yet"
    if env.lamps is None:
        return "World lamps: none (no small, very bright sources)"
    lamps = env.lamps
    how = "shaded per lamp" if enabled else "off: through SH and prefilter"
    return f"World lamps: {lamps.count}, {100 * lamps.share:.0f} % of the light ({how})"
