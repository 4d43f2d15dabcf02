"""Rough glass for the photons of :mod:`.caustics`: Cycles' *Filter Glossy* and GGX facets.

Cycles finds a caustic from the diffuse surface it lands on (the bounce's pdf p = cos θ / π) and
its Filter Glossy (``scene.cycles.blur_glossy``, 1 by default) then draws every later BSDF at
least as rough as α = ½ √(1 − p / blur_glossy) (``surface_shader_prepare_closures``,
``bsdf_microfacet_blur``): the glass on a caustic's path is rough, α 0.41–0.5, and, the blur set
after the closure's energy compensation, single-scattering GGX. A photon meets such glass at a
facet drawn from GGX's distribution of visible normals (Heitz 2018) as it sees the surface, is
refracted or reflected there, and is weighted by Smith's G2 / G1 (:func:`masking`).
"""

from __future__ import annotations

import numpy as np

from ..brdf import lambda_ggx
from ..brdf import reflect as mirror
from ..shading.frame import view_aligned_frame
from ..shading.glass.refract import refract


def reflect(d, n):
    """The ray ``d`` (…, 3) travelling on after a mirror at the unit normals ``n``
    (:func:`precompute.brdf.reflect` mirrors a direction pointing away)."""
    return -mirror(d, n)


def blur_roughness(cos_receiver, blur_glossy: float):
    """Cycles' *Filter Glossy* (``scene.cycles.blur_glossy``, 1 by default): after a bounce of
    pdf p every later BSDF is at least as rough as α = ½ √(1 − p / blur_glossy) (Cycles'
    ``surface_shader_prepare_closures``). A caustic is found from the diffuse receiver, p =
    cos θ / π, so Cycles draws the glass rough on its caustic paths: α 0.41 (cos 1) to 0.5
    (grazing) at the default. 0 where the filter is off (``blur_glossy`` 0). A float, or an
    array of ``cos_receiver``'s shape."""
    if not blur_glossy > 0.0:
        return np.zeros(np.shape(cos_receiver)) if np.ndim(cos_receiver) else 0.0
    p = np.maximum(np.asarray(cos_receiver, dtype=np.float64), 0.0) / np.pi / float(blur_glossy)
    alpha = np.where(p < 1.0, 0.5 * np.sqrt(np.maximum(1.0 - p, 0.0)), 0.0)
    return alpha if alpha.ndim else float(alpha)


def photon_roughness(landing, towards_light, blur_glossy: float) -> np.ndarray:
    """Each photon's roughness (N,) under Cycles' Filter Glossy: :func:`blur_roughness` at its
    landing cosine (:attr:`.caustics.Records.landing` of a smooth trace); a photon that did not land takes
    the sun's height as its cosine (the receiver taken as level ground)."""
    cos = np.asarray(landing, dtype=np.float64)
    cos = np.where(np.isfinite(cos), cos, max(float(np.asarray(towards_light)[2]), 0.0))
    return np.asarray(blur_roughness(cos, blur_glossy), dtype=np.float64).reshape(cos.shape)


