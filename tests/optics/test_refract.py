"""Solid glass's refraction of the scene behind (precompute/shading/refract.py), pure numpy.

Physics and properties: the exit ray of a glass sphere against an independent ray trace (Snell's
law at both interfaces, angles from the geometry); glass of index 1 shows the picture behind
unshifted; a ball of glass inverts a far picture behind it, as a ball lens; a ray that leaves the
picture sees nothing; an occluder in front of the ray's path is not taken for a hit.
"""

import numpy as np
import pytest

from precompute.shading import refract, transmit

SIZE = 96
DISTANCE, FOV = 4.0, 32.0


def unit(a):
    a = np.asarray(a, dtype=np.float64)
    return a / np.linalg.norm(a, axis=-1, keepdims=True)


def camera():
    """(view_proj, camera position, view_dir towards the viewer, pixel rays (H, W, 3) top row
    first): a camera at (0, −DISTANCE, 0) looking along +y, z up."""
    f = 1.0 / np.tan(np.radians(FOV) / 2.0)
    near, far = 0.1, 100.0
    proj = np.array(
        [
            [f, 0, 0, 0],
            [0, f, 0, 0],
            [0, 0, (far + near) / (near - far), 2 * far * near / (near - far)],
            [0, 0, -1, 0],
        ]
    )
    eye = np.array([0.0, -DISTANCE, 0.0])
    # camera axes: x right, y up (= world z), z back (= world −y)
    rot = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
    view = np.eye(4)
    view[:3, :3] = rot
    view[:3, 3] = -rot @ eye
    centres = (np.arange(SIZE) + 0.5) / SIZE * 2.0 - 1.0
    x, y = np.meshgrid(centres, -centres)  # top row first
    rays = unit(np.stack([x / f, np.ones_like(x), y / f], axis=-1))
    return proj @ view, eye, np.array([0.0, -1.0, 0.0]), rays


def wall_depth(rays, eye, y_plane):
    """Depth (distance along the camera axis) of a plane y = y_plane seen by each pixel."""
    return np.full(rays.shape[:2], y_plane - eye[1])


def sphere_hits(rays, eye, centre, radius):
    """(mask, points, normals, views) of the pixels whose ray hits the sphere (near hit)."""
    oc = eye - centre
    b = rays @ oc
    disc = b * b - (oc @ oc - radius * radius)
    mask = disc > 0
    t = -b[mask] - np.sqrt(disc[mask])
    points = eye + t[:, None] * rays[mask]
    normals = unit(points - centre)
    return mask, points, normals, unit(eye - points)


def trace_sphere(points, normals, views, centre, eta):
    """An independent ray trace through a sphere: Snell's law by angles in the plane of
    incidence at entry and exit; (exit point, exit direction)."""
    out_p, out_d = [], []
    for p, n, v in zip(points, normals, views, strict=True):
        d = -v
        cos_i = -d @ n
        theta_t = np.arcsin(np.sqrt(1.0 - cos_i**2) / eta)
        tangent = d + cos_i * n
        tangent = tangent / np.linalg.norm(tangent) if np.linalg.norm(tangent) > 1e-12 else np.zeros(3)
        inner = -np.cos(theta_t) * n + np.sin(theta_t) * tangent
        # second hit: |p + s inner − c| = R with p on the sphere → s = −2 (p − c)·inner
        p2 = p - 2.0 * ((p - centre) @ inner) * inner
        n2 = unit(p2 - centre)
        cos_2 = inner @ n2
        theta_2 = np.arcsin(min(eta * np.sqrt(max(1.0 - cos_2**2, 0.0)), 1.0))
        t2 = inner - cos_2 * n2
        t2 = t2 / np.linalg.norm(t2) if np.linalg.norm(t2) > 1e-12 else np.zeros(3)
        out_p.append(p2)
        out_d.append(np.cos(theta_2) * n2 + np.sin(theta_2) * t2)
    return np.array(out_p), np.array(out_d)


@pytest.mark.parametrize("eta", [1.33, 1.5, 2.0])
def test_exit_ray_of_a_sphere_matches_a_ray_trace(eta):
    _vp, eye, _vd, rays = camera()
    centre = np.array([0.2, 0.3, -0.1])
    _mask, p, n, v = sphere_hits(rays, eye, centre, 1.1)
    p2, d = refract.exit_ray(p, n, v, centre, eta)
    ref_p, ref_d = trace_sphere(p, n, v, centre, eta)
    assert np.max(np.abs(p2 - ref_p)) < 1e-9
    assert np.max(np.abs(d - ref_d)) < 1e-9
    # and the direction is transmit.solid_exit's (the sphere's deviation 2(θi − θt))
    assert np.max(np.abs(d - transmit.solid_exit(n, v, eta))) < 1e-9


