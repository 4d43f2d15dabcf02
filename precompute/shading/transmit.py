"""A transparent film's wall: its transmittance and reflection scale (numpy twin of glsl/tf_transmit.glsl).

A film drawn as a *wall* (a soap bubble, a thin sheet of coated glass, a Principled BSDF with
*Thin Wall* and *Transmission Weight*) lets what lies behind it through, multiplied per channel
by the wall's transmittance T, and reflects R·L. The draw composites with two blend passes over
what is already in the frame: multiply by T, then add R·L (addon/gpu/draw.py). Both factors come
from the film's reflectance r(u) per channel at the view cosine u = n·v
(:class:`precompute.colour.film_colour.FilmTable`: Cycles' per-channel film in the per-channel mode,
the row sums of the 3×3 matrices, white light E, in the spectral mode), evaluated once at the
macro view angle, as Cycles' thin wall does. The film is lossless (no absorption in a layer
and a real substrate): what it does not reflect it transmits, r + t = 1 per channel.

Two walls (``mode``):

- :data:`WALL_SHEET` — the extension's own (physical) wall: the film on the front face of a
  sheet of relative index η (the substrate over the ambient), the back face bare; the sheet's
  internal reflections summed incoherently. The back face reflects R_b = Fresnel(u, η) (the
  reflectance from inside at the refracted angle equals the one from outside at u, reciprocity):
  T = (1 − r)(1 − R_b) / (1 − r R_b), R = r + (1 − r)² R_b / (1 − r R_b). A free-standing film
  (a soap bubble: η = 1) has R_b = 0: T = 1 − r, R = r.
- :data:`WALL_CYCLES` — Cycles' *Thin Wall* (``bsdf_thin_glass_fresnel``, Blender 5.2): the film
  on both faces of an infinitely thin sheet, the series t' = t₁t₂ / (1 − r₂²), r' = r₁ + t' r₂ with
  r₂ = r₁ = r, t₂ = t₁ = 1 − r (a lossless stack reflects the same from both sides at
  Snell-related angles): T = (1 − r) / (1 + r), R = 2r / (1 + r). A Principled soap bubble
  (IOR 1, the film on air) thus reflects as two films, where one real soap film reflects r.

- :data:`WALL_SOLID` — solid glass of index η (a Principled BSDF with *Transmission* and no *Thin
  Wall*): the light enters through the film and leaves through it again (the film on every
  interface, as Cycles), T = (1 − r)², S = 1; one reflection inside the glass adds
  (1 − r)² r × the World along :func:`solid_internal` (the glints of lamps behind the viewer
  that a glass ball shows), further ones are left out; what is behind is
  replaced by what the ray sees after the glass: the scene behind where the draw has it (the
  headless frame's background pass, :mod:`.refract`), else the World seen along
  :func:`solid_exit` (the ray through a sphere of that glass), read from the prefiltered World's
  sharpest level where the draw has one (the split sum), else seen straight through.

**Tint** (a Principled BSDF's *Base Color*: Cycles tints its transmission by it; the extension's
own walls are untinted, tint 1). Cycles' thin wall takes it as the sheet's transmittance at
normal incidence and absorbs c = tint^(1 / cos θ_t) per pass (Beer–Lambert at the angle inside
the sheet of index η): T = c (1 − r)² / (1 − (c r)²), R = r + T c r, so S = 1 + T c
(:func:`tint_pass`; c = 1 gives the untinted wall). Solid glass tints each refraction by √tint:
what passes in and out again (the scene or World behind, the glints) is times the tint; its
T = (1 − r)² from :func:`wall` stays untinted, the draw applies the tint (:func:`wall_tint`).

**Inside a bubble** (:func:`mesh_inside`, :func:`inside_reflections`; ``tf_inside_step``,
``tf_wall_rt``, ``tf_wall_inside``). Seen through a closed wall, the far wall reflects the World
back inside: that light must still leave through the wall it meets next, and part of it is
reflected again. Cycles traces it on; over the benchmark's bubble the studio lamps seen after
two and three reflections inside are coloured arcs worth 1.3 mean ΔE2000. The path is traced on
the **sphere about the object's origin through the far wall's point** p₁ (exact for a spherical
bubble; the stand-in solid glass uses without its buffers): a thin wall does not bend the ray,
which crosses the chord t = −2 (p − c)·d and is reflected about the sphere's normal there, every
hit met at the same angle. Each hit reads the wall at its own thickness: the per-vertex
thickness parameter's least-squares linear fit over the mesh (exact where it is linear in
position). With R_k = S_k r_k and T_k the wall at hit k:

    far wall's reflection  S₁r₁·L(d₁)  →  S₁r₁·L(d₁)·T₂ + R₁·(R₂T₃·L(d₂) + R₂R₃T₄·L(d₃) + …)

to :data:`.policy.INSIDE_ORDERS` reflections after the first, L the prefiltered World at the
film's roughness (Blender's light objects, and the World's lamps where the prefilter has lifted
them out, are not in the later reflections). Only a closed mesh has an inside (every edge shared
by two triangles; an open sheet's back face is just its other side), and only where the fit
explains at least :data:`.policy.INSIDE_MIN_EXPLAINED` of the thickness's variance
(:attr:`Inside.drawn`): a noise's (the Soap Film preset's) thickness at the other hits is not
known, and read at the fit's mean thickness the reflections took the soap bubble sample scene
from 12.07 to 12.20 mean ΔE2000.

The reflection is the film's shaded reflection (the baked table: r per microfacet) times the
scale S = R / r per channel, capped at :data:`.policy.WALL_SCALE_MAX` where r → 0; exact for a
smooth film, where the half vector is the normal. In the spectral mode T and S are per channel
of white light (a diagonal approximation of the 3×3 transmission).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .lamps import film_at, thickness_lerp
from .policy import DIVISION_FLOOR, INSIDE_MIN_EXPLAINED, INSIDE_ORDERS, MIN_COS, WALL_GUARD, WALL_SCALE_MAX

#: The extension's physical wall: the film on the front of a sheet of relative index η.
WALL_SHEET = 0
#: Cycles' Thin Wall: the film on both faces, the slab series of ``bsdf_thin_glass_fresnel``.
WALL_CYCLES = 1
#: Solid glass of index η (Principled Transmission without Thin Wall): in and out through the film.
WALL_SOLID = 2
#: The walls by name (the draw items' ``wall``).
WALLS = {"sheet": WALL_SHEET, "cycles": WALL_CYCLES, "solid": WALL_SOLID}


def fresnel_dielectric(cos_i, eta) -> np.ndarray:
    """Unpolarised Fresnel reflectance of a dielectric interface of relative index η at cos θᵢ
    (1 under total internal reflection), as tf_fresnel_dielectric."""
    c = np.clip(np.asarray(cos_i, dtype=np.float64), 0.0, 1.0)
    eta = float(eta)
    g2 = eta * eta - 1.0 + c * c
    g = np.sqrt(np.maximum(g2, 0.0))
    a = (g - c) / np.maximum(g + c, DIVISION_FLOOR)
    b = (c * (g + c) - 1.0) / np.maximum(c * (g - c) + 1.0, DIVISION_FLOOR)
    return np.where(g2 > 0.0, np.clip(0.5 * a * a * (1.0 + b * b), 0.0, 1.0), 1.0)


def wall_tint(wall) -> np.ndarray:
    """The transmission tint (3,) of a draw item's ``wall`` (mode, η[, r, g, b]): its last three
    entries, 1 where it has none (the extension's own walls)."""
    values = tuple(wall or ())
    return np.asarray(values[2:5] if len(values) >= 5 else (1.0, 1.0, 1.0), dtype=np.float64)


def tint_pass(tint, cos_v, eta: float) -> np.ndarray:
    """c (…, 3): the share of light a thin wall of index ``eta`` tinted ``tint`` (its transmittance
    at normal incidence) lets through in one pass at the outside cosine ``cos_v`` (…):
    tint^(1 / cos θ_t), θ_t the angle inside (Cycles' ``bsdf_thin_glass_fresnel``); 0 where
    the light cannot enter (cos θ_t = 0). As tf_tint_pass."""
    c = np.clip(np.asarray(cos_v, dtype=np.float64), 0.0, 1.0)
    eta = max(float(eta), WALL_GUARD)
    cos_t = np.sqrt(np.maximum(1.0 - (1.0 - c * c) / (eta * eta), 0.0))[..., None]
    tint = np.clip(np.asarray(tint, dtype=np.float64), 0.0, 1.0)
    return np.where(cos_t > 0.0, tint ** (1.0 / np.maximum(cos_t, WALL_GUARD)), 0.0)


def wall(r, cos_v, mode: int, eta: float = 1.0, tint=None) -> tuple[np.ndarray, np.ndarray]:
    """(T, S): the wall's transmittance and reflection scale per channel from the film's
    reflectance ``r`` (…, 3) at the view cosine ``cos_v`` (…), for ``mode`` (:data:`WALL_SHEET`
    with relative index ``eta``, or :data:`WALL_CYCLES`) and a transmission ``tint`` (3,), Cycles'
    thin wall's (:func:`tint_pass`; None: untinted; solid glass's T stays untinted). See the
    module's docstring."""
    r = np.clip(np.asarray(r, dtype=np.float64), 0.0, 1.0)
    if int(mode) == WALL_SOLID:
        return (1.0 - r) ** 2, np.ones_like(r)
    if int(mode) == WALL_CYCLES:
        if tint is None:
            return (1.0 - r) / (1.0 + r), 2.0 / (1.0 + r)
        c = tint_pass(tint, cos_v, eta)
        t = c * (1.0 - r) ** 2 / np.maximum(1.0 - (c * r) ** 2, WALL_GUARD)
        return t, 1.0 + t * c
    rb = fresnel_dielectric(np.clip(np.asarray(cos_v, dtype=np.float64), MIN_COS, 1.0), eta)[..., None]
    denominator = np.maximum(1.0 - r * rb, WALL_GUARD)
    t = (1.0 - r) * (1.0 - rb) / denominator
    extra = (1.0 - r) ** 2 * rb / denominator
    s = np.minimum(1.0 + extra / np.maximum(r, WALL_GUARD), WALL_SCALE_MAX)
    return t, s


def white_reflectance(film, rows, u) -> np.ndarray:
    """The film's reflectance of white light per channel (N, 3) at cosines ``u`` (N,) and the
    thickness ``rows`` of :func:`.lamps.thickness_lerp` (the spectral rows summed), as
    tf_film_white."""
    f = film_at(film, film.reflectance, rows, u)
    return f.sum(axis=-1) if film.spectral else f


def shade(film, normals, views, mode: int, eta: float = 1.0, thickness_position=None, tint=None):
    """(T, S), each (N, 3), of a wall at unit ``normals`` and view directions ``views`` (the
    normal faces the viewer, as in the shader); ``film``: a
    :class:`precompute.colour.film_colour.FilmTable`. Mirrored by tf_wall (glsl/tf_transmit.glsl)."""
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(views, dtype=np.float64).reshape(-1, 3)
    cos_v = np.clip(np.abs(np.sum(n * v, axis=-1)), 0.0, 1.0)
    rows = thickness_lerp(film, thickness_position, n.shape[0])
    return wall(white_reflectance(film, rows, cos_v), cos_v, mode, eta, tint)


def solid_exit(normals, views, eta: float) -> np.ndarray:
    """The direction (N, 3) a ray leaves a glass sphere of index η through which it entered at the
    unit normal ``normals`` from the viewer (unit ``views``): the incident direction −v turned
    towards −n by the sphere's deviation 2(θᵢ − θₜ) (no internal reflection), as tf_solid_exit."""
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(views, dtype=np.float64).reshape(-1, 3)
    ci = np.clip(np.sum(n * v, axis=-1), 0.0, 1.0)
    si = np.sqrt(np.maximum(1.0 - ci * ci, 0.0))
    deviation = 2.0 * (np.arcsin(np.minimum(si, 1.0)) - np.arcsin(np.minimum(si / max(eta, WALL_GUARD), 1.0)))
    w = ci[:, None] * v - n
    norm = np.linalg.norm(w, axis=-1, keepdims=True)
    w = np.where(norm > 1e-15, w / np.maximum(norm, 1e-300), 0.0)
    out = -np.cos(deviation)[:, None] * v + np.sin(deviation)[:, None] * w
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def solid_internal(normals, views, eta: float) -> np.ndarray:
    """The direction (N, 3) a ray leaves a glass sphere of index η after one reflection inside it
    (entered at the unit normal ``normals`` from the viewer, unit ``views``): −v turned towards −n
    by π + 2θᵢ − 4θₜ (the primary rainbow's deviation; straight back at normal incidence), as
    tf_solid_internal. Its weight is (1 − r)² r per channel: in through the film, reflected by it
    inside (a lossless film reflects the same from both sides), out through it."""
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(views, dtype=np.float64).reshape(-1, 3)
    ci = np.clip(np.sum(n * v, axis=-1), 0.0, 1.0)
    si = np.sqrt(np.maximum(1.0 - ci * ci, 0.0))
    theta_i = np.arcsin(np.minimum(si, 1.0))
    theta_t = np.arcsin(np.minimum(si / max(eta, WALL_GUARD), 1.0))
    deviation = np.pi + 2.0 * theta_i - 4.0 * theta_t
    w = ci[:, None] * v - n
    norm = np.linalg.norm(w, axis=-1, keepdims=True)
    w = np.where(norm > 1e-15, w / np.maximum(norm, 1e-300), 0.0)
    out = -np.cos(deviation)[:, None] * v + np.sin(deviation)[:, None] * w
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def composite(behind, reflected, t) -> np.ndarray:
    """What the two blend passes leave in the frame: ``behind`` × T + ``reflected`` (…, 3)."""
    return np.asarray(behind, dtype=np.float64) * t + np.asarray(reflected, dtype=np.float64)


def coverage(t) -> np.ndarray:
    """The alpha a wall writes over an empty background: 1 − mean(T) (…,)."""
    return 1.0 - np.mean(np.asarray(t, dtype=np.float64), axis=-1)


#: The largest GGX α (Principled *Roughness*²) at which Cycles lets a shadow ray through a thin
#: wall of an index other than 1: measured (Blender 5.2, tests/eevee/test_wall_shadows.py's sunlit
#: plate of IOR 1.1 and 1.52): Roughness 0.0044 lets the sun through, 0.0045 stops it.
CYCLES_SHADOW_ALPHA_MAX = 2.0e-5


def wall_stops_shadow_rays(eta: float, roughness: float) -> bool:
    """Whether Cycles stops a shadow ray at a thin wall of relative index ``eta`` and Principled
    ``roughness``: a rough wall (α = roughness² above :data:`CYCLES_SHADOW_ALPHA_MAX`) whose index
    is not 1. A wall of index 1 (a soap film on air) lets shadow rays through at any roughness.
    Cycles' light under such a wall comes only by other paths (bounced, through the wall's rough
    transmission): 0.25–0.67 of the open ground's light in the scenes measured
    (docs/eevee-native-results.md)."""
    return abs(float(eta) - 1.0) > 1e-6 and float(roughness) ** 2 > CYCLES_SHADOW_ALPHA_MAX


#: Samples in u = cos θ of Cycles' back-face film table (:func:`cycles_back_table`).
BACK_SAMPLES = 129


def cycles_back_table(material, samples: int = BACK_SAMPLES) -> np.ndarray | None:
    """Cycles' film seen from inside solid glass, per channel (``samples``, 3) at u uniform 0…1
    inside the glass, or None where Cycles' per-channel film does not apply (the spectral mode,
    a metal, several layers).

    At a back face Cycles divides the film's index by the glass's
    (``adjust_thin_film_ior_at_backface``, Blender 5.2): the light comes from an ambient of 1
    through a film of n_f / η onto a substrate of 1 / η, the same interfaces as the film seen from
    inside but an optical path η times shorter (an optically thinner film: its glints are cyan
    where the front's reflection of a 300 nm film of 1.33 on 1.5 is pink)."""
    from ..colour import film_channels
    from ..optics import belcour2017

    if material.colour_mode != "per_channel" or not material.layers:
        return None
    stack = film_channels.cycles_stack(material)
    if stack is None or stack.f82 is not None or np.any(np.imag(stack.substrate) != 0.0):
        return None
    eta = float(np.real(stack.substrate[0])) / float(stack.ambient)
    film = float(stack.film) / float(stack.ambient)
    back = belcour2017.FilmStack(1.0, film / eta, np.full(3, 1.0 / eta + 0j))
    u = np.linspace(0.0, 1.0, int(samples))
    d = float(material.thicknesses()[0])
    sens = film_channels.sensitivity(material.colour_space)
    return belcour2017.film_reflectance(back, u, d, sens)


def back_reflectance(film, rows, cos_inside, eta: float, table=None) -> np.ndarray:
    """The film's reflectance per channel (N, 3) seen from inside solid glass of index ``eta`` at
    the inside cosines ``cos_inside`` (N,): Cycles' back face from ``table``
    (:func:`cycles_back_table`, linear in u) where given, else the front film (``film``, thickness
    ``rows``) at the Snell-related outside cosine (a lossless film reflects the same from both
    sides), 1 under total internal reflection. As tf_glass_back_r."""
    c = np.clip(np.asarray(cos_inside, dtype=np.float64), 0.0, 1.0)
    if table is not None:
        t = np.asarray(table, dtype=np.float64)
        x = c * (t.shape[0] - 1)
        i0 = np.clip(np.floor(x).astype(np.int64), 0, t.shape[0] - 2)
        w = (x - i0)[:, None]
        return (1.0 - w) * t[i0] + w * t[i0 + 1]
    e = max(float(eta), WALL_GUARD)
    s2 = e * e * (1.0 - c * c)
    outside = np.sqrt(np.maximum(1.0 - s2, 0.0))
    r = np.clip(white_reflectance(film, rows, outside), 0.0, 1.0)
    return np.where((s2 >= 1.0)[:, None], 1.0, r)


# ----------------------------------------------------------------------------------------------
# A closed thin wall's reflections inside it (a bubble; see the module docstring)


@dataclass(frozen=True)
class Inside:
    """What a wall's mesh offers its reflections inside: ``closed`` (every edge shared by two
    triangles), ``fit`` (4,): the thickness parameter ≈ fit[:3]·p + fit[3] over object-space
    positions p (zeros for a constant thickness), and ``explained``: the share of the thickness's
    variance the fit explains (R²; 1 for a constant thickness)."""

    closed: bool
    fit: tuple = (0.0, 0.0, 0.0, 0.0)
    explained: float = 1.0

    @property
    def drawn(self) -> bool:
        """Whether the draw adds the reflections inside: a closed mesh whose thickness the fit
        explains (:data:`.policy.INSIDE_MIN_EXPLAINED`; a noise is not: module docstring)."""
        return self.closed and self.explained >= INSIDE_MIN_EXPLAINED


def _welded(positions: np.ndarray) -> np.ndarray:
    """Per-corner ids (int64) equal where the corners share a position exactly (the corners of
    one vertex): a sort of the positions' bits (0.2 s for a million corners)."""
    bits = np.ascontiguousarray(np.asarray(positions, dtype=np.float32).reshape(-1, 3)).view(np.uint32)
    order = np.lexsort((bits[:, 2], bits[:, 1], bits[:, 0]))
    ordered = bits[order]
    new = np.ones(len(ordered), dtype=bool)
    new[1:] = np.any(ordered[1:] != ordered[:-1], axis=1)
    ids = np.empty(len(ordered), dtype=np.int64)
    ids[order] = np.cumsum(new) - 1
    return ids


def _closed(ids: np.ndarray) -> bool:
    """Whether every edge of the (F, 3) triangles of vertex ``ids`` is shared by exactly two."""
    edges = np.sort(np.concatenate([ids[:, [0, 1]], ids[:, [1, 2]], ids[:, [2, 0]]]), axis=1)
    edges = edges[edges[:, 0] != edges[:, 1]]  # degenerate triangles' collapsed edges
    if edges.shape[0] == 0:
        return False
    keys = np.sort(edges[:, 0] * (int(ids.max()) + 1) + edges[:, 1])
    starts = np.flatnonzero(np.concatenate([[True], keys[1:] != keys[:-1], [True]]))
    return bool(np.all(np.diff(starts) == 2))


#: Corners a thickness fit reads at most (every k-th beyond): the fit of a million corners is as
#: good from a tenth of them, and the batch build stays short.
FIT_CORNERS = 100_000


def mesh_inside(positions, triangles, thickness=None) -> Inside:
    """:class:`Inside` of a mesh given per corner: (V, 3) ``positions``, (F, 3) ``triangles``
    (corner indices) and the optional (V,) ``thickness`` parameter in [0, 1]. About 0.4 s for a
    million corners (the batch build, not a draw)."""
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if tris.shape[0] == 0:
        return Inside(False)
    closed = _closed(_welded(positions)[tris])
    if thickness is None:
        return Inside(closed)
    step = max(1, len(thickness) // FIT_CORNERS)
    pos = np.asarray(positions, dtype=np.float64).reshape(-1, 3)[::step]
    th = np.asarray(thickness, dtype=np.float64).reshape(-1)[::step]
    ok = np.isfinite(th)
    if ok.sum() < 4:
        return Inside(closed, (0.0, 0.0, 0.0, float(np.nanmean(th)) if ok.any() else 0.5))
    design = np.concatenate([pos[ok], np.ones((int(ok.sum()), 1))], axis=1)
    coefficients = np.linalg.lstsq(design, th[ok], rcond=None)[0]
    total = float(np.sum((th[ok] - th[ok].mean()) ** 2))
    residual = float(np.sum((design @ coefficients - th[ok]) ** 2))
    explained = 1.0 if total <= 1e-12 * ok.sum() else max(0.0, 1.0 - residual / total)
    return Inside(closed, tuple(float(c) for c in coefficients), explained)


def world_fit(fit, model) -> np.ndarray:
    """The object-space ``fit`` (4,) over world positions under the 4×4 ``model`` matrix:
    g·M⁻¹(p − o) + a = (M⁻ᵀ g)·p + (a − (M⁻ᵀ g)·o)."""
    fit = np.asarray(fit, dtype=np.float64).reshape(4)
    m = np.asarray(model, dtype=np.float64).reshape(4, 4)
    g = np.linalg.pinv(m[:3, :3]).T @ fit[:3]
    return np.array([*g, fit[3] - g @ m[:3, 3]])


def inside_path(points, directions, centre, orders: int = INSIDE_ORDERS + 1) -> list:
    """The ray inside the sphere about ``centre`` through ``points`` (N, 3), leaving them along
    ``directions`` (N, 3, into the sphere): ``orders`` hits, each (points, directions reflected
    there, cosine), as ``tf_inside_step``. A direction that does not enter the sphere stays where
    it is with cosine 0 (:func:`inside_reflections` then lets it leave freely)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    c = np.asarray(centre, dtype=np.float64).reshape(3)
    hits = []
    for _ in range(orders):
        chord = np.maximum(-2.0 * np.sum((p - c) * d, axis=-1), 0.0)
        p = p + chord[:, None] * d
        radius = p - c
        length = np.linalg.norm(radius, axis=-1, keepdims=True)
        n = np.where(length > 0.0, radius / np.maximum(length, 1e-300), -d)  # outward
        cos = np.clip(np.sum(d * n, axis=-1), 0.0, 1.0)
        d = d - 2.0 * np.sum(d * n, axis=-1, keepdims=True) * n
        hits.append((p, d, np.where(chord > 0.0, cos, 0.0)))
    return hits


def inside_reflections(film, points, normals, views, centre, fit, mode: int, eta: float, tint, radiance):
    """(T₂, extra), each (N, 3): the far wall's reflection is S₁r₁·L(d₁)·T₂ + R₁·extra (module
    docstring). ``points`` on the far wall with ``normals`` facing the viewer (inward) and
    ``views`` towards the viewer; ``fit``: :func:`world_fit` (None: a constant thickness, the
    table's first row); ``radiance``: directions (N, 3) → (N, 3), the World along them."""
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(views, dtype=np.float64).reshape(-1, 3)
    d1 = -v + 2.0 * np.sum(v * n, axis=-1, keepdims=True) * n  # reflect(-v, n)
    hits = inside_path(points, d1, centre)

    def wall_at(p, cos):
        position = None if fit is None else np.clip(p @ np.asarray(fit[:3]) + fit[3], 0.0, 1.0)
        rows = thickness_lerp(film, position, p.shape[0])
        r = np.clip(white_reflectance(film, rows, cos), 0.0, 1.0)
        t, s = wall(r, cos, mode, eta, tint)
        return s * r, t

    reflectance, exit_t = wall_at(hits[0][0], hits[0][2])
    extra = np.zeros_like(exit_t)
    carried = np.ones_like(exit_t)
    for (_p, d, _cos), (p_next, _d, cos_next) in zip(hits[:-1], hits[1:], strict=True):
        carried = carried * reflectance
        reflectance, t_next = wall_at(p_next, cos_next)
        extra = extra + carried * t_next * radiance(d)
    entered = (hits[0][2] > 0.0)[:, None]  # else d₁ leaves the sphere at once: freely
    return np.where(entered, exit_t, 1.0), np.where(entered, extra, 0.0)
