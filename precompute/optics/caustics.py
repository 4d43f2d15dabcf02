"""Solid glass's shadow and caustics on what it stands on, for EEVEE's background pass.

EEVEE's shadow of a glass object is a shadow map: opaque, or (transparent shadows) a straight
ray's loss. Cycles bends the light: a glass ball's shadow is dark where the ball refracts the
light away and bright where it focuses it, and the light the film reflects lands beside it.
The background pass therefore renders the sun lamps' shadow of solid glass opaque and this
module puts back the light that went through, or off, the glass (``addon/headless/caustics.py``
drives it in Blender):

1. **Photons.** For each sun (direction, irradiance E), a square grid of parallel rays
   (:func:`photon_grid`, ``CAUSTIC_GRID``² over the glass's bounding sphere) each carries the
   flux E h² of its cell (h its spacing). :func:`trace` follows them: into the glass through the
   film (1 − r at the entry cosine, the reflected share r goes on outside), through its real mesh
   (the caller's ray casts), totally reflected inside where the angle passes the critical one,
   out through the film (1 − r_b), until they meet something that is not glass: a receiver.
   Each reflection by the film, outside (r) or inside (r_b), starts a branch of its own,
   ``CAUSTIC_REFLECTIONS`` of them on a path at most (each crossing of a thin wall would
   otherwise double the rays).
2. **Caustic cells.** Four neighbouring photons that took the same kind of path (the same events
   at the film, the same receiver) bound a cell of the light's cross-section whose image on the
   receiver is the quad of their hit points: the cell's flux (the corners' mean) is spread over
   that quad by bilinear sub-points (:func:`splat`), as many as the quad covers pixels × 4, so the
   irradiance is the flux over the quad's area, a focus included (the sum of the cells that
   overlap there). Cells whose corners part (another receiver, another path, a quad wider than
   ``CAUSTIC_MAX_EXTENT`` pixels) give each of their photons' share to its own pixel.
3. **Irradiance.** Each pixel's flux over its footprint on the receiver (the pixel's solid angle ×
   distance² / |n · r|, :func:`footprint`) is the irradiance the glass sends there, which the
   pass's diffuse colour turns into radiance (× albedo / π).
4. **Rough glass.** Where Cycles' Filter Glossy makes the glass rough on a caustic's path
   (:mod:`.facets`), :func:`trace` takes a roughness per photon and meets each face at a GGX
   facet; such photons scatter apart, so :func:`splat` lands each at its own point
   (``cells=False``) and :func:`smooth` averages them into a density.

Glass of index 1 without a film sends every photon straight on with its flux: the irradiance
is E cos θ wherever the glass's shadow falls, the light as if the glass were not there
(tests/optics/test_caustics.py, and in Blender tests/headless/test_background_lamps.py).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..shading.glass.refract import refract
from ..shading.policy import (
    CAUSTIC_BOUNCES,
    CAUSTIC_DEPTH_SLACK,
    CAUSTIC_DISC_SAMPLES,
    CAUSTIC_GRID,
    CAUSTIC_MAX_EXTENT,
    CAUSTIC_MAX_SUB,
    CAUSTIC_MIN_FLUX,
    CAUSTIC_REFLECTIONS,
)
from ..shading.transmit import fresnel_dielectric
from . import facets

#: Path events, each a base-4 digit of a photon's path key (its first digit never 0, so every
#: sequence is its own key): reflected totally inside, into the glass, reflected off its
#: outside, reflected by the film inside.
TOTAL, ENTER, REFLECT_OUT, REFLECT_IN = 0, 1, 2, 3
#: A key past this takes no more total reflections (an int64 holds 31 digits; a light-guided
#: photon may reflect totally up to CAUSTIC_BOUNCES times in each glass it crosses).
KEY_LIMIT = 4**28
#: Casts: what an outside ray met (:func:`trace`'s ``cast_outside``).
MISS = -1


@dataclass(frozen=True)
class GlassOptics:
    """One solid glass object's optics for its photons: relative index ``eta``; ``front``
    (cos (N,) → reflectance (N, 3)) from outside at the outside cosine; ``back`` (cos (N,) →
    (N, 3)) from inside at the inside cosine, where the light can leave (total internal
    reflection is decided here)."""

    eta: float
    front: Callable
    back: Callable


def plain_glass(eta: float) -> GlassOptics:
    """Glass of relative index ``eta`` without a film: the dielectric's Fresnel reflectance on
    both sides (from inside at the Snell-related outside cosine)."""
    eta = float(eta)

    def front(c):
        return np.repeat(fresnel_dielectric(c, eta)[:, None], 3, axis=1)

    def back(c):
        c = np.clip(np.asarray(c, dtype=np.float64), 0.0, 1.0)
        outside = np.sqrt(np.maximum(1.0 - eta * eta * (1.0 - c * c), 0.0))
        return front(outside)

    return GlassOptics(eta, front, back)


def across(d) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (u, v) across the unit direction ``d``, d × u = v."""
    helper = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(d, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(d, u)


def photon_grid(centre, radius: float, towards_light, n: int = CAUSTIC_GRID):
    """(origins (n², 3), direction (3,), cell area h²): an n × n grid of parallel rays along
    −``towards_light`` over the disc's bounding square of ``radius`` about ``centre``, starting
    2 radii before it (row-major: photon i·n + j)."""
    d = -np.asarray(towards_light, dtype=np.float64)
    d = d / np.linalg.norm(d)
    u, v = across(d)
    h = 2.0 * float(radius) / n
    s = (np.arange(n) + 0.5) * h - float(radius)
    a, b = np.meshgrid(s, s, indexing="ij")
    start = np.asarray(centre, dtype=np.float64) - 2.0 * float(radius) * d
    origins = start + a.reshape(-1, 1) * u + b.reshape(-1, 1) * v
    return origins, d, h * h


def disc_directions(towards_light, angle: float, count: int = CAUSTIC_DISC_SAMPLES) -> np.ndarray:
    """Directions (K, 3) towards a sun of angular diameter ``angle`` (radians), each carrying 1/K
    of its light: its centre alone where ``count`` is 1 or the sun a point; else the centre and
    ``count`` − 1 directions on the ring at √½ of its radius (the disc's rms radius), so the
    shadow's and the caustics' edges soften as the pass's soft shadow does."""
    d = np.asarray(towards_light, dtype=np.float64)
    d = d / np.linalg.norm(d)
    if count <= 1 or not angle > 0.0:
        return d[None]
    u, v = across(d)
    r = np.tan(0.5 * float(angle)) * np.sqrt(0.5)
    phi = 2.0 * np.pi * np.arange(count - 1) / (count - 1)
    ring = d + r * (np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v)
    out = np.concatenate([d[None], ring])
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


@dataclass
class Records:
    """Where a sun's photons ended on receivers: per path key, photon index (M,), hit point
    (M, 3), flux (M, 3) and receiver id (M,); ``landing`` (N,): each photon's cosine to the
    receiver's normal where it first landed (NaN where it did not)."""

    paths: dict
    landing: np.ndarray | None = None

    def add(self, key, photon, point, flux, receiver):
        """Record photons (arrays as :func:`trace` holds them) under their path keys."""
        for k in np.unique(key):
            sel = key == k
            self.paths.setdefault(int(k), []).append((photon[sel], point[sel], flux[sel], receiver[sel]))

    def arrays(self):
        """{key: (photon, point, flux, receiver)}, each key's pieces joined."""
        return {
            k: tuple(np.concatenate([piece[i] for piece in pieces]) for i in range(4))
            for k, pieces in self.paths.items()
        }


def trace(origins, direction, flux, glasses, cast_outside, cast_inside, scale=1.0, alpha=0.0, seed=0):
    """Follow photons from ``origins`` (N, 3) along ``direction`` (3,), each carrying ``flux``
    (N, 3), through the solid glass objects ``glasses`` (list of :class:`GlassOptics`); see the
    module. The casts are the caller's:

    - ``cast_outside(o, d)`` → (glass (M,) index into ``glasses`` or −1, receiver (M,) id ≥ 0 or
      −1, points (M, 3), normals (M, 3) unit, outward, smooth): the first thing each ray meets.
    - ``cast_inside(g, o, d)`` → (hit (M,) bool, points, normals outward): where a ray inside
      glass ``g`` meets its surface.

    ``scale``: the scene's size (the glass's radius), for the step off a surface. Photons that
    meet a receiver before any glass are not recorded (the pass lights them); ``cast_outside``'s
    normals at a receiver are its own, for :attr:`Records.landing`. ``alpha``: the glass drawn
    rough (GGX, :func:`.facets.blur_roughness`; one, or one per photon), each photon meeting each face at
    a microfacet drawn from ``seed``'s generator; 0: smooth. Returns :class:`Records`."""
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    n_rays = o.shape[0]
    d = np.broadcast_to(np.asarray(direction, dtype=np.float64), o.shape).copy()
    f = np.asarray(flux, dtype=np.float64).reshape(n_rays, 3).copy()
    floor = CAUSTIC_MIN_FLUX * float(np.max(f)) if f.size else 0.0
    photon = np.arange(n_rays)
    key = np.zeros(n_rays, dtype=np.int64)
    inside = np.full(n_rays, -1)
    faces = np.zeros(n_rays, dtype=np.int64)
    orders = np.zeros(n_rays, dtype=np.int64)
    eps = 1e-5 * float(scale)
    rng = np.random.default_rng(seed)
    rough = np.broadcast_to(np.asarray(alpha, dtype=np.float64), (n_rays,))
    records = Records({}, np.full(n_rays, np.nan))
    for _ in range(4 * (CAUSTIC_BOUNCES + CAUSTIC_REFLECTIONS + 2)):
        if photon.size == 0:
            break
        nxt = []
        out = inside < 0
        if np.any(out):
            idx = np.flatnonzero(out)
            g, rec, p, nrm = cast_outside(o[idx] + eps * d[idx], d[idx])
            seen = (rec >= 0) & (key[idx] != 0)
            if np.any(seen):
                s = idx[seen]
                records.add(key[s], photon[s], p[seen], f[s], rec[seen])
                first = np.isnan(records.landing[photon[s]])
                records.landing[photon[s][first]] = np.abs(np.sum(d[s] * nrm[seen], axis=-1))[first]
            for gi in np.unique(g[g >= 0]):
                sel = g == gi
                s = idx[sel]
                optics = glasses[int(gi)]
                dd, nn, pp = d[s], nrm[sel], p[sel]
                a = rough[photon[s]]
                if np.any(a > 0.0):
                    nn = facets.microfacets(nn, -dd, a, rng, facets.entering(dd, nrm[sel], optics.eta))
                c = np.clip(-np.sum(dd * nn, axis=-1), 0.0, 1.0)
                r = np.clip(optics.front(c), 0.0, 1.0)
                inward, outward = refract(dd, nn, 1.0 / optics.eta), facets.reflect(dd, nn)
                wi, wo = facets.weights(a, nrm[sel], dd, inward, outward)
                ks, od = key[s] * 4, orders[s]
                nxt.append((pp, inward, f[s] * (1.0 - r) * wi, photon[s], ks + ENTER, int(gi), 0, od))
                nxt.append((pp, outward, f[s] * r * wo, photon[s], ks + REFLECT_OUT, -1, 0, od + 1))
        for gi in np.unique(inside[inside >= 0]):
            idx = np.flatnonzero(inside == gi)
            optics = glasses[int(gi)]
            hit, p, nrm = cast_inside(int(gi), o[idx] + eps * d[idx], d[idx])
            idx, p, nrm = idx[hit], p[hit], nrm[hit]
            dd, macro = d[idx], nrm
            a = rough[photon[idx]]
            if np.any(a > 0.0):
                nrm = -facets.microfacets(-nrm, -dd, a, rng, facets.leaving(dd, nrm, optics.eta))
            c = np.clip(np.sum(dd * nrm, axis=-1), 0.0, 1.0)
            total = optics.eta * optics.eta * (1.0 - c * c) >= 1.0
            mirrored = facets.reflect(dd, nrm)
            leaving = refract(dd, -nrm, optics.eta)
            wl, wm = facets.weights(a, macro, dd, leaving, mirrored)
            t = idx[total]
            nxt.append(
                (
                    p[total],
                    mirrored[total],
                    f[t] * wm[total],
                    photon[t],
                    np.where(key[t] < KEY_LIMIT, key[t] * 4 + TOTAL, key[t]),
                    int(gi),
                    faces[t] + 1,
                    orders[t],
                )
            )
            e = idx[~total]
            rb = np.clip(optics.back(c[~total]), 0.0, 1.0)
            nxt.append(
                (
                    p[~total],
                    leaving[~total],
                    f[e] * (1.0 - rb) * wl[~total],
                    photon[e],
                    key[e],
                    -1,
                    0,
                    orders[e],
                )
            )
            nxt.append(
                (
                    p[~total],
                    mirrored[~total],
                    f[e] * rb * wm[~total],
                    photon[e],
                    key[e] * 4 + REFLECT_IN,
                    int(gi),
                    faces[e] + 1,
                    orders[e] + 1,
                )
            )
        parts = []
        for p, dd, ff, ph, kk, where, fc, od in nxt:
            m = len(ph)
            fc = np.broadcast_to(fc, (m,))
            od = np.broadcast_to(od, (m,))
            keep = (np.max(ff, axis=-1) > floor) & (fc <= CAUSTIC_BOUNCES) & (od <= CAUSTIC_REFLECTIONS)
            if np.any(keep):
                parts.append(
                    (
                        p[keep],
                        dd[keep],
                        ff[keep],
                        ph[keep],
                        kk[keep],
                        np.full(int(keep.sum()), where),
                        fc[keep],
                        od[keep],
                    )
                )
        if not parts:
            break
        o, d, f, photon, key, inside, faces, orders = (
            np.concatenate([q[i] for q in parts]) for i in range(8)
        )
        inside = inside.astype(np.int64)
    return records


@dataclass(frozen=True)
class Camera:
    """The pass's camera: ``view`` (4, 4) world → camera, ``projection`` (4, 4), the image
    ``width`` × ``height`` (row 0 at the top), ``ortho``."""

    view: np.ndarray
    projection: np.ndarray
    width: int
    height: int
    ortho: bool = False

    def project(self, points):
        """(rows, cols, depth along the camera axis) of world ``points`` (N, 3), pixel units
        (pixel (i, j) covers rows i … i + 1)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        cam = p @ self.view[:3, :3].T + self.view[:3, 3]
        clip = cam @ self.projection[:, :3].T + self.projection[:, 3]
        w = np.where(np.abs(clip[:, 3]) > 1e-300, clip[:, 3], 1e-300)
        cols = (clip[:, 0] / w + 1.0) * 0.5 * self.width
        rows = (1.0 - clip[:, 1] / w) * 0.5 * self.height
        return rows, cols, -cam[:, 2]


def projected_radius(camera: Camera, centre, radius: float) -> float:
    """The pixels a sphere of ``radius`` about ``centre`` spans from its middle on the picture
    (its half height, roughly), at least one."""
    _, _, z = camera.project(np.asarray(centre, dtype=np.float64)[None])
    scale = 0.5 * camera.height * abs(float(camera.projection[1, 1])) * float(radius)
    return max(scale if camera.ortho else scale / max(float(z[0]), 1e-9), 1.0)


def footprint(camera: Camera, depth, normals) -> np.ndarray:
    """Each pixel's area (H, W) on the surface it sees: depth along the camera axis ``depth``
    (H, W, ``inf`` where nothing is) and unit world normals ``normals`` (H, W, 3); its solid angle
    × distance² over |n · r| (|n · r| at least 0.05), ``inf`` where nothing is."""
    h, w = depth.shape
    pr = np.asarray(camera.projection, dtype=np.float64)
    sx, sy = 2.0 / (pr[0, 0] * w), 2.0 / (pr[1, 1] * h)
    x = (np.arange(w) + 0.5) / w * 2.0 - 1.0
    y = 1.0 - (np.arange(h) + 0.5) / h * 2.0
    xx, yy = np.meshgrid(x, y)
    if camera.ortho:
        ray = np.broadcast_to(np.array([0.0, 0.0, -1.0]), (h, w, 3))
        scale = np.full((h, w), sx * sy)
    else:
        q = np.stack([(xx + pr[0, 2]) / pr[0, 0], (yy + pr[1, 2]) / pr[1, 1], -np.ones_like(xx)], axis=-1)
        length = np.linalg.norm(q, axis=-1)
        ray = q / length[..., None]
        z = np.where(np.isfinite(depth), depth, 0.0)
        scale = sx * sy * z * z / length  # (s z)² cos α, cos α = 1 / |q|
    n_cam = np.asarray(normals, dtype=np.float64) @ np.asarray(camera.view, dtype=np.float64)[:3, :3].T
    facing = np.maximum(np.abs(np.sum(n_cam * ray, axis=-1)), 0.05)
    return np.where(np.isfinite(depth), scale / facing, np.inf)


def _deposit(acc, camera, depth, points, flux):
    """Add ``flux`` (N, 3) at world ``points`` to ``acc`` (H, W, 3): each point shared among the
    four pixels about it by bilinear weights (a lattice of points finer than the pixels then sums
    to its density without beats), among those of them whose depth is the point's (within
    CAUSTIC_DEPTH_SLACK: a pixel that sees another surface takes none of it)."""
    rows, cols, z = camera.project(points)
    h, w = depth.shape
    fr, fc = rows - 0.5, cols - 0.5
    ok = np.isfinite(z) & (fr > -1.0) & (fr < h) & (fc > -1.0) & (fc < w)
    fr, fc, z, flux = fr[ok], fc[ok], z[ok], flux[ok]
    i0, j0 = np.floor(fr).astype(np.int64), np.floor(fc).astype(np.int64)
    ti, tj = fr - i0, fc - j0
    taps = []
    for a in (0, 1):
        for b in (0, 1):
            i, j = i0 + a, j0 + b
            inside = (i >= 0) & (i < h) & (j >= 0) & (j < w)
            there = depth[np.clip(i, 0, h - 1), np.clip(j, 0, w - 1)]
            seen = inside & (np.abs(z - there) <= CAUSTIC_DEPTH_SLACK * np.abs(there))
            weight = (ti if a else 1.0 - ti) * (tj if b else 1.0 - tj) * seen
            taps.append((i, j, weight))
    total = sum(t[2] for t in taps)
    for i, j, weight in taps:
        sel = weight > 0.0
        flat = i[sel] * w + j[sel]
        share = weight[sel] / total[sel]
        for c in range(3):
            acc[..., c] += np.bincount(flat, weights=flux[sel, c] * share, minlength=h * w).reshape(h, w)


def splat(records: Records, n: int, camera: Camera, depth, cells: bool = True) -> np.ndarray:
    """The flux (H, W, 3) the photons of ``records`` (from an n × n :func:`photon_grid`) bring to
    each pixel of the pass (``depth``: its depth along the camera axis), by caustic cells (see the
    module); photons on surfaces the camera does not see there (depth off by more than
    ``CAUSTIC_DEPTH_SLACK``) are left out. ``cells`` False: each photon at its own point (rough
    glass's photons, whose neighbours scatter apart; :func:`smooth` then)."""
    h, w = depth.shape
    acc = np.zeros((h, w, 3))
    pending, count = [], 0

    def deposit(points, flux, flush=False):
        # one deposit per few million points: each call sums over the whole image
        nonlocal count
        if len(points):
            pending.append((points, flux))
            count += len(points)
        if pending and (flush or count > 4_000_000):
            _deposit(
                acc,
                camera,
                depth,
                np.concatenate([q[0] for q in pending]),
                np.concatenate([q[1] for q in pending]),
            )
            pending.clear()
            count = 0

    for _key, (photon, point, flux, receiver) in records.arrays().items():
        if not cells:
            deposit(point, flux)
            continue
        grid_p = np.full((n * n, 3), np.nan)
        grid_f = np.zeros((n * n, 3))
        grid_r = np.full(n * n, -1)
        grid_p[photon], grid_f[photon], grid_r[photon] = point, flux, receiver
        grid_p, grid_f, grid_r = grid_p.reshape(n, n, 3), grid_f.reshape(n, n, 3), grid_r.reshape(n, n)
        rows, cols, _ = camera.project(grid_p.reshape(-1, 3))
        pix = np.stack([rows, cols], axis=-1).reshape(n, n, 2)
        corners = [
            (slice(0, -1), slice(0, -1)),
            (slice(1, None), slice(0, -1)),
            (slice(0, -1), slice(1, None)),
            (slice(1, None), slice(1, None)),
        ]
        cp = [grid_p[c] for c in corners]
        cf = [grid_f[c] for c in corners]
        cr = [grid_r[c] for c in corners]
        cx = [pix[c] for c in corners]
        valid = [r >= 0 for r in cr]
        whole = (
            valid[0] & valid[1] & valid[2] & valid[3] & (cr[0] == cr[1]) & (cr[0] == cr[2]) & (cr[0] == cr[3])
        )
        extent = np.zeros(whole.shape)
        for a in range(4):
            for b in range(a + 1, 4):
                extent = np.maximum(extent, np.nan_to_num(np.max(np.abs(cx[a] - cx[b]), axis=-1), nan=np.inf))
        whole &= extent <= CAUSTIC_MAX_EXTENT
        # a cell's photons that do not make a whole cell: each its quarter share at its own point
        for a in range(4):
            part = valid[a] & ~whole
            deposit(cp[a][part], 0.25 * cf[a][part])
        cell_flux = 0.25 * (cf[0] + cf[1] + cf[2] + cf[3])
        k = np.clip(np.ceil(2.0 * extent), 1, CAUSTIC_MAX_SUB).astype(np.int64)
        for kk in np.unique(k[whole]):
            sel = whole & (k == kk)
            s = (np.arange(kk) + 0.5) / kk
            ss, tt = np.meshgrid(s, s, indexing="ij")
            ss, tt = ss.reshape(1, -1, 1), tt.reshape(1, -1, 1)
            p00, p10, p01, p11 = (c[sel][:, None, :] for c in cp)
            pts = (1 - ss) * (1 - tt) * p00 + ss * (1 - tt) * p10 + (1 - ss) * tt * p01 + ss * tt * p11
            fl = np.repeat(cell_flux[sel][:, None, :] / (kk * kk), kk * kk, axis=1)
            deposit(pts.reshape(-1, 3), fl.reshape(-1, 3))
    deposit(np.zeros((0, 3)), np.zeros((0, 3)), flush=True)
    return acc


def smooth(flux, depth, sigma: float) -> np.ndarray:
    """``flux`` (H, W, 3) averaged by a Gaussian of ``sigma`` pixels over the pixels that see
    something (finite ``depth``; the others stay 0): rough glass's scattered photons become a
    density. The total is kept where the World is not within reach."""
    if not sigma > 0.0:
        return flux
    seen = np.isfinite(depth).astype(np.float64)
    radius = int(np.ceil(3.0 * sigma))
    taps = np.exp(-0.5 * (np.arange(-radius, radius + 1) / sigma) ** 2)
    taps /= taps.sum()

    def blur(x):
        for axis in (0, 1):
            pad = [(0, 0)] * x.ndim
            pad[axis] = (radius, radius)
            xp = np.pad(x, pad)
            out = np.zeros_like(x)
            size = x.shape[axis]
            for k, t in enumerate(taps):
                out += t * np.take(xp, np.arange(k, k + size), axis=axis)
            x = out
        return x

    density = blur(flux * seen[..., None])
    weight = blur(seen)
    return np.where(seen[..., None] > 0.0, density / np.maximum(weight, 1e-12)[..., None], 0.0)
