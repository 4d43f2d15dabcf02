"""Photons from Blender's point, spot and area lights for solid glass's caustics.

A sun's photons are parallel rays over the glass's bounding sphere (:func:`.caustics.photon_grid`).
A light at a finite distance sends them from points: a point or spot light from its centre, an
area light from the centres of its cells (the same cells, and the same radiometry, as
:mod:`precompute.shading.lights` lights a film with: Cycles' conventions). From each point,
:func:`point_photons` spans the glass's bounding sphere with an n × n grid of rays over the
square that bounds it seen from there (the central projection onto the plane at unit distance
along the axis), row-major like the sun's grid, so :func:`.caustics.splat` joins four neighbours
into a caustic cell as it does a sun's. Each ray carries the flux of its cell, I(ω) Ω, I the
point's intensity towards it (:func:`emitted`) and Ω the cell's solid angle, h² cos³ θ at its
centre (h the grid's spacing on that plane, θ the ray's angle from the axis).

A point, spot or area light inside a glass's bounding sphere has no such square:
:func:`outside_sphere` tells the caller, which keeps the plain shadow through glass for it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..shading import lights as light_shading
from ..shading.policy import AREA_SAMPLES, CAUSTIC_GRID
from .caustics import across

__all__ = ["Emitter", "emitted", "emitters", "outside_sphere", "point_photons"]


def outside_sphere(position, centre, radius: float) -> bool:
    """Whether ``position`` lies outside the sphere of ``radius`` about ``centre``, where
    :func:`point_photons` can span it."""
    gap = np.asarray(position, dtype=np.float64) - np.asarray(centre, dtype=np.float64)
    return bool(np.linalg.norm(gap) > float(radius))


def point_photons(position, centre, radius: float, n: int = CAUSTIC_GRID):
    """(origins (n², 3), directions (n², 3) unit, solid angles (n²,)): an n × n grid of rays from
    ``position`` over the square that bounds the sphere of ``radius`` about ``centre`` as seen
    from there (half-width tan β on the plane at unit distance, sin β = radius / distance),
    row-major (photon i·n + j), each with its cell's solid angle h² cos³ θ. Raises ValueError
    where ``position`` is not outside the sphere."""
    p = np.asarray(position, dtype=np.float64).reshape(3)
    axis = np.asarray(centre, dtype=np.float64).reshape(3) - p
    distance = float(np.linalg.norm(axis))
    if not distance > float(radius) > 0.0:
        raise ValueError(f"a light at {distance:.4g} from a glass of radius {radius:.4g}: not outside it")
    w = axis / distance
    u, v = across(w)
    half = float(radius) / math.sqrt(distance * distance - float(radius) ** 2)
    h = 2.0 * half / n
    s = (np.arange(n) + 0.5) * h - half
    a, b = np.meshgrid(s, s, indexing="ij")
    rays = w + a.reshape(-1, 1) * u + b.reshape(-1, 1) * v
    length = np.linalg.norm(rays, axis=-1)
    directions = rays / length[:, None]
    omega = h * h / length**3
    return np.broadcast_to(p, directions.shape).copy(), directions, omega


@dataclass(frozen=True)
class Emitter:
    """One point a light's photons start from: its ``position`` (3,) and ``area`` (m², an area
    light's cell; 0 for a point or spot light's centre)."""

    position: np.ndarray
    area: float = 0.0


def emitters(lights: light_shading.Lights, k: int, samples: int = AREA_SAMPLES) -> list[Emitter]:
    """The points light ``k`` of ``lights`` sends photons from: a point or spot light's centre;
    an area light's ``samples`` × ``samples`` cells of equal area (disks and ellipses through the
    concentric map), the films' cells (:func:`precompute.shading.lights.area_cells`). A sun has none
    (its photons are parallel)."""
    kind = int(lights.kind[k])
    if kind in (light_shading.POINT, light_shading.SPOT):
        return [Emitter(lights.position[k].copy())]
    if kind != light_shading.AREA:
        return []
    grid, area = light_shading.area_cells(lights, k, samples)
    u, v = lights.axis_u[k], lights.axis_v[k]
    return [Emitter(lights.position[k] + a * u + b * v, area) for a, b in grid]


def emitted(lights: light_shading.Lights, k: int, emitter: Emitter, directions, omega) -> np.ndarray:
    """The flux (N, 3) each ray from ``emitter`` along ``directions`` (N, 3) carries over its
    solid angle ``omega`` (N,): I Ω, I the intensity of light ``k`` that way (Cycles'
    conventions, :func:`precompute.shading.lights.light_from_blender`): a point light's I, a
    spot's times its cone and blend; an area cell's L A cos θ times the light's spread, nothing
    behind it."""
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    w = np.asarray(omega, dtype=np.float64).reshape(-1)
    kind = int(lights.kind[k])
    axis = lights.direction[k]
    if kind == light_shading.AREA:
        cos_l = d @ axis
        spread = light_shading.spread_attenuation(
            cos_l, lights.tan_half_spread[k], lights.normalize_spread[k]
        )
        scale = np.where(cos_l > 0.0, float(emitter.area) * cos_l * spread, 0.0)
    elif kind == light_shading.SPOT:
        scale = light_shading.spot_attenuation(d @ axis, lights.cos_half_spot[k], lights.spot_smooth[k])
    else:
        scale = np.ones(d.shape[0])
    return (scale * w)[:, None] * lights.energy[k]
