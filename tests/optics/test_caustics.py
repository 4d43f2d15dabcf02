"""Solid glass's shadow and caustics (precompute/optics/caustics.py) over exact geometry.

A glass ball above a floor, the rays cast here in closed form (ray–sphere, ray–plane), seen by an
orthographic camera from above. Checked: glass of index 1 gives the floor the sun's E cos θ
wherever its shadow falls (the light as if there were no glass); a lossless ball lens delivers
every photon's flux to the floor; the ball focuses a vertical sun onto its paraxial focus
nR / 2(n − 1) below its centre, the shadow's ring around it lit only by its rim's aberrant light;
the Fresnel losses of a slab are the closed form's (1 − F)²; a photon on a surface the camera does
not see is left out. Rough glass (Cycles' Filter Glossy on caustic paths): Cycles' roughness, GGX
facets, a lens whose focus spreads while its flux stays, the smoothing that keeps the total.
"""

from __future__ import annotations

import numpy as np
import pytest

from precompute.brdf import ggx_albedo
from precompute.optics import caustics, facets, sources
from precompute.shading.transmit import fresnel_dielectric

R = 1.0
SIDE = 8.0  # the camera's orthographic width
PIXELS = 128


def ortho_camera(height: float = 10.0, side: float = SIDE) -> caustics.Camera:
    view = np.eye(4)
    view[2, 3] = -height  # camera at (0, 0, height) looking down −z
    near, far = 0.1, 100.0
    proj = np.diag([2.0 / side, 2.0 / side, -2.0 / (far - near), 1.0])
    proj[2, 3] = -(far + near) / (far - near)
    return caustics.Camera(view, proj, PIXELS, PIXELS, ortho=True)


def ball_casts(centre, radius=R):
    """(cast_outside, cast_inside) for one ball (glass 0) above the floor z = 0 (receiver 0)."""
    c = np.asarray(centre, dtype=np.float64)

    def sphere(o, d, far_root):
        oc = o - c
        b = np.sum(oc * d, axis=-1)
        disc = b * b - (np.sum(oc * oc, axis=-1) - radius * radius)
        root = np.sqrt(np.maximum(disc, 0.0))
        t = -b + root if far_root else -b - root
        return np.where((disc >= 0.0) & (t > 0.0), t, np.inf)

    def outside(o, d):
        ts = sphere(o, d, False)
        tp = np.where(d[:, 2] < 0.0, -o[:, 2] / np.where(d[:, 2] < 0.0, d[:, 2], -1.0), np.inf)
        tp = np.where(tp > 0.0, tp, np.inf)
        t = np.minimum(ts, tp)
        p = o + np.where(np.isfinite(t), t, 0.0)[:, None] * d
        ball = np.isfinite(ts) & (ts <= tp)
        floor = np.isfinite(tp) & (tp < ts)
        n = np.where(ball[:, None], (p - c) / radius, np.array([0.0, 0.0, 1.0]))
        return np.where(ball, 0, -1), np.where(floor, 0, -1), p, n

    def inside(g, o, d):
        t = sphere(o, d, True)
        p = o + np.where(np.isfinite(t), t, 0.0)[:, None] * d
        return np.isfinite(t), p, (p - c) / radius

    return outside, inside


def floor_flux(optics, centre, sun, grid=160, side=SIDE, alpha=0.0):
    """The floor's irradiance (H, W, 3) and the pixels' area from a sun of irradiance 1 towards
    ``sun`` through one ball at ``centre``, the camera ``side`` wide; ``alpha``: the ball rough
    (each photon at its own point, not smoothed)."""
    camera = ortho_camera(side=side)
    depth = np.full((PIXELS, PIXELS), 10.0)
    normals = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (PIXELS, PIXELS, 3))
    origins, direction, area = caustics.photon_grid(centre, R, sun, grid)
    flux = np.full((len(origins), 3), area)
    out, inn = ball_casts(centre)
    records = caustics.trace(origins, direction, flux, [optics], out, inn, scale=R, alpha=alpha)
    acc = caustics.splat(records, grid, camera, depth, cells=alpha == 0.0)
    pixel_area = caustics.footprint(camera, depth, normals)
    return acc / pixel_area[..., None], pixel_area


def lossless(eta):
    def zero(c):
        return np.zeros((len(np.atleast_1d(c)), 3))

    return caustics.GlassOptics(float(eta), zero, zero)


