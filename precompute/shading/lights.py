"""Blender's light objects shading the film (numpy twin of glsl/tf_lights.glsl).

Sun, point, spot and area lights, converted to the radiometric quantities Cycles uses
(:func:`light_from_blender`, facts from Cycles' ``scene/light.cpp`` and ``kernel/light/*.h``
verified against Cycles renders in tests/parity/test_scene_lights.py), and shaded with the exact
microfacet BRDF and the film's reflectance at each sample's own half vector, as the World's
lamps are (shading/lamps.py): D G₂ F(ωo·h) / (4 cos θo) × E⊥ per sample, times the
multiple-scattering factor at the view angle.

Samples (:func:`light_samples`), one set per light and shading point:

- sun: its centre direction, E⊥ = its irradiance;
- point and spot (spheres of radius r): the centre, E⊥ = I / d² (the exact irradiance of a
  uniform sphere above the horizon), times the spot's cone and blend (:func:`spot_attenuation`);
- area (square, rectangle, disk, ellipse): the centres of an S × S grid of equal-area cells
  (:data:`policy.AREA_SAMPLES` per axis; disks through the concentric map), each
  E⊥ = L · A_cell · cos θ_light / d², times Cycles' spread (:func:`spread_attenuation`).

Each sample's GGX D is widened by its footprint, α'² = α² + ρ² (:func:`footprint`): a uniform
disc of half-vector radius ρ has the peak density 1/(πρ²) of a GGX lobe with α = ρ, and D_α'
stays normalised, so a mirror shows a finite, energy-preserving highlight instead of a delta,
and the cells of an area light merge into one highlight. G₂, F and the cosines stay those of the
sample direction. A sample below the surface (cos θi ≤ 0) or behind a one-sided area light
contributes nothing. No shadows from other objects.

References
----------
- Walter, B., Marschner, S., Li, H. & Torrance, K. (2007). Microfacet models for refraction
  through rough surfaces. EGSR.
- Karis, B. (2013). Real shading in Unreal Engine 4. SIGGRAPH course notes (widening the lobe
  by the light's size).
- Shirley, P. & Chiu, K. (1997). A low distortion map between disk and square. JGT 2(3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import brdf
from . import policy
from .lamps import film_at, lit_pixels
from .policy import LIGHT_VEC4, MIN_COS

#: Light kinds as the shader stores them (``tf_lights.light[5k].w``; policy.LIGHT_KINDS).
KINDS = dict(policy.LIGHT_KINDS)
SUN, POINT, SPOT, AREA = (KINDS[k] for k in ("SUN", "POINT", "SPOT", "AREA"))
#: A hard spot edge (blend 0): the smoothstep's inverse width, finite in float32.
SPOT_HARD = 1e30
#: Nearest distance to a light's centre or sample the shaders divide by (policy).
MIN_LIGHT_DISTANCE = policy.MIN_LIGHT_DISTANCE
#: tan of the spread's half angle for a full spread (π: no attenuation).
FULL_SPREAD = -1.0


@dataclass(frozen=True)
class Lights:
    """K lights, one row each (the shader's TFLights buffer, :meth:`pack`).

    ``kind`` (K,) :data:`SUN`…:data:`AREA`; ``position`` (K, 3) m; ``direction`` (K, 3) the
    light's −Z axis (a sun's light travels along it, a spot points along it, an area light emits
    to its side); ``energy`` (K, 3): a sun's irradiance E (W/m²), a point or spot light's
    intensity I (W/sr), an area light's radiance L (W/(m² sr)), colour and Specular factor
    folded in; ``radius`` (K,): a sphere's radius (m), a sun's half angle (rad); ``axis_u``,
    ``axis_v`` (K, 3): an area light's full extents (m); ``cos_half_spot``, ``spot_smooth`` (K,):
    a spot's cos(size/2) and 1/((1 − cos(size/2))·blend); ``tan_half_spread``,
    ``normalize_spread`` (K,): an area light's spread (:data:`FULL_SPREAD`: none);
    ``ellipse`` (K,): a disk or ellipse area light.
    """

    kind: np.ndarray
    position: np.ndarray
    direction: np.ndarray
    energy: np.ndarray
    radius: np.ndarray
    axis_u: np.ndarray
    axis_v: np.ndarray
    cos_half_spot: np.ndarray
    spot_smooth: np.ndarray
    tan_half_spread: np.ndarray
    normalize_spread: np.ndarray
    ellipse: np.ndarray

    @property
    def count(self) -> int:
        """K, the number of lights."""
        return int(self.kind.shape[0])

    @classmethod
    def from_rows(cls, rows) -> Lights:
        """Lights from a sequence of :func:`light_from_blender` dicts (empty: no lights)."""
        rows = list(rows)
        vec = ("position", "direction", "energy", "axis_u", "axis_v")

        def column(name):
            if not rows:
                return np.zeros((0, 3) if name in vec else (0,))
            return np.array([r[name] for r in rows], dtype=np.float64)

        return cls(
            np.array([r["kind"] for r in rows], dtype=np.int64).reshape(-1),
            *(
                column(n)
                for n in (
                    "position",
                    "direction",
                    "energy",
                    "radius",
                    "axis_u",
                    "axis_v",
                    "cos_half_spot",
                    "spot_smooth",
                    "tan_half_spread",
                    "normalize_spread",
                )
            ),
            column("ellipse").astype(bool),
        )

    def pack(self) -> np.ndarray:
        """(K·:data:`LIGHT_VEC4`, 4) float64, the shader's layout (resources.LIGHTS):
        [0] position, kind; [1] direction, radius; [2] energy, cos_half_spot or tan_half_spread;
        [3] axis_u, spot_smooth or normalize_spread; [4] axis_v, ellipse."""
        out = np.zeros((self.count, LIGHT_VEC4, 4))
        area = self.kind == AREA
        out[:, 0, :3], out[:, 0, 3] = self.position, self.kind
        out[:, 1, :3], out[:, 1, 3] = self.direction, self.radius
        out[:, 2, :3] = self.energy
        out[:, 2, 3] = np.where(area, self.tan_half_spread, self.cos_half_spot)
        out[:, 3, :3] = self.axis_u
        out[:, 3, 3] = np.where(area, self.normalize_spread, self.spot_smooth)
        out[:, 4, :3], out[:, 4, 3] = self.axis_v, self.ellipse
        return out.reshape(-1, 4)


def _unit(a) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    n = np.linalg.norm(a)
    return a / n if n > 0 else np.array([0.0, 0.0, -1.0])


def light_from_blender(
    kind: str,
    matrix_world,
    colour=(1.0, 1.0, 1.0),
    energy: float = 10.0,
    *,
    exposure: float = 0.0,
    normalize: bool = True,
    radius: float = 0.0,
    angle: float = 0.0,
    spot_size: float = math.pi / 4,
    spot_blend: float = 0.15,
    shape: str = "SQUARE",
    size: float = 1.0,
    size_y: float = 1.0,
    spread: float = math.pi,
    specular_factor: float = 1.0,
) -> dict:
    """One light's row of :class:`Lights` from Blender's settings, as Cycles converts them.

    ``kind``: ``"SUN"``, ``"POINT"``, ``"SPOT"``, ``"AREA"``; ``matrix_world`` 4×4 (rows);
    ``colour`` the light's RGB (times its temperature colour where used); ``energy`` W (W/m² for
    a sun), times 2^``exposure``; ``radius`` m (point, spot); ``angle`` rad (sun's diameter);
    ``spot_size`` rad (full cone), ``spot_blend`` [0, 1]; ``shape`` SQUARE, RECTANGLE, DISK,
    ELLIPSE with ``size``, ``size_y`` m (times the object's scale); ``spread`` rad.

    Cycles (``scene/light.cpp``): a point or spot light's radiance is P / (π · 4π r²), so its
    intensity (radiance × its disc, π r²) is P / (4π) at any radius (P / π for r = 0 and P r²
    without *Normalize*); a sun's radiance is S / (π sin²(angle/2)), so its irradiance is S
    (S π sin²(angle/2) without *Normalize*); an area light's radiance is P / (π A), A its area
    (π/4 · u v for disks and ellipses; P / π without *Normalize*).
    """
    kind = kind.upper()
    if kind not in KINDS:
        raise ValueError(f"unknown light type {kind!r}")
    m = np.asarray(matrix_world, dtype=np.float64).reshape(4, 4)
    scale = float(energy) * 2.0 ** float(exposure) * float(specular_factor)
    rgb = np.nan_to_num(np.asarray(colour, dtype=np.float64).reshape(3), nan=0.0) * scale
    row = {
        "kind": KINDS[kind],
        "position": m[:3, 3].copy(),
        "direction": _unit(-m[:3, 2]),
        "radius": 0.0,
        "axis_u": np.zeros(3),
        "axis_v": np.zeros(3),
        "cos_half_spot": -2.0,  # every direction inside
        "spot_smooth": SPOT_HARD,
        "tan_half_spread": FULL_SPREAD,
        "normalize_spread": 1.0,
        "ellipse": False,
    }
    if kind == "SUN":
        half = 0.5 * max(float(angle), 0.0)
        row["radius"] = half
        disc = math.pi * math.sin(half) ** 2 if half > 0.0 else 1.0
        row["energy"] = rgb if normalize else rgb * disc
    elif kind in ("POINT", "SPOT"):
        r = max(float(radius), 0.0)
        row["radius"] = r
        if normalize:
            row["energy"] = rgb / (4.0 * math.pi)
        else:
            row["energy"] = rgb * (r * r) if r > 0.0 else rgb / math.pi
        if kind == "SPOT":
            half = 0.5 * float(np.clip(spot_size, 1e-6, math.pi))
            c = math.cos(half)
            row["cos_half_spot"] = c
            blend = float(np.clip(spot_blend, 0.0, 1.0))
            row["spot_smooth"] = 1.0 / ((1.0 - c) * blend) if blend > 0.0 else SPOT_HARD
    else:
        ellipse = shape.upper() in ("DISK", "ELLIPSE")
        sy = size if shape.upper() in ("SQUARE", "DISK") else size_y
        u = m[:3, 0] * float(size)
        v = m[:3, 1] * float(sy)
        area = float(np.linalg.norm(u) * np.linalg.norm(v)) * (math.pi / 4.0 if ellipse else 1.0)
        row["axis_u"], row["axis_v"], row["ellipse"] = u, v, ellipse
        row["energy"] = rgb / (math.pi * area) if normalize and area > 0.0 else rgb / math.pi
        half = 0.5 * max(float(spread), 0.0)
        if half < 0.5 * math.pi - 1e-6:
            t = math.tan(half)
            row["tan_half_spread"] = t
            # Cycles: ∫₀^a cos x (1 − tan x / tan a) sin x dx, divided into tan a (third order small)
            row["normalize_spread"] = 1.0 / (t - half) if half > 0.05 else 3.0 / max(half, 1e-6) ** 3
    return row


def spot_attenuation(cos_axis, cos_half_spot, spot_smooth) -> np.ndarray:
    """Blender's spot cone: smoothstep((cos ψ − cos(size/2)) / ((1 − cos(size/2))·blend)), ψ the
    angle from the spot's axis (Cycles ``spot_light_attenuation``; a hard edge at blend 0)."""
    x = np.clip((np.asarray(cos_axis) - cos_half_spot) * spot_smooth, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def spread_attenuation(cos_light, tan_half_spread, normalize_spread) -> np.ndarray:
    """Cycles' area-light spread: (tan(spread/2) − tan θ)·normalisation, ≥ 0; 1 for a full spread."""
    if tan_half_spread < 0.0:
        return np.ones_like(np.asarray(cos_light, dtype=np.float64))
    c = np.clip(cos_light, MIN_COS, 1.0)
    tan_a = np.sqrt(np.maximum(1.0 - c * c, 0.0)) / c
    return np.maximum((tan_half_spread - tan_a) * normalize_spread, 0.0)


def footprint(sin2) -> np.ndarray:
    """ρ² added to α² for a source of angular radius θ (sin² θ given): the half-vector disc's
    radius is θ/2, ρ² = sin² θ / 4."""
    return 0.25 * np.asarray(sin2)


def area_grid(samples: int, ellipse: bool) -> np.ndarray:
    """(S², 2) cell centres in [−½, ½]² (square), or on the disc of radius ½ through the
    concentric map (equal-area cells), S = ``samples`` per axis."""
    s = int(samples)
    t = (np.arange(s) + 0.5) / s * 2.0 - 1.0
    a, b = np.meshgrid(t, t, indexing="ij")
    a, b = a.ravel(), b.ravel()
    if not ellipse:
        return 0.5 * np.stack([a, b], -1)
    big_a = np.abs(a) > np.abs(b)
    r = np.where(big_a, a, b)
    phi = np.where(
        big_a, (np.pi / 4) * b / np.where(a == 0, 1, a), np.pi / 2 - (np.pi / 4) * a / np.where(b == 0, 1, b)
    )
    return 0.5 * np.stack([r * np.cos(phi), r * np.sin(phi)], -1)


def area_cells(lights: Lights, k: int, samples: int = policy.AREA_SAMPLES) -> tuple[np.ndarray, float]:
    """(centres (S², 2) as fractions of ``axis_u`` and ``axis_v``, each cell's area m²): area
    light ``k``'s ``samples`` × ``samples`` cells of equal area (:func:`area_grid`)."""
    ellipse = bool(lights.ellipse[k])
    grid = area_grid(samples, ellipse)
    size = float(np.linalg.norm(lights.axis_u[k]) * np.linalg.norm(lights.axis_v[k]))
    return grid, size * (math.pi / 4.0 if ellipse else 1.0) / grid.shape[0]


def light_samples(lights: Lights, k: int, positions, lobe=None):
    """Samples of light ``k`` seen from ``positions`` (N, 3): a list of (l (N, 3) unit towards
    the sample, E⊥ (N, 3), ρ² (N,)) (see the module docstring). ``lobe``: :func:`area_lobe` for
    a rectangle (None: a uniform grid)."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    kind = int(lights.kind[k])
    e = lights.energy[k]
    if kind == SUN:
        l = np.broadcast_to(-lights.direction[k], p.shape)
        rho2 = np.full(p.shape[0], footprint(math.sin(lights.radius[k]) ** 2))
        return [(l, np.broadcast_to(e, p.shape), rho2)]
    if kind in (POINT, SPOT):
        to = lights.position[k] - p
        r = float(lights.radius[k])
        d2 = np.maximum(np.sum(to * to, -1), max(r * r, MIN_LIGHT_DISTANCE**2))
        l = to / np.sqrt(d2)[:, None]
        scale = 1.0 / d2
        if kind == SPOT:
            scale = scale * spot_attenuation(
                -(l @ lights.direction[k]), lights.cos_half_spot[k], lights.spot_smooth[k]
            )
        return [(l, scale[:, None] * e, footprint(r * r / d2))]
    return _area_samples(lights, k, p, lobe)


def lobe_cells(centre, width, samples: int):
    """Cells along one axis of a light, in [−½, ½]: (midpoints (N, S), widths (N, S)).

    The S cells hold equal shares of a Cauchy distribution of ``centre`` and ``width`` (N,)
    restricted to [−½, ½]: small where the film's lobe meets the light, wide elsewhere, and
    together exactly the light's extent. A wide lobe (width ≫ 1) gives a uniform grid.
    """
    # bounded so that float32 keeps c + w tan(·) to ~1e-5 (a lobe that wide is uniform anyway)
    c = np.clip(np.asarray(centre, dtype=np.float64), -policy.AREA_MAX_WIDTH, policy.AREA_MAX_WIDTH)[:, None]
    w = np.clip(np.asarray(width, dtype=np.float64), policy.AREA_MIN_WIDTH, policy.AREA_MAX_WIDTH)[:, None]
    lo = np.arctan((-0.5 - c) / w)
    hi = np.arctan((0.5 - c) / w)
    t = np.arange(int(samples) + 1) / int(samples)
    edges = np.clip(c + w * np.tan(lo + (hi - lo) * t), -0.5, 0.5)
    edges[:, 0], edges[:, -1] = -0.5, 0.5
    return 0.5 * (edges[:, 1:] + edges[:, :-1]), edges[:, 1:] - edges[:, :-1]


def area_lobe(lights: Lights, k: int, positions, normals, views, alpha: float):
    """Where the film's lobe meets area light ``k``, per point: (centre u, centre v, width u,
    width v) in the light's [−½, ½]² coordinates, for :func:`lobe_cells`.

    The mirror ray p + t r (r = reflect(−v, n)) meets the light's plane at the centre; the width
    is the lobe's angular scale, policy.AREA_LOBE_SCALE · α, times t, over the ray's obliquity
    to the plane and the light's size. A ray that never meets the plane gives a uniform grid.
    """
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(views, dtype=np.float64).reshape(-1, 3)
    r = 2.0 * np.sum(n * v, -1, keepdims=True) * n - v
    axis = lights.direction[k]
    facing = -(r @ axis)  # > 0: the ray runs towards the light's emitting side
    safe = np.maximum(facing, MIN_COS)
    t = np.maximum((p - lights.position[k]) @ axis, 0.0) / safe
    hit = p + t[:, None] * r - lights.position[k]
    out = []
    for ax in (lights.axis_u[k], lights.axis_v[k]):
        size = max(float(np.linalg.norm(ax)), policy.AREA_MIN_AXIS)
        centre = (hit @ ax) / (size * size)
        width = policy.AREA_LOBE_SCALE * alpha * t / (safe * size)
        out.append(
            (
                np.where(facing > MIN_COS, centre, 0.0),
                np.where(facing > MIN_COS, width, policy.AREA_UNIFORM_WIDTH),
            )
        )
    return out[0][0], out[1][0], out[0][1], out[1][1]


def _area_samples(lights: Lights, k: int, p: np.ndarray, lobe):
    """The S × S cell samples of area light ``k`` (module docstring)."""
    out = []
    ellipse = bool(lights.ellipse[k])
    u, v = lights.axis_u[k], lights.axis_v[k]
    size = np.linalg.norm(u) * np.linalg.norm(v)
    if ellipse or lobe is None:  # disks and ellipses: uniform equal-area cells (concentric map)
        grid, area = area_cells(lights, k)
        cell = np.full(p.shape[0], area)
        cells = [(np.full(p.shape[0], a), np.full(p.shape[0], b), cell) for a, b in grid]
    else:
        cu, cv, wu, wv = lobe
        mu, du = lobe_cells(cu, wu, policy.AREA_SAMPLES)
        mv, dv = lobe_cells(cv, wv, policy.AREA_SAMPLES)
        cells = [
            (mu[:, i], mv[:, j], du[:, i] * dv[:, j] * size)
            for i in range(mu.shape[1])
            for j in range(mv.shape[1])
        ]
    for su, sv, cell in cells:
        to = lights.position[k] + su[:, None] * u + sv[:, None] * v - p
        d2 = np.maximum(np.sum(to * to, -1), MIN_LIGHT_DISTANCE**2)
        l = to / np.sqrt(d2)[:, None]
        cos_l = -(l @ lights.direction[k])
        omega = np.where(cos_l > 0.0, cell * cos_l / d2, 0.0)
        scale = omega * spread_attenuation(cos_l, lights.tan_half_spread[k], lights.normalize_spread[k])
        out.append((l, scale[:, None] * lights.energy[k], footprint(omega)))
    return out


def sample_weight(n, v, l, alpha: float, rho2, cos_o) -> np.ndarray:
    """D_α'(n·h) G₂(cos θi, cos θo) / (4 cos θo) of one sample, α'² = α² + ρ²; 0 below the surface."""
    cos_i = np.sum(n * l, -1)
    h = v + l
    h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-30)
    wide = np.sqrt(alpha * alpha + rho2)
    d = brdf.D_ggx(np.clip(np.sum(n * h, -1), 0.0, 1.0), wide)
    g = brdf.G2_smith_height_correlated(np.maximum(cos_i, MIN_COS), cos_o, alpha)
    return np.where(cos_i > 0.0, d * g / (4.0 * cos_o), 0.0), np.clip(np.sum(v * h, -1), 0.0, 1.0)


def shade(
    film, lights: Lights, roughness: float, positions, normals, views, thickness_position=None
) -> np.ndarray:
    """Σ_lights Σ_samples D_α' G₂ F(ωo·h) / (4 cos θo) × E⊥ × multiscatter(cos θo), plus a diffuse
    base's Σ E⊥ cos θi (× (1 − R(cos θi)) per channel, spectral) × film.diffuse(cos θo): (N, 3).

    Mirrored by tf_lights.glsl ``tf_shade_lights``. ``film``: a
    :class:`precompute.colour.film_colour.FilmTable` (its ``diffuse``: the base, None without one);
    ``positions``, ``normals``, ``views`` (N, 3), world space, normals facing the viewer;
    ``thickness_position`` in [0, 1] along the film table's rows (None: the first), as
    shading.lamps.shade.
    """
    n, v, alpha, t, cos_o = lit_pixels(film, lights.count, roughness, normals, views, thickness_position)
    out = np.zeros((n.shape[0], 3))
    if alpha is None:
        return out
    base = np.zeros((n.shape[0], 3)) if film.diffuse is not None else None
    for k in range(lights.count):
        lobe = area_lobe(lights, k, positions, n, v, alpha) if lights.kind[k] == AREA else None
        for l, e, rho2 in light_samples(lights, k, positions, lobe):
            weight, u = sample_weight(n, v, l, alpha, rho2, cos_o)
            f = film_at(film, film.reflectance, t, u)
            rgb = np.einsum("nij,nj->ni", f, e) if film.spectral else f * e
            out += weight[:, None] * rgb
            if base is not None:
                base += diffuse_in(film, t, np.sum(n * l, axis=-1), e)
    out = out * film_at(film, film.multiscatter, t, cos_o)
    return out if base is None else out + base * film_at(film, film.diffuse, t, cos_o)


def diffuse_in(film, rows, cos_i, e) -> np.ndarray:
    """(N, 3): what a sample of light ``e`` (N, 3) at cosines ``cos_i`` (N,) brings the diffuse
    base under the film: E⊥ cos θi, times 1 − R(cos θi) per channel for a spectral film (Cycles'
    per-channel layering puts no film on the light's way in); 0 below the horizon."""
    c = np.maximum(np.asarray(cos_i, dtype=np.float64), 0.0)
    through = np.asarray(e, dtype=np.float64) * c[:, None]
    if film.spectral:
        white = film_at(film, film.reflectance, rows, np.clip(c, 0.0, 1.0)).sum(axis=-1)
        through = through * np.clip(1.0 - white, 0.0, 1.0)
    return through


def irradiance(lights: Lights, positions, normals) -> np.ndarray:
    """Σ E⊥ cos θi over every sample (N, 3): what a white Lambertian surface receives (its
    radiance is this / π); used to check the conversion against Cycles."""
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    out = np.zeros((n.shape[0], 3))
    for k in range(lights.count):
        for l, e, _ in light_samples(lights, k, positions):
            out += np.maximum(np.sum(n * l, -1), 0.0)[:, None] * e
    return out
