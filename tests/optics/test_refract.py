"""Solid glass's refraction of the scene behind (precompute/shading/glass/refract.py), pure numpy.

Physics and properties: the exit ray of a glass sphere against an independent ray trace (Snell's
law at both interfaces, angles from the geometry); glass of index 1 shows the picture behind
unshifted; a ball of glass inverts a far picture behind it, as a ball lens; a ray that leaves the
picture sees nothing; an occluder in front of the ray's path is not taken for a hit; a ray meets
a receding floor where the floor is, to a few hundredths of a texel.
"""

import numpy as np
import pytest

from precompute.shading import transmit
from precompute.shading.glass import refract

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
    assert np.array_equal(np.floor(rows), want_rows) and np.array_equal(np.floor(cols), want_cols)


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
    hit, _r, _c = refract.march(origins, dirs, empty, vp, eye, vd, (1, 1, 0, 0), edge=False)
    assert not hit.any()
    far = wall_depth(rays, eye, 5.0)
    hit, _r, _c = refract.march(origins, dirs, far, vp, eye, vd, (1, 1, 0, 0), edge=False)
    assert hit.tolist() == [False, True]


def test_a_ray_that_leaves_the_picture_sees_its_edge():
    """policy.REFRACT_EDGE: the sideways ray, passing behind a near wall (never within its
    thickness of it), takes the wall's texel where it left the picture (the right edge, on its
    row); where the picture holds no surface (the World) it sees nothing, as one that never left."""
    vp, eye, vd, _rays = camera()
    origins = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    dirs = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    near_wall = np.full((SIZE, SIZE), 2.0)
    hit, rows, cols = refract.march(origins, dirs, near_wall, vp, eye, vd, (1, 1, 0, 0), edge=True)
    assert hit.tolist() == [True, False]
    empty = np.full((SIZE, SIZE), np.inf)
    hit, _r, _c = refract.march(origins, dirs, empty, vp, eye, vd, (1, 1, 0, 0), edge=True)
    assert not hit.any()
    # the march steps grow geometrically: its last sample inside lies near the edge, not on it
    assert cols[0] > 0.9 * SIZE and abs(rows[0] - (SIZE - 1) / 2) <= 1


def test_a_ray_that_leaves_the_picture_climbing_away_from_a_floor_sees_nothing():
    """policy.REFRACT_EDGE with a floor: of two rays that leave the picture sideways above it, the
    one going down meets the floor beyond the edge and takes its edge texel; the one climbing
    away never meets the floor and sees the World (the glass cube's lower side faces, whose rays
    leave rising after a total internal reflection at the bottom face: ΔE 30–40 where they took
    the floor). A ray behind the surface it leaves over (an occluder) still takes its edge."""
    vp, eye, vd, rays = camera()
    depth = floor_depth(rays, eye, -1.0)
    origins = np.array([[0.3, 0.0, -0.6], [0.3, 0.0, -0.6]])
    dirs = unit([[1.0, -0.3, -0.08], [1.0, -0.3, 0.15]])
    s_floor = (-1.0 - origins[:, 2]) / dirs[:, 2]
    assert s_floor[0] > 4.0 and s_floor[1] < 0.0  # the first meets the floor well off the picture
    hit, rows, cols = refract.march(origins, dirs, depth, vp, eye, vd, (1, 1, 0, 0), edge=True)
    assert hit.tolist() == [True, False]
    assert cols[0] > 0.9 * SIZE
    near_wall = np.full((SIZE, SIZE), 2.0)  # in front of both rays: they pass behind it
    hit, _r, _c = refract.march(origins, dirs, near_wall, vp, eye, vd, (1, 1, 0, 0), edge=True)
    assert hit.tolist() == [True, True]


def test_an_occluder_in_front_of_the_path_is_not_a_hit():
    """A ray that passes behind a small near object (its depth far in front of the ray) goes on to
    the wall behind it."""
    vp, eye, vd, rays = camera()
    depth = wall_depth(rays, eye, 6.0)
    depth[40:56, 40:56] = 1.0  # a near square, 1 unit from the camera
    origin = np.array([[-0.8, 0.0, 0.0]])  # left of it, heading right and away: behind it, then out
    hit, rows, cols = refract.march(origin, unit([[0.3, 1.0, 0.0]]), depth, vp, eye, vd, (1, 1, 0, 0))
    assert hit[0] and depth[int(rows[0]), int(cols[0])] == pytest.approx(10.0)
    assert cols[0] > 56  # seen to the right of the square, where the ray meets the wall


def floor_depth(rays, eye, z_floor):
    """Depth (along the camera axis) of a floor z = z_floor seen by each pixel, inf above its
    horizon."""
    s = np.where(rays[..., 2] < 0.0, (z_floor - eye[2]) / np.minimum(rays[..., 2], -1e-12), np.inf)
    return s * rays[..., 1]  # the camera looks along +y: depth = s (ray · axis)