def test_glass_of_index_one_lights_its_shadow_as_if_it_were_not_there():
    theta = np.radians(30.0)
    sun = np.array([np.sin(theta), 0.0, np.cos(theta)])
    e, _ = floor_flux(caustics.plain_glass(1.0), (0.0, 0.0, 2.0), sun)
    # the shadow: the ball's disc cast along the sun onto z = 0, an ellipse; well inside it
    ys, xs = np.mgrid[0:PIXELS, 0:PIXELS]
    x = (xs + 0.5) / PIXELS * SIDE - SIDE / 2
    y = SIDE / 2 - (ys + 0.5) / PIXELS * SIDE
    cx = -2.0 * np.tan(theta)  # the ball's centre projected along the sun
    inner = ((x - cx) * np.cos(theta)) ** 2 + y**2 < (0.85 * R) ** 2
    outer = ((x - cx) * np.cos(theta)) ** 2 + y**2 > (1.1 * R) ** 2
    ratio = e[inner, 1] / np.cos(theta)
    spread = f"{np.percentile(ratio, 5):.3f}–{np.percentile(ratio, 95):.3f}"
    print(f"index 1: E / E cos θ inside the shadow median {np.median(ratio):.4f}, 5–95 % {spread}")
    assert abs(np.median(ratio) - 1.0) < 0.01
    assert np.percentile(ratio, 5) > 0.9 and np.percentile(ratio, 95) < 1.1
    assert np.all(e[outer] == 0.0)  # nothing where no photon went through the glass


def test_a_lossless_ball_delivers_every_photons_flux():
    # a vertical sun: the rim's rays leave at up to 96° from it (only the outer 0.2 % of the disc
    # upwards); the floor seen 200 radii wide
    e, pixel_area = floor_flux(lossless(1.5), (0.0, 0.0, 1.5), np.array([0.0, 0.0, 1.0]), side=400.0)
    total = float(np.sum(e[..., 0] * pixel_area))
    print(f"lossless ball: flux on the floor {total:.4f} of π R² = {np.pi * R * R:.4f}")
    assert abs(total / (np.pi * R * R) - 1.0) < 0.01


def test_filter_glossys_roughness_is_cycles_closed_form():
    # Cycles: blur_pdf = cos θ / π / blur_glossy after a diffuse bounce, α = ½ √(1 − blur_pdf)
    assert facets.blur_roughness(1.0, 1.0) == pytest.approx(0.5 * np.sqrt(1.0 - 1.0 / np.pi), abs=1e-12)
    assert facets.blur_roughness(0.0, 1.0) == pytest.approx(0.5)
    assert facets.blur_roughness(0.5, 0.25) == pytest.approx(0.5 * np.sqrt(1.0 - 2.0 / np.pi))
    assert facets.blur_roughness(1.0, 0.1) == 0.0  # p ≥ 1: the path is not blurred
    assert facets.blur_roughness(1.0, 0.0) == 0.0  # the filter off


def test_microfacet_normals_follow_ggx():
    """Seen along the normal, the visible normals are D(m) (m · n): tan² θm has the CDF
    x / (α² + x), so its quartiles are α²/3, α² and 3α²; every normal about its own n, its azimuth
    uniform."""
    alpha, count = 0.45, 200_000
    rng = np.random.default_rng(3)
    n = np.tile(np.array([[0.0, 0.6, 0.8]]), (count, 1))
    m = facets.microfacets(n, n, alpha, rng, lambda rows, m: np.ones(len(rows), dtype=bool))
    assert np.allclose(np.linalg.norm(m, axis=-1), 1.0)
    cos_t = np.clip(np.sum(m * n, axis=-1), -1.0, 1.0)
    tan2 = (1.0 - cos_t**2) / cos_t**2
    quartiles = np.percentile(tan2, [25, 50, 75]) / alpha**2
    print(f"GGX tan² θm quartiles / α²: {np.round(quartiles, 4)} (1/3, 1, 3)")
    assert quartiles == pytest.approx([1.0 / 3.0, 1.0, 3.0], rel=0.03)
    side = np.cross(n[0], m - cos_t[:, None] * n) @ np.array([1.0, 0.0, 0.0])
    assert abs(np.mean(side > 0.0) - 0.5) < 0.01
    never = facets.microfacets(n[:10], n[:10], alpha, rng, lambda rows, m: np.zeros(len(rows), dtype=bool))
    assert np.array_equal(never, n[:10])  # never valid: the normal itself


