"""Solid glass's shadow and caustics (precompute/optics/caustics.py) over exact geometry.

A glass ball above a floor, the rays cast here in closed form (ray–sphere, ray–plane), seen by an
orthographic camera from above. Checked: glass of index 1 gives the floor the sun's E cos θ
wherever its shadow falls (the light as if there were no glass); a lossless ball lens delivers
every photon's flux to the floor; the ball focuses a vertical sun onto its paraxial focus
nR / 2(n − 1) below its centre, the shadow's ring around it lit only by its rim's aberrant light;
the Fresnel losses of a slab are the closed form's (1 − F)²; a photon on a surface the camera does
not see is left out.
"""

from __future__ import annotations

import numpy as np
import pytest

from precompute.optics import caustics
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


def floor_flux(optics, centre, sun, grid=160, side=SIDE):
    """The floor's irradiance (H, W, 3) and the pixels' area from a sun of irradiance 1 towards
    ``sun`` through one ball at ``centre``, the camera ``side`` wide."""
    camera = ortho_camera(side=side)
    depth = np.full((PIXELS, PIXELS), 10.0)
    normals = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (PIXELS, PIXELS, 3))
    origins, direction, area = caustics.photon_grid(centre, R, sun, grid)
    flux = np.full((len(origins), 3), area)
    out, inn = ball_casts(centre)
    records = caustics.trace(origins, direction, flux, [optics], out, inn, scale=R)
    acc = caustics.splat(records, grid, camera, depth)
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
