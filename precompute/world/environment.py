"""A World panorama analysed once for the draw: lamps, prefiltered levels, SH without the lamps.

:func:`analyse_world` is the one call between a World's equirect panorama and what the shader
needs from it (the add-on calls it when the World's key changes):

1. its bright lamps and their pixels (:func:`precompute.world.lamps.extract`), shaded per light
   direction by the lamp loop;
2. the lamps' SH, the projection of the lamp pixels (:func:`precompute.sh.projection.project_equirect`),
   so that the SH lighting of a lamp-shaded material is the World's SH without them
   (:attr:`Environment.sh_without_lamps` = world − lamps over their common bands);
3. the GGX prefilter of the split sum (:func:`precompute.world.prefilter.prefilter`) with the lamps
   lifted out from ``lamps.LAMP_LEVEL`` on (:attr:`Environment.prefiltered`), for the glossy
   materials whose lamps go through the lamp loop;
4. the prefilter of the whole World (:attr:`Environment.prefiltered_whole`), for the glossy
   materials the lamps do not apply to.

A prefilter costs seconds, so neither is computed by :func:`analyse_world`: each is computed the
first time a drawn material reads it, then kept (addon/drawing/scene_draw.py asks only for those its
glossy materials read). Without lamps the two are one and the same.

Every watt is kept: rest + lamps = the panorama, in power and in SH (tests/sh/test_environment.py).
Pure numpy; never imports ``bpy``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ..materials.material import MAX_SH_ORDER
from ..sh import projection
from . import lamps as lamps_mod
from . import prefilter as prefilter_mod
from .lamps import Lamps
from .prefilter import Prefiltered

__all__ = ["Environment", "analyse_world"]


@dataclass(frozen=True, eq=False)
class Environment:
    """A World panorama analysed for the draw (see :func:`analyse_world`).

    Attributes
    ----------
    panorama : ndarray, shape (H, W, 3)
        Scene-linear radiance, top row first (docs/conventions.md), as given (not copied).
    world_sh : ndarray, shape ((L+1)², 3), float64
        The World's SH radiance as given (e.g. from its nodes, ``addon.world.world.world_sh``).
    lamps : precompute.world.lamps.Lamps or None
        The lamps lifted out of the panorama; None when it has none.
    lamp_mask : ndarray, shape (H, W), bool
        The panorama's pixels the lamps carry (all False without lamps).
    lamp_sh : ndarray, shape ((l_max+1)², 3), or None
        SH of the lamp pixels (the panorama times ``lamp_mask``); None without lamps.
    l_max : int
        The highest band of ``lamp_sh``.
    width : int
        The widest prefiltered level (texels across).
    """

    panorama: np.ndarray
    world_sh: np.ndarray
    lamps: Lamps | None
    lamp_mask: np.ndarray
    lamp_sh: np.ndarray | None
    l_max: int
    width: int

    @functools.cached_property
    def prefiltered(self) -> Prefiltered:
        """The split sum's levels with the lamps lifted out: the whole World below
        ``lamps.LAMP_LEVEL``, the World without its lamps from there on (computed on first use,
        then kept). Without lamps, the whole World at every level: :attr:`prefiltered_whole`.
        """
        if self.lamps is None:
            return self.prefiltered_whole
        return prefilter_mod.prefilter(self.panorama, width=self.width, lamp_mask=self.lamp_mask)

    @functools.cached_property
    def prefiltered_whole(self) -> Prefiltered:
        """The prefilter with the lamps in every level (computed on first use, then kept).

        Without lamps it is also :attr:`prefiltered`: nothing is filtered twice.
        """
        return prefilter_mod.prefilter(self.panorama, width=self.width)

    def computed_prefilters(self) -> tuple[str, ...]:
        """Which prefilters exist so far: ``"prefiltered"``, ``"prefiltered_whole"`` (one entry
        when the World has no lamps and the two are the same)."""
        done = [name for name in ("prefiltered", "prefiltered_whole") if name in self.__dict__]
        return ("prefiltered_whole",) if self.lamps is None and done else tuple(done)

    @functools.cached_property
    def sh_without_lamps(self) -> np.ndarray:
        """The World's SH without its lamps: ``world_sh − lamp_sh`` over their common bands.

        What the SH path shades for a material whose lamps go through the lamp loop (adding the
        lamps' light back gives the World's); ``world_sh`` itself when there are no lamps.
        """
        coeffs = np.asarray(self.world_sh, dtype=np.float64)
        if self.lamp_sh is None:
            return coeffs
        n = min(coeffs.shape[0], self.lamp_sh.shape[0])
        coeffs = coeffs.copy()
        coeffs[:n] -= self.lamp_sh[:n]
        coeffs.setflags(write=False)  # kept and shared: never changed in place
        return coeffs


def analyse_world(
    panorama,
    world_sh_coeffs,
    *,
    l_max: int = MAX_SH_ORDER,
    width: int = prefilter_mod.LEVEL_WIDTH,
) -> Environment:
    """Lamps and the lamps' SH of a World panorama, in one call; the prefilters on demand.

    Parameters
    ----------
    panorama : array_like, shape (H, W, 3)
        The World's radiance as an equirect image, top row first (e.g. a Cycles panorama).
    world_sh_coeffs : array_like, shape ((L+1)², 3)
        The World's SH radiance, from which :attr:`Environment.sh_without_lamps` subtracts the
        lamps.
    l_max : int
        Highest band of the lamps' SH (default: every band a table may use, MAX_SH_ORDER).
    width : int
        Width of the widest prefiltered level (``prefilter.LEVEL_WIDTH``, 512).

    Returns
    -------
    Environment
        Frozen; its prefilters are computed on first use (:attr:`Environment.prefiltered`,
        :attr:`Environment.prefiltered_whole`).
    """
    panorama = np.asarray(panorama)
    found, mask = lamps_mod.extract(panorama)
    if found.count:
        lamp_sh = projection.project_equirect(np.where(mask[..., None], panorama, 0.0), l_max)
        found_lamps = found
    else:
        lamp_sh = found_lamps = None
    return Environment(
        panorama=panorama,
        world_sh=np.asarray(world_sh_coeffs, dtype=np.float64),
        lamps=found_lamps,
        lamp_mask=mask,
        lamp_sh=lamp_sh,
        l_max=int(l_max),
        width=int(width),
    )