def test_visible_normals_seen_askew_are_the_ggx_normals_weighted_by_their_facing():
    """Seen from 60° off the normal, the drawn normals' statistics equal those of plain GGX normals
    (drawn here by the closed-form inverse CDF of D(m) (m · n)) weighted by max(0, v · m) / (m · n)."""
    alpha, count = 0.45, 400_000
    rng = np.random.default_rng(5)
    n = np.array([0.0, 0.0, 1.0])
    v = np.array([np.sin(np.radians(60.0)), 0.0, np.cos(np.radians(60.0))])
    m = facets.microfacets(
        np.tile(n, (count, 1)), np.tile(v, (count, 1)), alpha, rng, lambda r, m: np.ones(len(r), dtype=bool)
    )
    x = rng.random(count)
    tan_t = alpha * np.sqrt(x / (1.0 - x))
    cos_t = 1.0 / np.sqrt(1.0 + tan_t**2)
    phi = 2.0 * np.pi * rng.random(count)
    g = np.stack([tan_t * cos_t * np.cos(phi), tan_t * cos_t * np.sin(phi), cos_t], -1)
    w = np.maximum(g @ v, 0.0) / g[:, 2]
    for name, f in (("m·n", lambda q: q[:, 2]), ("m·v", lambda q: q @ v), ("m_x", lambda q: q[:, 0])):
        drawn, weighted = float(np.mean(f(m))), float(np.sum(w * f(g)) / np.sum(w))
        print(f"{name}: visible normals {drawn:.4f}, weighted GGX {weighted:.4f}")
        assert drawn == pytest.approx(weighted, abs=0.004)
    assert np.all(m @ v > 0.0)  # every drawn facet faces the viewer


@pytest.mark.parametrize("mu", [1.0, 0.5, 0.2])
def test_visible_normals_and_their_masking_give_ggxs_single_scattering_albedo(mu):
    """A mirror of rough facets (F ≡ 1): directions drawn through visible normals, each weighted
    by facets.masking (G2 / G1), average to the single-scattering albedo E(μ) that
    precompute.brdf.ggx_albedo integrates on its quadrature rule (directions below the surface
    carry nothing)."""
    alpha, count = 0.45, 400_000
    rng = np.random.default_rng(7)
    n = np.tile(np.array([0.0, 0.0, 1.0]), (count, 1))
    v = np.tile(np.array([np.sqrt(1.0 - mu * mu), 0.0, mu]), (count, 1))
    m = facets.microfacets(n, v, alpha, rng, lambda r, m: np.ones(len(r), dtype=bool))
    out = 2.0 * np.sum(v * m, axis=-1, keepdims=True) * m - v
    w = np.where(out[:, 2] > 0.0, facets.masking(np.full(count, mu), out[:, 2], alpha), 0.0)
    want = float(ggx_albedo(np.array([mu]), alpha)[0])
    print(f"μ {mu}: drawn and masked {w.mean():.4f}, ggx_albedo {want:.4f}")
    assert w.mean() == pytest.approx(want, abs=0.004)