def test_glass_of_index_one_shows_the_picture_unshifted():
    vp, eye, vd, rays = camera()
    centre = np.zeros(3)
    mask, p, n, v = sphere_hits(rays, eye, centre, 1.0)
    p2, d = refract.exit_ray(p, n, v, centre, 1.0)
    assert np.max(np.abs(d + v)) < 1e-12  # straight on
    hit, rows, cols = refract.march(p2, d, wall_depth(rays, eye, 6.0), vp, eye, vd, (1, 1, 0, 0))
    want_rows, want_cols = np.nonzero(mask)
    assert hit.all()
    assert np.array_equal(rows, want_rows) and np.array_equal(cols, want_cols)


def test_a_ball_of_glass_inverts_the_picture_behind_it():
    """A ball lens (η = 1.5, R = 1: focal length ηR / 2(η − 1) = 1.5 from its centre) in front of
    a picture 8 units behind it: what it shows is upside down and mirrored."""
    vp, eye, vd, rays = camera()
    centre = np.zeros(3)
    mask, p, n, v = sphere_hits(rays, eye, centre, 1.0)
    p2, d = refract.exit_ray(p, n, v, centre, 1.5)
    hit, rows, cols = refract.march(p2, d, wall_depth(rays, eye, 8.0), vp, eye, vd, (1, 1, 0, 0))
    pix_rows, pix_cols = np.nonzero(mask)
    mid = (SIZE - 1) / 2.0
    off = (np.abs(pix_rows - mid) > 4) & hit
    assert hit.mean() > 0.5  # the rays bent most (near the rim) leave the picture
    assert np.all(np.sign(rows[off] - mid) == -np.sign(pix_rows[off] - mid))
    off = (np.abs(pix_cols - mid) > 4) & hit
    assert np.all(np.sign(cols[off] - mid) == -np.sign(pix_cols[off] - mid))


def test_rays_that_leave_the_picture_or_meet_nothing_see_nothing():
    vp, eye, vd, rays = camera()
    origins = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    dirs = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # sideways out of the picture; straight on
    empty = np.full((SIZE, SIZE), np.inf)
    hit, _r, _c = refract.march(origins, dirs, empty, vp, eye, vd, (1, 1, 0, 0))
    assert not hit.any()
    hit, _r, _c = refract.march(origins, dirs, wall_depth(rays, eye, 5.0), vp, eye, vd, (1, 1, 0, 0))
    assert hit.tolist() == [False, True]


def test_an_occluder_in_front_of_the_path_is_not_a_hit():
    """A ray that passes behind a small near object (its depth far in front of the ray) goes on to
    the wall behind it."""
    vp, eye, vd, rays = camera()
    depth = wall_depth(rays, eye, 6.0)
    depth[40:56, 40:56] = 1.0  # a near square, 1 unit from the camera
    origin = np.array([[-0.8, 0.0, 0.0]])  # left of it, heading right and away: behind it, then out
    hit, rows, cols = refract.march(origin, unit([[0.3, 1.0, 0.0]]), depth, vp, eye, vd, (1, 1, 0, 0))
    assert hit[0] and depth[rows[0], cols[0]] == pytest.approx(10.0)
    assert cols[0] > 56  # seen to the right of the square, where the ray meets the wall


@pytest.mark.parametrize("eta", [1.33, 1.5])
def test_one_reflection_inside_a_sphere_matches_a_ray_trace(eta):
    """transmit.solid_internal: in, reflected once at the far side, out; traced with Snell's law
    and the mirror law at the sphere's normals."""
    _vp, eye, _vd, rays = camera()
    centre = np.zeros(3)
    _mask, p, n, v = sphere_hits(rays, eye, centre, 1.0)
    inner = refract.refract(-v, n, 1.0 / eta)
    p2 = p - 2.0 * np.sum(p * inner, -1, keepdims=True) * inner
    n2 = unit(p2)
    bounced = inner - 2.0 * np.sum(inner * n2, -1, keepdims=True) * n2
    p3 = p2 - 2.0 * np.sum(p2 * bounced, -1, keepdims=True) * bounced
    out = refract.refract(bounced, -unit(p3), eta)
    assert np.max(np.abs(transmit.solid_internal(n, v, eta) - out)) < 1e-9
    # straight back towards the viewer at normal incidence
    assert np.allclose(
        transmit.solid_internal([[0.0, -1.0, 0.0]], [[0.0, -1.0, 0.0]], eta), [[0.0, -1.0, 0.0]]
    )