def microfacets(n, view, alpha, rng, valid, tries: int = 8):
    """GGX microfacet normals (M, 3) about the unit normals ``n`` (M, 3) of roughness ``alpha``
    (one, or one per row; 0: the normal itself) as the unit directions ``view`` (M, 3; on n's
    side) see them: the distribution of visible normals, D(m) max(0, v · m) G1(v) / (v · n),
    drawn by Heitz's (2018) sampling of the stretched hemisphere. A draw that ``valid(rows, m)``
    (bool per row) refuses is drawn again, up to ``tries`` times, then the normal itself stands."""
    n = np.asarray(n, dtype=np.float64)
    out = n.copy()
    rough = np.broadcast_to(np.asarray(alpha, dtype=np.float64), (len(n),))
    view = np.asarray(view, dtype=np.float64)
    todo = np.flatnonzero(rough > 0.0)
    for _ in range(tries):
        if todo.size == 0:
            break
        a = rough[todo][:, None]
        stretch = np.concatenate([a, a, np.ones_like(a)], axis=-1)
        frame = view_aligned_frame(n[todo], view[todo])  # rows x, y, z = n; the view in x-z
        local = np.einsum("mij,mj->mi", frame, view[todo])
        local[:, 2] = np.maximum(local[:, 2], 1e-6)
        vh = local * stretch
        vh /= np.linalg.norm(vh, axis=-1, keepdims=True)
        length = np.hypot(vh[:, 0], vh[:, 1])
        t1 = np.where(
            length[:, None] > 1e-12,
            np.stack([-vh[:, 1], vh[:, 0], np.zeros_like(length)], -1) / np.maximum(length, 1e-12)[:, None],
            np.array([[1.0, 0.0, 0.0]]),
        )
        t2 = np.cross(vh, t1)
        r, phi = np.sqrt(rng.random(todo.size)), 2.0 * np.pi * rng.random(todo.size)
        p1, p2 = r * np.cos(phi), r * np.sin(phi)
        s = 0.5 * (1.0 + vh[:, 2])
        p2 = (1.0 - s) * np.sqrt(np.maximum(1.0 - p1 * p1, 0.0)) + s * p2
        p3 = np.sqrt(np.maximum(1.0 - p1 * p1 - p2 * p2, 0.0))
        nh = p1[:, None] * t1 + p2[:, None] * t2 + p3[:, None] * vh
        ml = nh * stretch
        ml[:, 2] = np.maximum(ml[:, 2], 0.0)
        ml /= np.linalg.norm(ml, axis=-1, keepdims=True)
        m = np.einsum("mij,mi->mj", frame, ml)
        ok = np.asarray(valid(todo, m), dtype=bool)
        out[todo[ok]] = m[ok]
        todo = todo[~ok]
    return out


def masking(cos_view, cos_out, alpha) -> np.ndarray:
    """The weight of a direction drawn through a visible normal (:func:`microfacets`): Smith's
    height-correlated G2 / G1 = (1 + Λ(v)) / (1 + Λ(v) + Λ(l)), the cosines to the surface's
    normal (absolute). Single scattering: the light the facets shadow is lost, as on Cycles'
    blurred glass, whose energy compensation is set before the blur (its roughness then ≈ 0)."""
    lv = lambda_ggx(np.abs(cos_view), alpha)
    return (1.0 + lv) / (1.0 + lv + lambda_ggx(np.abs(cos_out), alpha))


def entering(d, n, eta):
    """A microfacet test for rays ``d`` meeting glass from outside at macro normals ``n``: the
    facet faces the ray, its reflection leaves the surface and its refraction enters it."""

    def valid(rows, m):
        dd, nn = d[rows], n[rows]
        faces = np.sum(dd * m, axis=-1) < 0.0
        up = np.sum(reflect(dd, m) * nn, axis=-1) > 0.0
        down = np.sum(refract(dd, m, 1.0 / eta) * nn, axis=-1) < 0.0
        return faces & up & down

    return valid


def leaving(d, n, eta):
    """The same from inside (``n`` outward, the facets drawn about −n): the facet faces the ray,
    its reflection stays inside and its refraction, where there is one, leaves."""

    def valid(rows, inward):
        dd, nn, m = d[rows], n[rows], -inward
        c = np.sum(dd * m, axis=-1)
        total = eta * eta * (1.0 - c * c) >= 1.0
        stays = np.sum(reflect(dd, m) * nn, axis=-1) < 0.0
        leaves = total | (np.sum(refract(dd, -m, eta) * nn, axis=-1) > 0.0)
        return (c > 0.0) & stays & leaves

    return valid


def weights(alpha, macro, d, *outgoing):
    """:func:`masking` (M, 1) of each ``outgoing`` direction (M, 3) of rays ``d`` at the surface's
    ``macro`` normals; ones for smooth glass."""
    if not np.any(alpha > 0.0):
        return tuple(np.ones((len(d), 1)) for _ in outgoing)
    cv = np.sum(d * macro, axis=-1)
    return tuple(masking(cv, np.sum(o * macro, axis=-1), alpha)[:, None] for o in outgoing)