def test_a_rough_ball_spreads_its_focus():
    """Cycles' Filter Glossy draws the glass rough on caustic paths (α ≈ 0.45): the ball lens's
    focus spreads over the shadow around it. What the floor and a dome above get is less than
    the flux into the ball, by single scattering's loss alone: the facets' shadowing at each of
    the ≥ 2 faces (a rough mirror of this α keeps 0.74 of the light at normal incidence, above),
    as on Cycles' blurred glass; a rough face also reflects much of the light totally back
    inside, and some of it leaves upwards."""
    eta, alpha = 1.5, 0.45
    focus = eta * R / (2.0 * (eta - 1.0))
    out, inn = ball_casts((0.0, 0.0, 1.5))

    def with_dome(o, d):  # receiver 1: everything that leaves upwards
        glass, rec, p, n = out(o, d)
        up = (glass < 0) & (rec < 0) & (d[:, 2] > 0.0)
        return glass, np.where(up, 1, rec), np.where(up[:, None], o + 100.0 * d, p), n

    origins, direction, area = caustics.photon_grid((0.0, 0.0, 1.5), R, np.array([0.0, 0.0, 1.0]), 160)
    flux = np.full((len(origins), 3), area)
    records = caustics.trace(origins, direction, flux, [lossless(eta)], with_dome, inn, scale=R, alpha=alpha)
    got = np.concatenate([np.c_[rec, f[:, 0]] for _, _, f, rec in records.arrays().values()])
    floor, dome = (float(got[got[:, 0] == k, 1].sum()) / (np.pi * R * R) for k in (0, 1))
    print(f"rough lossless ball: floor {floor:.4f} + dome {dome:.4f} = {floor + dome:.4f} of the flux in")
    assert 0.65 < floor + dome < 0.95
    assert dome > 0.05
    smooth, _ = floor_flux(lossless(eta), (0.0, 0.0, focus), np.array([0.0, 0.0, 1.0]))
    rough, _ = floor_flux(lossless(eta), (0.0, 0.0, focus), np.array([0.0, 0.0, 1.0]), alpha=alpha)
    ys, xs = np.mgrid[0:PIXELS, 0:PIXELS]
    rho = np.hypot((xs + 0.5) / PIXELS * SIDE - SIDE / 2, SIDE / 2 - (ys + 0.5) / PIXELS * SIDE)
    centre, ring = rho < 0.1 * R, (rho > 0.6 * R) & (rho < 0.9 * R)
    print(
        f"focus: smooth {smooth[centre, 1].mean():.2f}, rough {rough[centre, 1].mean():.2f}; "
        f"ring 0.6–0.9 R: smooth {smooth[ring, 1].mean():.3f}, rough {rough[ring, 1].mean():.3f}"
    )
    assert rough[centre, 1].mean() < 0.25 * smooth[centre, 1].mean()
    assert rough[ring, 1].mean() > 1.3 * smooth[ring, 1].mean()


def test_each_photon_is_as_rough_as_cycles_makes_the_glass_from_where_it_lands():
    """Glass of index 1 sends each photon straight on: under a sun 30° off the vertical every
    photon through the ball lands on the floor at cos 30°, so each takes Filter Glossy's roughness
    at that cosine; a photon that never landed takes the sun's height."""
    theta = np.radians(30.0)
    sun = np.array([np.sin(theta), 0.0, np.cos(theta)])
    origins, direction, area = caustics.photon_grid((0.0, 0.0, 2.0), R, sun, 32)
    out, inn = ball_casts((0.0, 0.0, 2.0))
    records = caustics.trace(origins, direction, np.full((len(origins), 3), area), [lossless(1.0)], out, inn)
    landed = np.isfinite(records.landing)
    assert np.allclose(records.landing[landed], np.cos(theta), atol=1e-9)
    alpha = facets.photon_roughness(records.landing, sun, 1.0)
    assert np.allclose(alpha[landed], facets.blur_roughness(np.cos(theta), 1.0))
    assert np.allclose(alpha[~landed], facets.blur_roughness(sun[2], 1.0))
    assert 0.6 * len(origins) < landed.sum() < 0.9 * len(origins)  # the disc of the square grid, π/4


def test_smoothing_keeps_a_constant_and_the_total_and_leaves_the_void():
    depth = np.full((64, 64), 5.0)
    depth[:, :8] = np.inf  # the World
    flux = np.zeros((64, 64, 3))
    flux[30:34, 30:34] = 1.0
    out = caustics.smooth(flux, depth, 2.0)
    assert np.sum(out) == pytest.approx(np.sum(flux), rel=1e-9)
    assert out[32, 32, 0] < 1.0 and out[32, 38, 0] > 0.0
    constant = caustics.smooth(np.where(np.isfinite(depth)[..., None], 1.0, 0.0), depth, 3.0)
    assert np.allclose(constant[:, 8:], 1.0) and np.all(constant[:, :8] == 0.0)


def test_a_spheres_radius_on_the_picture():
    # orthographic, 8 wide over 128 pixels: a radius of 1 is 16 pixels
    assert caustics.projected_radius(ortho_camera(), (0.0, 0.0, 0.0), 1.0) == pytest.approx(16.0)