def test_a_ray_meets_a_receding_floor_where_the_floor_is():
    """Rays from above the floor, going down and away, see the floor where they cross its plane
    (an independent ray–plane intersection), to a few hundredths of a texel on average and with
    no bias toward the camera: the depth between texel centres is bilinear in 1 / depth (exact
    for a plane), and the hit keeps its place inside the texel. The nearest texel's depth alone,
    a staircase, put the hit 0.23 texel nearer on average (the glass ball's refracted floor
    misplaced by up to 0.7 pixel)."""
    vp, eye, vd, rays = camera()
    depth = floor_depth(rays, eye, -1.0)
    rng = np.random.default_rng(3)
    origins = np.stack(
        [rng.uniform(-0.6, 0.6, 400), rng.uniform(-0.5, 0.5, 400), rng.uniform(-0.3, 0.3, 400)], -1
    )
    dirs = unit(
        np.stack([rng.uniform(-0.2, 0.2, 400), rng.uniform(0.6, 1.0, 400), rng.uniform(-0.6, -0.25, 400)], -1)
    )
    hit, rows, cols = refract.march(origins, dirs, depth, vp, eye, vd, (1, 1, 0, 0), edge=False)
    s = (-1.0 - origins[:, 2]) / dirs[:, 2]
    q = origins + s[:, None] * dirs
    clip = np.c_[q, np.ones(len(q))] @ vp.T
    uv = clip[:, :2] / clip[:, 3:] * 0.5 + 0.5
    want_rows, want_cols = SIZE * (1.0 - uv[:, 1]), SIZE * uv[:, 0]
    inside = (uv >= 0.0).all(axis=1) & (uv < 1.0).all(axis=1)
    assert hit[inside].mean() > 0.95 and inside.sum() > 200
    m = hit & inside
    d_row, d_col = rows[m] - want_rows[m], cols[m] - want_cols[m]
    assert abs(np.mean(d_row)) < 0.05 and abs(np.mean(d_col)) < 0.05
    assert np.mean(np.abs(d_row)) < 0.1 and np.mean(np.abs(d_col)) < 0.1
    # and the colour seen there is the picture's, between texel centres: a ramp reads true
    ramp = np.broadcast_to((np.arange(SIZE) + 0.5)[:, None, None], (SIZE, SIZE, 3))
    seen = refract.seen(hit[m], rows[m], cols[m], ramp, np.zeros((m.sum(), 3)), depth)
    inner = (rows[m] > 0.5) & (rows[m] < SIZE - 0.5)
    assert np.max(np.abs(seen[inner, 0] - rows[m][inner])) < 1e-9


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


def test_the_picture_behind_is_read_sharp_between_texel_centres():
    """refract.sharp (tf_behind_colour_at): a linear ramp reads true, a step is crossed within
    a texel as Catmull–Rom crosses it (slope 1.25 per texel at its middle against bilinear's 1,
    never past its two sides), and across a depth edge, near the picture's edge or over two
    surfaces, the read is bilinear."""
    size = 16
    ramp = np.broadcast_to((np.arange(size) + 0.5)[None, :, None] * 0.1, (size, size, 3)).copy()
    depth = np.full((size, size), 2.0)
    rows = np.full(50, 8.3)
    cols = np.linspace(2.5, 13.5, 50)
    np.testing.assert_allclose(refract.sharp(ramp, depth, rows, cols)[:, 0], 0.1 * cols, atol=1e-12)
    step = np.zeros((size, size, 3))
    step[:, 8:] = 1.0
    mid = np.array([7.5, 8.0, 8.5])  # texel centre 7.5 (0), the edge, texel centre 8.5 (1)
    sharp = refract.sharp(step, depth, np.full(3, 8.0), mid)[:, 0]
    linear = refract.bilinear(step, np.full(3, 8.0), mid)[:, 0]
    np.testing.assert_allclose(sharp, [0.0, 0.5, 1.0], atol=1e-12)
    np.testing.assert_allclose(linear, [0.0, 0.5, 1.0], atol=1e-12)
    h = 1e-3
    slope = (refract.sharp(step, depth, np.full(2, 8.0), [8.0 - h, 8.0 + h])[:, 0] @ [-1, 1]) / (2 * h)
    assert slope == pytest.approx(1.25, abs=1e-5)
    quarter = refract.sharp(step, depth, np.full(1, 8.0), [7.75])[0, 0]
    assert 0.0 <= quarter < 0.25  # sharper than bilinear's 0.25, no undershoot (held at 0)
    # two surfaces among the sixteen texels (a depth edge a texel past the four): bilinear
    near = depth.copy()
    near[:, 9:] = 1.0
    np.testing.assert_allclose(
        refract.sharp(step, near, [8.0], [8.25]), refract.bilinear(step, [8.0], [8.25])
    )
    # the picture's edge: bilinear
    np.testing.assert_allclose(
        refract.sharp(step, depth, [0.9], [8.25]), refract.bilinear(step, [0.9], [8.25])
    )