def test_a_ball_lens_focuses_a_vertical_sun_on_its_paraxial_focus():
    eta = 1.5
    focus = eta * R / (2.0 * (eta - 1.0))  # below the centre
    e, _ = floor_flux(lossless(eta), (0.0, 0.0, focus), np.array([0.0, 0.0, 1.0]))
    middle = e[PIXELS // 2 - 1 : PIXELS // 2 + 1, PIXELS // 2 - 1 : PIXELS // 2 + 1, 1].mean()
    ys, xs = np.mgrid[0:PIXELS, 0:PIXELS]
    rho = np.hypot((xs + 0.5) / PIXELS * SIDE - SIDE / 2, SIDE / 2 - (ys + 0.5) / PIXELS * SIDE)
    ring = e[(rho > 0.6 * R) & (rho < 0.9 * R), 1]
    print(f"ball lens at its focus: middle {middle:.1f} × the sun, ring 0.6–0.9 R mean {ring.mean():.4f}")
    assert middle > 20.0
    assert np.unravel_index(np.argmax(e[..., 1]), e.shape[:2]) in {(63, 63), (63, 64), (64, 63), (64, 64)}
    # the shadow around the focus (the light straight through would give 1; what is left there is
    # the rim's light, spherical aberration: it crossed the axis above the paraxial focus)
    assert ring.mean() < 0.25


@pytest.mark.parametrize("incidence", [0.0, 50.0])
def test_a_slab_loses_a_fresnel_reflection_at_each_face(incidence):
    """A 4 × 4 × 0.5 slab of index 1.5 (cast here: two planes and the sides) under a sun: the floor
    gets (1 − F)², the film-less slab's closed form without its reflections inside (a path
    reflected twice is not followed, policy.CAUSTIC_REFLECTIONS)."""
    theta = np.radians(incidence)
    sun = np.array([np.sin(theta), 0.0, np.cos(theta)])
    lo, hi = np.array([-2.0, -2.0, 1.0]), np.array([2.0, 2.0, 1.5])

    def box(o, d, inside):
        inv = 1.0 / np.where(np.abs(d) > 1e-300, d, 1e-300)
        t0, t1 = (lo - o) * inv, (hi - o) * inv
        near, far = np.minimum(t0, t1), np.maximum(t0, t1)
        tn, tf = near.max(axis=-1), far.min(axis=-1)
        t = tf if inside else tn
        ok = (tf >= max(tn.min(), -np.inf)) & (tn <= tf) & (t > 0.0)
        p = o + np.where(ok, t, 0.0)[:, None] * d
        axis = np.argmax(near, axis=-1) if not inside else np.argmin(far, axis=-1)
        n = np.zeros_like(p)
        n[np.arange(len(p)), axis] = np.where(inside, 1.0, -1.0) * np.sign(d[np.arange(len(p)), axis])
        return ok, p, n, t

    def outside(o, d):
        ok, p, n, ts = box(o, d, False)
        ts = np.where(ok, ts, np.inf)
        tp = np.where(d[:, 2] < 0.0, -o[:, 2] / np.where(d[:, 2] < 0.0, d[:, 2], -1.0), np.inf)
        slab = ts <= tp
        floor = np.isfinite(tp) & ~slab
        p = np.where(slab[:, None], p, o + np.where(np.isfinite(tp), tp, 0.0)[:, None] * d)
        n = np.where(slab[:, None], n, np.array([0.0, 0.0, 1.0]))
        return np.where(slab, 0, -1), np.where(floor, 0, -1), p, n

    def inside(g, o, d):
        ok, p, n, _ = box(o, d, True)
        return ok, p, n

    camera = ortho_camera()
    depth = np.full((PIXELS, PIXELS), 10.0)
    normals = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (PIXELS, PIXELS, 3))
    grid = 160
    origins, direction, area = caustics.photon_grid((0.0, 0.0, 1.25), 2.9, sun, grid)
    records = caustics.trace(
        origins,
        direction,
        np.full((len(origins), 3), area),
        [caustics.plain_glass(1.5)],
        outside,
        inside,
        2.0,
    )
    e = caustics.splat(records, grid, camera, depth) / caustics.footprint(camera, depth, normals)[..., None]
    f_out = float(fresnel_dielectric(np.cos(theta), 1.5))
    want = np.cos(theta) * (1.0 - f_out) ** 2
    shift = 1.25 * np.tan(theta)  # the slab's middle cast onto the floor
    c0 = int((SIDE / 2 - shift) / SIDE * PIXELS)
    middle = e[56:72, c0 - 8 : c0 + 8, 0]
    print(f"slab at {incidence}°: floor {middle.mean():.4f}, closed form {want:.4f}")
    assert abs(middle.mean() / want - 1.0) < 0.003


def test_a_photon_the_camera_does_not_see_is_left_out():
    """The same ball of index 1 with the pass's depth saying a nearer surface covers the floor's
    left half: the flux lands only on the right half."""
    camera = ortho_camera()
    depth = np.full((PIXELS, PIXELS), 10.0)
    depth[:, : PIXELS // 2] = 5.0
    origins, direction, area = caustics.photon_grid((0.0, 0.0, 2.0), R, (0.0, 0.0, 1.0), 64)
    out, inn = ball_casts((0.0, 0.0, 2.0))
    records = caustics.trace(
        origins, direction, np.full((len(origins), 3), area), [caustics.plain_glass(1.0)], out, inn, R
    )
    acc = caustics.splat(records, 64, camera, depth)
    assert acc[:, : PIXELS // 2].sum() == 0.0
    assert abs(acc[:, PIXELS // 2 :, 0].sum() / (0.5 * np.pi * R * R) - 1.0) < 0.02


def test_a_suns_disc_directions_sit_within_its_disc_about_its_centre():
    """A sun of 10° across in 7 directions: the first its centre, the others 5° × √½ from it, all
    on a ring about it (their mean is the centre); one direction for a point sun."""
    centre = np.array([0.3, -0.4, 0.8]) / np.linalg.norm([0.3, -0.4, 0.8])
    dirs = caustics.disc_directions(centre, np.radians(10.0), 7)
    assert dirs.shape == (7, 3) and np.allclose(np.linalg.norm(dirs, axis=-1), 1.0)
    assert np.allclose(dirs[0], centre)
    angles = np.degrees(np.arccos(np.clip(dirs[1:] @ centre, -1.0, 1.0)))
    assert np.allclose(angles, np.degrees(np.arctan(np.tan(np.radians(5.0)) * np.sqrt(0.5))), atol=1e-9)
    mean = dirs.mean(axis=0)
    assert np.degrees(np.arccos(mean @ centre / np.linalg.norm(mean))) < 1e-6
    assert caustics.disc_directions(centre, 0.0, 7).shape == (1, 3)


def point_floor_flux(optics, centre, light, side=SIDE):
    """The floor's irradiance (H, W, 3) and the pixels' area from a point light of intensity 1
    W/sr at ``light`` through one ball at ``centre`` (precompute/optics/sources.py)."""
    camera = ortho_camera(side=side)
    depth = np.full((PIXELS, PIXELS), 10.0)
    normals = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (PIXELS, PIXELS, 3))
    origins, directions, omega = sources.point_photons(light, centre, R, 160)
    flux = np.repeat(omega[:, None], 3, axis=1)
    out, inn = ball_casts(centre)
    records = caustics.trace(origins, directions, flux, [optics], out, inn, scale=R)
    acc = caustics.splat(records, 160, camera, depth)
    pixel_area = caustics.footprint(camera, depth, normals)
    return acc / pixel_area[..., None], pixel_area


def test_a_point_lights_photons_span_the_glass_by_their_solid_angles():
    """A point light's grid of rays over the square that bounds a glass's sphere as seen from
    the light: the cells' solid angles h² cos³ θ add up to the square pyramid's 4 asin(t² / (1 +
    t²)) (t = tan β, sin β = R / distance), every ray to the sphere's silhouette falls inside
    the square, and a light inside the sphere is refused."""
    light, centre = np.array([0.3, -0.2, 6.0]), np.array([0.0, 0.0, 2.0])
    origins, directions, omega = sources.point_photons(light, centre, R, 160)
    distance = np.linalg.norm(centre - light)
    t = R / np.sqrt(distance**2 - R**2)
    total, exact = float(omega.sum()), 4.0 * np.arcsin(t * t / (1.0 + t * t))  # the square pyramid
    print(f"solid angle of the grid {total:.6f}, the pyramid's {exact:.6f}")
    assert total == pytest.approx(exact, rel=1e-4)
    assert np.allclose(origins, light) and np.allclose(np.linalg.norm(directions, axis=-1), 1.0)
    axis = (centre - light) / distance
    cos_edge = np.min(directions @ axis)
    assert cos_edge < np.sqrt(1.0 - (R / distance) ** 2)  # the silhouette's cone is inside
    with pytest.raises(ValueError, match="not outside"):
        sources.point_photons(centre + 0.5 * R, centre, R, 8)


def test_glass_of_index_one_under_a_point_light_lets_its_light_through():
    """Through glass of index 1 without a film the floor in the ball's shadow gets the point
    light's I cos θ / r², as if there were no glass."""
    light = np.array([0.0, 0.0, 6.0])
    e, _ = point_floor_flux(caustics.plain_glass(1.0), (0.0, 0.0, 2.0), light)
    ys, xs = np.mgrid[0:PIXELS, 0:PIXELS]
    x = (xs + 0.5) / PIXELS * SIDE - SIDE / 2
    y = SIDE / 2 - (ys + 0.5) / PIXELS * SIDE
    shadow = 6.0 * np.tan(np.arcsin(R / 4.0))  # the ball's shadow from 6 above, 4 from its centre
    rho = np.hypot(x, y)
    r2 = rho**2 + 36.0
    want = 6.0 / np.sqrt(r2) / r2
    ratio = e[rho < 0.85 * shadow, 1] / want[rho < 0.85 * shadow]
    spread = f"{np.percentile(ratio, 5):.3f}–{np.percentile(ratio, 95):.3f}"
    print(
        f"point light, index 1: E / (I cos θ / r²) in the shadow median {np.median(ratio):.4f},"
        f" 5–95 % {spread}"
    )
    assert abs(np.median(ratio) - 1.0) < 0.01
    assert np.percentile(ratio, 5) > 0.9 and np.percentile(ratio, 95) < 1.1
    assert np.all(e[rho > 1.1 * shadow] == 0.0)


def test_a_lossless_ball_under_a_point_light_delivers_its_cones_flux():
    """A lossless ball lens under a point light: the floor receives I 2π (1 − cos β), the flux
    of the cone the ball subtends."""
    light, centre = np.array([0.0, 0.0, 6.0]), np.array([0.0, 0.0, 2.0])
    e, pixel_area = point_floor_flux(lossless(1.5), centre, light, side=400.0)
    total = float(np.sum(e[..., 0] * pixel_area))
    cone = 2.0 * np.pi * (1.0 - np.sqrt(1.0 - (R / 4.0) ** 2))
    print(f"lossless ball under a point light: flux on the floor {total:.5f} of the cone's {cone:.5f}")
    assert total / cone == pytest.approx(1.0, abs=0.01)


def test_lights_send_photons_with_cycles_intensities():
    """The flux a light's ray carries is its intensity that way times the ray's solid angle: a
    point light P / 4π; a spot the same times its cone (0 outside it); an area light's cells
    L A cos θ, their areas adding up to the light's, nothing behind it."""
    from precompute.shading import lights as light_shading

    matrix = np.eye(4)
    matrix[:3, 3] = (0.0, 0.0, 5.0)  # −Z (the spot's axis, the area's side) points down
    rows = [
        light_shading.light_from_blender("POINT", matrix, energy=100.0, radius=0.1),
        light_shading.light_from_blender(
            "SPOT", matrix, energy=100.0, spot_size=np.radians(60), spot_blend=0.0
        ),
        light_shading.light_from_blender(
            "AREA", matrix, energy=100.0, shape="RECTANGLE", size=2.0, size_y=1.0
        ),
    ]
    lights = light_shading.Lights.from_rows(rows)
    down, aside, up = (
        np.array([[0.0, 0.0, -1.0]]),
        np.array([[np.sin(0.7), 0.0, -np.cos(0.7)]]),
        np.array([[0, 0, 1.0]]),
    )
    omega = np.array([1e-3])
    point = sources.emitters(lights, 0)
    assert len(point) == 1 and np.allclose(point[0].position, (0, 0, 5))
    assert np.allclose(sources.emitted(lights, 0, point[0], down, omega), 100.0 / (4 * np.pi) * 1e-3)
    spot = sources.emitters(lights, 1)[0]
    assert np.allclose(sources.emitted(lights, 1, spot, down, omega), 100.0 / (4 * np.pi) * 1e-3)
    assert np.all(sources.emitted(lights, 1, spot, aside, omega) == 0.0)  # 40° off a 30° half cone
    cells = sources.emitters(lights, 2)
    assert len(cells) == 16 and sum(c.area for c in cells) == pytest.approx(2.0)
    radiance = 100.0 / (np.pi * 2.0)
    assert np.allclose(
        sources.emitted(lights, 2, cells[0], aside, omega), radiance * cells[0].area * np.cos(0.7) * 1e-3
    )
    assert np.all(sources.emitted(lights, 2, cells[0], up, omega) == 0.0)
    assert (
        sources.emitters(light_shading.Lights.from_rows([light_shading.light_from_blender("SUN", matrix)]), 0)
        == []
    )
