"""Solid glass's exit through its real mesh (precompute/shading/glass/glass_exit.py ``mesh_exit``), pure
numpy, against independent ray traces.

The glass buffers (the object's nearest front and back faces per pixel, ``glass_texel``'s
encoding) are built here analytically for a sphere and for a turned cube, at the camera of
tests/optics/test_refract.py; the exit the march finds is compared with a ray trace that intersects the
exact surface: Snell's law at each face, total internal reflection where it occurs.
"""

import numpy as np
import pytest
from _glass_mesh import Box, encode
from test_refract import SIZE, camera, sphere_hits, trace_sphere, unit

from precompute.shading.glass import glass_exit, refract


def sphere_buffers(rays, eye, view_dir, centre, radius, own=0):
    """(front, back) of a sphere seen by each pixel's ray."""
    oc = eye - centre
    b = rays @ oc
    disc = b * b - (oc @ oc - radius * radius)
    hit = disc > 0
    root = np.sqrt(np.maximum(disc, 0.0))
    buffers = []
    for t in (-b - root, -b + root):
        q = eye + t[..., None] * rays
        n = unit(q - centre)
        depth = (eye - q) @ view_dir
        buffers.append(encode(np.where(hit, own, -1), n, depth))
    return buffers


@pytest.mark.parametrize("eta", [1.33, 1.5])
def test_the_mesh_exit_of_a_sphere_matches_a_ray_trace(eta):
    """Buffers of a sphere: the march finds its far side; the exit direction equals the traced one
    to a fraction of the buffers' resolution: the normal at the exit is interpolated between the
    texel centres around it (the nearest texel's alone gave a median of 6e-3 and 9e-3, a texel of
    normal)."""
    vp, eye, vd, rays = camera()
    centre, radius = np.array([0.1, 0.2, -0.05]), 1.0
    front, back = sphere_buffers(rays, eye, vd, centre, radius)
    mask, p, n, v = sphere_hits(rays, eye, centre, radius)
    inner_cos = np.sum(n * v, -1)
    keep = inner_cos > 0.3  # the rim's inner rays run along the silhouette, a texel apart
    q, d, found, _cos = glass_exit.mesh_exit(p, n, v, centre, eta, 0, front, back, vp, eye, vd)
    ref_q, ref_d = trace_sphere(p, n, v, centre, eta)
    assert found[keep].all(), "the march found the sphere's far side everywhere but the rim"
    err = np.linalg.norm(d - ref_d, axis=-1)[keep]
    print(f"η {eta}: exit direction error median {np.median(err):.2e}, p99 {np.percentile(err, 99):.2e}")
    assert np.median(err) < 1e-3 and np.percentile(err, 99) < 0.01
    assert np.median(np.linalg.norm(q - ref_q, axis=-1)[keep]) < 0.01


def turned_box():
    c, s = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ np.array(
        [[1.0, 0, 0], [0, np.cos(0.3), -np.sin(0.3)], [0, np.sin(0.3), np.cos(0.3)]]
    )
    return Box([0.0, 0.3, -0.1], [0.6, 0.6, 0.6], turn)


def test_the_mesh_exit_of_a_cube_follows_its_faces_and_total_internal_reflection():
    """A turned glass cube: a flat face refracts the way the sphere about its centre cannot; where a
    side face reflects totally the ray is reflected and leaves through the next face."""
    vp, eye, vd, rays = camera()
    box = turned_box()
    front, back = box.buffers(rays, eye, vd)
    t_near, _tf, n_near, _nf = box.hits(np.broadcast_to(eye, rays.shape), rays)
    hit = np.isfinite(t_near)
    p = eye + t_near[hit][:, None] * rays[hit]
    n, v = n_near[hit], -rays[hit]
    eta = 1.5
    inner = unit(refract.refract(-v, n, 1.0 / eta))
    ref_q, ref_d = box.trace(p, inner, eta)
    # leave out the pixels next to the silhouette and the cube's edges (a texel there mixes faces)
    near_edge = np.zeros(hit.shape, bool)
    face = np.argmax(np.abs(n_near @ box.m), -1)
    for axis in (0, 1):
        for shift in (1, -1):
            near_edge |= np.roll(face, shift, axis) != face
            near_edge |= np.roll(hit, shift, axis) != hit
    keep = ~near_edge[hit]
    q, d, found, _cos = glass_exit.mesh_exit(p, n, v, box.c, eta, 0, front, back, vp, eye, vd)
    assert found[keep].all()
    err = np.linalg.norm(d - ref_d, axis=-1)[keep]
    tir = np.zeros(keep.shape, bool)
    _tn, t_far, _nn, n_far = box.hits(p, inner)
    tir = np.sum(refract.refract(inner, -n_far, eta) ** 2, -1) < 1e-12
    print(
        f"cube: exit direction error median {np.median(err):.2e}, p95 {np.percentile(err, 95):.2e},"
        f" {tir[keep].mean():.0%} of the pixels reflect totally once"
    )
    assert tir[keep].mean() > 0.05, "the scene should exercise total internal reflection"
    assert np.percentile(err, 95) < 0.02
    assert np.median(np.linalg.norm(q - ref_q, axis=-1)[keep]) < 0.01
    # the sphere about the cube's centre gets the same rays wrong: the mesh is what fixes them
    _sq, sd = refract.exit_ray(p, n, v, box.c, eta)
    assert np.median(np.linalg.norm(sd - ref_d, axis=-1)[keep]) > 0.1


def test_the_reflected_glint_ray_leaves_a_sphere_as_one_reflection_inside():
    """``reflections`` 1: reflected at the far side, out through the next: transmit.solid_internal."""
    from precompute.shading import transmit

    vp, eye, vd, rays = camera()
    centre = np.zeros(3)
    front, back = sphere_buffers(rays, eye, vd, centre, 1.0)
    _m, p, n, v = sphere_hits(rays, eye, centre, 1.0)
    keep = np.sum(n * v, -1) > 0.5
    _q, d, found, _cos = glass_exit.mesh_exit(
        p, n, v, centre, 1.5, 0, front, back, vp, eye, vd, reflections=1
    )
    assert found[keep].all()
    err = np.linalg.norm(d - transmit.solid_internal(n, v, 1.5), axis=-1)[keep]
    # two faces' normals, each a texel's (~0.03 rad apart at this sphere's 35-pixel radius), and
    # a reflection that doubles the normal's error
    print(f"glint direction error median {np.median(err):.2e}")
    assert np.median(err) < 0.05


def test_without_the_object_in_the_buffers_the_sphere_stands_in():
    vp, eye, vd, rays = camera()
    centre = np.zeros(3)
    front, back = sphere_buffers(rays, eye, vd, centre, 1.0, own=3)  # another object's faces
    _m, p, n, v = sphere_hits(rays, eye, centre, 1.0)
    q, d, found, _cos = glass_exit.mesh_exit(p, n, v, centre, 1.5, 0, front, back, vp, eye, vd)
    sq, sd = refract.exit_ray(p, n, v, centre, 1.5)
    assert not found.any()
    assert np.array_equal(d, sd) and np.array_equal(q, sq)


def test_glass_texel_decodes_ids_normals_and_depth():
    ids, normals, depth = glass_exit.glass_texel([[0.0, 0.0, 0.0, 0.0], [0.0, 0.0, -3.0, 7.5]])
    assert ids.tolist() == [-1, 2]
    assert np.allclose(normals[1], [0, 0, -1]) and depth[1] == 7.5
    assert SIZE > 0


# ----------------------------------------------------------------------------------------------
# Smooth-shaded faces as Cycles meets them (``valid_normal``, the geometric normals)


def test_octahedral_coordinates_round_trip_every_direction():
    rng = np.random.default_rng(7)
    n = unit(rng.normal(size=(4000, 3)))
    n = np.concatenate([n, np.eye(3), -np.eye(3)])
    e = glass_exit.octahedral(n)
    assert np.all(np.abs(e) <= 1.0 + 1e-12)
    assert np.max(np.abs(glass_exit.from_octahedral(e) - n)) < 1e-12


def test_a_valid_normal_lifts_a_mirror_that_dips_below_its_face_to_cycles_threshold():
    """Cycles' rule (ensure_valid_specular_reflection), checked by its defining properties: a
    normal whose mirror of the incoming direction rises at least t = min(0.9 cos, 0.01) above the
    face is kept; any other is turned towards the geometric normal, in the plane of the two, to a
    unit normal whose mirror rises exactly t."""
    rng = np.random.default_rng(3)
    ng = np.tile([0.0, 0.0, 1.0], (20000, 1))
    wi = unit(rng.normal(size=ng.shape) * [1.0, 1.0, 0.5] + [0.0, 0.0, 0.05])
    wi[:, 2] = np.abs(wi[:, 2]) + 1e-3
    wi = unit(wi)
    n = unit(ng + rng.normal(size=ng.shape) * 0.6)  # smooth normals up to far off the face's
    n[n[:, 2] < 0.2] = unit(n[n[:, 2] < 0.2] + [0.0, 0.0, 1.0])
    n = unit(n)
    n[np.sum(n * wi, -1) <= 0.0] = ng[0]  # the incoming side of the smooth normal, as Cycles asks

    def rise(normal, w=wi):
        return np.sum(ng[: len(w)] * (2.0 * np.sum(normal * w, -1, keepdims=True) * normal - w), -1)

    t = np.minimum(0.9 * wi[:, 2], 0.01)
    out = glass_exit.valid_normal(ng, wi, n)
    kept = rise(n) >= t
    assert 0.05 < kept.mean() < 0.95  # both branches exercised
    assert np.array_equal(out[kept], n[kept])
    lifted = ~kept
    assert np.max(np.abs(np.linalg.norm(out[lifted], axis=-1) - 1.0)) < 1e-9
    assert np.max(np.abs(rise(out[lifted], wi[lifted]) - t[lifted])) < 1e-7
    coplanar = np.einsum("ij,ij->i", np.cross(n[lifted], ng[lifted]), out[lifted])
    assert np.max(np.abs(coplanar)) < 1e-9
    assert np.all(out[lifted, 2] > n[lifted, 2])  # turned towards the face's normal


def _towards(flat, toward, degrees):
    """Unit normals ``flat`` (…, 3) tilted by ``degrees`` towards the direction ``toward``."""
    side = unit(toward - np.sum(toward * flat, -1, keepdims=True) * flat)
    return unit(flat + np.tan(np.radians(degrees)) * side)


def slab_view():
    """A thin glass slab (a wine glass's foot) seen at 76° from its normal by the test camera:
    its exact flat buffers, its faces' smooth normals tilted towards the viewer, 40° on the top
    and 17° on the bottom, as a foot shaded smooth across its rim has them."""
    vp, eye, vd, rays = camera()
    tilt = np.radians(-14.0)  # the slab's normal 76° from the view
    turn = np.array([[1.0, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]])
    box = Box([0.0, 0.0, 0.0], [1.6, 1.6, 0.08], turn)
    front, back = box.buffers(rays, eye, vd)
    ids, flat, depth = glass_exit.glass_texel(back)
    toward = unit(eye - box.c)
    smooth_back = encode(ids, _towards(flat, toward, 17.0), depth)
    _i, flat_front, _d = glass_exit.glass_texel(front)
    geometric = np.concatenate([glass_exit.octahedral(flat_front), glass_exit.octahedral(flat)], axis=-1)
    t_near, _tf, n_near, _nf = box.hits(np.broadcast_to(eye, rays.shape), rays)
    hit = np.isfinite(t_near) & (ids == 0)
    p = eye + t_near[hit][:, None] * rays[hit]
    v = -rays[hit]
    smooth_front = _towards(n_near[hit], v, 40.0)
    return (vp, eye, vd), box, front, smooth_back, geometric, p, smooth_front, n_near[hit], v


def test_a_smooth_shaded_face_keeps_the_ray_inside_as_cycles_does():
    """Inside the slab the ray meets the bottom face beyond the critical angle of its tilted
    smooth normal. Where the mirror about that normal dips below the face (found here from the
    slab's planes), the march that reads the smooth normal alone lets the ray out right there,
    down through the bottom; Cycles lifts the normal so that the mirror grazes along the face
    (rising min(0.9 cos, 0.01) above it), and the ray goes on inside: with the geometric normals
    it leaves elsewhere, or its path ends."""
    (vp, eye, vd), box, front, back, geometric, p, n, flat, v = slab_view()
    toward_eye = np.sign(np.sum((eye - box.c) * box.m[:, 2]))
    bottom = -box.m[:, 2] * toward_eye  # the outward normal of the face away from the viewer
    d0 = unit(refract.refract(-v, n, 1.0 / 1.5))
    # where the inner ray meets the bottom plane, and the smooth normal there
    reach = (np.sum((box.c + 0.08 * bottom - p) * bottom, -1)) / np.sum(d0 * bottom, -1)
    first = p + reach[:, None] * d0
    nb = _towards(np.broadcast_to(bottom, first.shape), unit(eye - first), 17.0)
    tir = np.sum(refract.refract(d0, -nb, 1.5) ** 2, -1) < 1e-12
    dips = tir & (np.sum((d0 - 2.0 * np.sum(d0 * nb, -1, keepdims=True) * nb) * bottom, -1) > 0.0)
    args = (p, n, v, box.c, 1.5, 0, front, back, vp, eye, vd)
    q_old, _d, found_old, _c = glass_exit.mesh_exit(*args)
    q, _d, found, cos = glass_exit.mesh_exit(*args, geometric=geometric, entry_geometric=flat)
    at_first_old = np.linalg.norm(q_old - first, axis=-1) < 0.05
    at_first = (np.linalg.norm(q - first, axis=-1) < 0.05) & ~np.isnan(cos[:, 1])
    print(
        f"slab: {len(p)} px, {dips.mean():.0%} of them with a mirror that dips below the bottom; "
        f"of those, out at the first face: {at_first_old[dips].mean():.0%} with the smooth normal "
        f"alone, {at_first[dips].mean():.0%} as Cycles meets the face"
    )
    assert found.mean() > 0.9 and found_old.mean() > 0.9 and dips.mean() > 0.2
    assert at_first_old[dips].mean() > 0.8  # the rest: the march's resolution at the slab's edges
    assert at_first[dips].mean() < 0.05


def test_flat_faces_meet_the_march_as_before():
    """Where the geometric normals are the shading normals (a flat-shaded cube) the rules change
    nothing: the exits equal those of the march that reads the shading normals alone."""
    vp, eye, vd, rays = camera()
    box = turned_box()
    front, back = box.buffers(rays, eye, vd)
    t_near, _tf, n_near, _nf = box.hits(np.broadcast_to(eye, rays.shape), rays)
    ids, nf, _d = glass_exit.glass_texel(front)
    _ib, nb, _db = glass_exit.glass_texel(back)
    hit = np.isfinite(t_near) & (ids == 0)
    p, n, v = eye + t_near[hit][:, None] * rays[hit], n_near[hit], -rays[hit]
    geometric = np.concatenate([glass_exit.octahedral(nf), glass_exit.octahedral(nb)], axis=-1)
    for k in (0, 1):
        args = (p, n, v, box.c, 1.5, 0, front, back, vp, eye, vd)
        plain = glass_exit.mesh_exit(*args, reflections=k)
        ruled = glass_exit.mesh_exit(*args, reflections=k, geometric=geometric, entry_geometric=n)
        carried = ~np.isnan(plain[3][:, 1]) & ~np.isnan(ruled[3][:, 1])
        # a glint's path that leaves in one and not the other: where the face a step lands on in
        # the buffers is not the one its ray crosses (a texel at an edge), a pixel in a thousand
        assert np.mean(np.isnan(plain[3][:, 1]) != np.isnan(ruled[3][:, 1])) < 1e-3
        assert np.array_equal(plain[2], ruled[2])
        for a, b in zip(plain[:2] + plain[3:], ruled[:2] + ruled[3:], strict=True):
            assert np.allclose(a[carried], b[carried], atol=1e-9, equal_nan=True)


def layered_buffers(boxes, rays, eye, view_dir):
    """(front, back) (layers, H, W, 4) of one object made of ``boxes``: per pixel its front faces
    nearest first, and its back faces (depth peeling, as addon/gpu/glass_buffers.py draws)."""
    sides = []
    for side in (0, 1):
        depth, faces = [], []
        for box in boxes:
            t_near, t_far, n_near, n_far = box.hits(np.broadcast_to(eye, rays.shape), rays)
            t, n = (t_near, n_near) if side == 0 else (t_far, n_far)
            hit = np.isfinite(t_near) & (t_near > 0)
            q = eye + np.where(hit, t, 0.0)[..., None] * rays
            depth.append(np.where(hit, (eye - q) @ view_dir, np.inf))
            faces.append(n)
        order = np.argsort(np.stack(depth), axis=0)
        depth, faces = np.stack(depth), np.stack(faces)
        layers = []
        for k in range(len(boxes)):
            pick = order[k]
            d = np.take_along_axis(depth, pick[None], 0)[0]
            n = np.take_along_axis(faces, pick[None, ..., None], 0)[0]
            layers.append(encode(np.where(np.isfinite(d), 0, -1), n, np.where(np.isfinite(d), d, 0.0)))
        sides.append(np.stack(layers))
    return sides


def exit_errors(q, d, ref_q, ref_d, where):
    """(exit point errors, exit direction errors) against a reference, over the lanes ``where``."""
    return np.linalg.norm(q - ref_q, axis=-1)[where], np.linalg.norm(d - ref_d, axis=-1)[where]


def two_boxes(far_turn=None):
    """One object of two boxes, the second behind the first (a wine glass's far wall behind its
    near one; turned as the first, or by ``far_turn``), its two-layer buffers, the camera's pixels
    that see the near box first, and an exact trace through both (a dict)."""
    vp, eye, vd, rays = camera()
    turn = turned_box().m
    near = Box([-0.2, -0.3, 0.0], [0.35, 0.2, 0.5], turn)
    far = Box([0.15, 0.9, 0.1], [0.45, 0.25, 0.45], turn if far_turn is None else far_turn)
    front, back = layered_buffers([near, far], rays, eye, vd)
    t_near, _tf, n_near, _nf = near.hits(np.broadcast_to(eye, rays.shape), rays)
    t_far_box = far.hits(np.broadcast_to(eye, rays.shape), rays)[0]
    hit = np.isfinite(t_near) & (t_near < t_far_box)
    p = eye + t_near[hit][:, None] * rays[hit]
    n, v = n_near[hit], -rays[hit]
    eta = 1.5
    q1, d1 = near.trace(p, unit(refract.refract(-v, n, 1.0 / eta)), eta)
    tn2, _t2, n2, _n2 = far.hits(q1 + 1e-9 * d1, d1)
    enters = np.isfinite(tn2) & (tn2 > 0)
    p2 = q1 + np.where(enters, tn2, 0.0)[:, None] * d1
    q2, d2 = far.trace(p2, unit(refract.refract(d1, n2, 1.0 / eta)), eta)
    # the paths that meet every face a texel or more from its edges in the buffers (a texel at an
    # edge mixes two faces' normals)
    keep = np.ones(len(p), bool)
    for box, side, at in ((near, 0, p), (near, 1, q1), (far, 0, p2), (far, 1, q2)):
        keep &= ~on_edge(box, side, at, rays, eye, vd, vp) | ((box is far) & ~enters)
    args = (front, back, vp, eye, vd)
    return dict(locals())


def on_edge(box, side, at, rays, eye, vd, vp):
    """Whether points ``at`` lie a texel or less from an edge of ``box``'s faces in its buffer
    ``side`` (0 front, 1 back)."""
    ids, normals, _depth = glass_exit.glass_texel(box.buffers(rays, eye, vd)[side])
    face = np.where(ids >= 0, np.argmax(normals @ box.m, -1) + 3 * np.argmax(-normals @ box.m, -1), -1)
    edge = np.zeros(face.shape, bool)
    for axis in (0, 1):
        for shift in (1, -1):
            edge |= np.roll(face, shift, axis) != face
    row, col, _in = refract._project(np.nan_to_num(at), vp, np.array([1.0, 1.0, 0.0, 0.0]), face.shape)
    return edge[row, col]


def test_a_ray_that_leaves_a_concave_glass_enters_its_further_span():
    """The two boxes: with two layers in the buffers the ray that leaves the near box enters the
    far one and leaves it where an exact trace through both boxes does; with the nearest layer
    alone it would go on to the scene behind from the near box."""
    t = two_boxes()
    p, n, v, keep, enters, eta = t["p"], t["n"], t["v"], t["keep"], t["enters"], t["eta"]
    ref_q = np.where(enters[:, None], t["q2"], t["q1"])
    ref_d = np.where(enters[:, None], t["d2"], t["d1"])
    q, d, found, cos, branches = glass_exit.mesh_exit(p, n, v, t["near"].c, eta, 0, *t["args"], side=True)
    entered = ~np.isnan(cos[:, 2])
    assert found[keep].all() and cos.shape == (len(p), 4)
    assert enters[keep].mean() > 0.2, "the scene should send rays from the near box into the far one"
    agree = np.mean(entered[keep] == enters[keep])
    err_q, err_d = exit_errors(q, d, ref_q, ref_d, keep)
    print(
        f"two boxes: {enters[keep].mean():.0%} of the rays enter the far box, the march agrees on"
        f" {agree:.1%}; exit point error median {np.median(err_q):.1e}, direction p95"
        f" {np.percentile(err_d, 95):.1e}"
    )
    assert agree > 0.97  # the rest pass a texel from the far box's silhouette
    assert np.median(err_q) < 0.01 and np.percentile(err_d, 95) < 0.02
    # the film's mirror where the ray enters the far box: from its entry point (found on the
    # face's depth at a texel, ~0.03 wide there), mirrored about its face
    both = keep & enters & entered
    d1, n2 = t["d1"], t["n2"]
    mirror = d1 - 2.0 * np.sum(d1 * n2, -1, keepdims=True) * n2
    assert np.array_equal(~np.isnan(branches.mirror_point[:, 0]), entered)
    assert np.median(np.linalg.norm(branches.mirror_point - t["p2"], axis=-1)[both]) < 0.03
    assert np.percentile(np.linalg.norm(branches.mirror_dir - mirror, axis=-1)[both], 95) < 0.02
    # the nearest layer alone: the rays that should enter the far box leave from the near one
    front, back, vp, eye, vd = t["args"]
    q0, _d0, _f0, cos0 = glass_exit.mesh_exit(p, n, v, t["near"].c, eta, 0, front[0], back[0], vp, eye, vd)
    assert cos0.shape == (len(p), 2)
    assert np.median(np.linalg.norm(q0 - ref_q, axis=-1)[keep & enters]) > 0.3


def test_the_far_walls_branches_go_back_through_the_glass():
    """The two boxes: the far box's film mirror (in the air between them) and its reflection back
    inside where the path leaves it (glass_exit.Branches) are followed back through the glass
    (branch_exit): the mirror enters the near box from behind and leaves it, the inner reflection
    leaves the far box, enters the near one and leaves it, each where an exact trace does."""
    c, s = np.cos(np.radians(8.0)), np.sin(np.radians(8.0))
    t = two_boxes(
        np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    )  # its front face about square to the view
    near, far, eta, keep = t["near"], t["far"], t["eta"], t["keep"]
    _q, _d, _found, cos, b = glass_exit.mesh_exit(
        t["p"], t["n"], t["v"], near.c, eta, 0, *t["args"], side=True
    )
    vp, eye, vd, rays = t["vp"], t["eye"], t["vd"], t["rays"]

    def through_near(o, d):  # exact: in air from o along d, through the near box if it meets it
        tn, _tf, nn, _nf = near.hits(o + 1e-9 * d, d)
        met = np.isfinite(tn) & (tn > 0)
        entry = o + np.where(met, tn, 0.0)[:, None] * d
        q, out = near.trace(entry, unit(refract.refract(d, nn, 1.0 / eta)), eta)
        cos = np.clip(-np.sum(d * nn, -1), 0.0, 1.0)
        return met, entry, np.where(met[:, None], q, np.nan), np.where(met[:, None], out, d), cos

    # the mirror: from the far box's face, in the air, back towards the near box
    live = keep & ~np.isnan(b.mirror_point[:, 0])
    met, entry, ref_q, ref_d, ref_cos = through_near(b.mirror_point, b.mirror_dir)
    keep_m = live & ~on_edge(near, 1, entry, rays, eye, vd, vp) & ~on_edge(near, 0, ref_q, rays, eye, vd, vp)
    q, d, followed, cos_entry, cos_m = glass_exit.branch_exit(
        b.mirror_point, b.mirror_dir, True, near.c, eta, 0, *t["args"]
    )
    agree = np.mean((followed & ~np.isnan(cos_entry))[keep_m] == met[keep_m])
    both = keep_m & met & followed
    err_q, err_d = exit_errors(q, d, ref_q, ref_d, both)
    print(
        f"mirror: {live.sum()} branches, {met[keep_m].mean():.0%} meet the near box again, the march"
        f" agrees on {agree:.1%}; exit point error median {np.median(err_q):.1e}, direction p95"
        f" {np.percentile(err_d, 95):.1e}"
    )
    assert live.sum() > 200 and met[keep_m].mean() > 0.2 and agree > 0.95
    assert np.median(err_q) < 0.02 and np.percentile(err_d, 95) < 0.05
    assert np.median(np.abs(cos_entry - ref_cos)[both]) < 0.01  # the film's cosine where it enters
    # the inner reflection: where the path leaves the far box (no total reflection there), back
    # inside it about that face, out of it, and on through the near box
    inside_far = unit(refract.refract(t["d1"], t["n2"], 1.0 / eta))
    _tn, t_out, _nn, n_out = far.hits(t["p2"] + 1e-9 * inside_far, inside_far)
    straight = np.sum(refract.refract(inside_far, -n_out, eta) ** 2, -1) > 1e-12  # no total reflection
    live = keep & straight & ~np.isnan(b.inner_point[:, 0])
    at = t["p2"] + t_out[:, None] * inside_far
    back_in = inside_far - 2.0 * np.sum(inside_far * n_out, -1, keepdims=True) * n_out
    q4, d4 = far.trace(at, back_in, eta)
    met, entry, ref_q, ref_d, _cos = through_near(q4, d4)
    ref_q = np.where(met[:, None], ref_q, q4)
    keep_i = live & ~on_edge(far, 0, q4, rays, eye, vd, vp) & ~on_edge(near, 1, entry, rays, eye, vd, vp)
    keep_i &= ~on_edge(near, 0, ref_q, rays, eye, vd, vp)
    assert np.percentile(np.linalg.norm(b.inner_point - at, axis=-1)[live], 50) < 0.03
    q, d, followed, _cos_entry, cos_i = glass_exit.branch_exit(
        b.inner_point, b.inner_dir, False, near.c, eta, 0, *t["args"]
    )
    leaves = followed & ~np.isnan(cos_i[:, 1])
    entered_near = ~np.isnan(cos_i[:, 2])
    agree = np.mean(entered_near[keep_i & leaves] == met[keep_i & leaves])
    both = keep_i & leaves
    err_q, err_d = exit_errors(q, d, ref_q, ref_d, both)
    print(
        f"inner: {live.sum()} branches, {leaves[keep_i].mean():.0%} leave, {met[both].mean():.0%} through"
        f" the near box,"
        f" the march agrees on {agree:.1%}; exit point error median {np.median(err_q):.1e}, direction p95"
        f" {np.percentile(err_d, 95):.1e}"
    )
    assert live.sum() > 200 and leaves[keep_i].mean() > 0.9 and met[both].mean() > 0.1 and agree > 0.95
    assert np.median(err_q) < 0.02 and np.percentile(err_d, 95) < 0.05


def sphere_t(o, d, centre, radius):
    """(near, far) distances along rays o + t d (…, 3) to a sphere; inf where they miss it."""
    oc = o - centre
    b = np.sum(d * oc, -1)
    disc = b * b - (np.sum(oc * oc, -1) - radius * radius)
    root = np.sqrt(np.maximum(disc, 0.0))
    return np.where(disc > 0, -b - root, np.inf), np.where(disc > 0, -b + root, np.inf)


def test_a_ray_guided_along_a_shell_leaves_across_its_silhouette():
    """A hollow glass ball (a thin shell, a wine glass's bowl in small): the rays that enter it
    outside the cavity's silhouette are guided along the shell by total internal reflection and
    leave through its outer face where that face is seen edge-on, past the last covered texel.
    The march reads that face on the last texel inside (the texel where the exit lies is
    empty): it carries most of the paths an exact trace sees leave (47 % when the empty texel's
    face was read), and each leaves on the outer sphere near the exact exit point."""
    vp, eye, vd, rays = camera()
    c, outer, inner = np.array([0.05, 0.1, 0.0]), 1.0, 0.9
    eyes = np.broadcast_to(eye, rays.shape)
    t0, t3 = sphere_t(eyes, rays, c, outer)
    t1, t2 = sphere_t(eyes, rays, c, inner)
    hit, cavity = np.isfinite(t0), np.isfinite(t1)

    def faces(t, sign, valid):
        q = eye + np.where(valid, t, 0.0)[..., None] * rays
        return encode(np.where(valid, 0, -1), sign * unit(q - c), np.where(valid, (eye - q) @ vd, 0.0))

    # two layers: the outer face and, through the cavity, the inner faces and the far outer face
    front = np.stack([faces(t0, 1.0, hit), faces(t2, -1.0, cavity)])
    back = np.stack(
        [np.where(cavity[..., None], faces(t1, -1.0, cavity), faces(t3, 1.0, hit)), faces(t3, 1.0, cavity)]
    )
    eta = 1.5
    ring = hit & ~cavity
    p, v = eye + t0[ring][:, None] * rays[ring], -rays[ring]
    n = unit(p - c)
    # exact: refracted out where it can, else reflected, at the shell's faces
    o, d = p.copy(), unit(refract.refract(-v, n, 1.0 / eta))
    left = np.zeros(len(p), bool)
    exit_p = p.copy()
    for _ in range(60):
        _tn, t_out = sphere_t(o + 1e-9 * d, d, c, outer)
        t_in, _tf = sphere_t(o + 1e-9 * d, d, c, inner)
        to_inner = np.where(t_in > 1e-9, t_in, np.inf) < t_out
        q = o + np.minimum(np.where(t_in > 1e-9, t_in, np.inf), t_out)[:, None] * d
        normal = np.where(to_inner[:, None], -1.0, 1.0) * unit(q - c)  # the glass's outward normal
        tir = np.sum(refract.refract(d, -normal, eta) ** 2, -1) < 1e-12
        leave = ~left & ~tir
        assert not (leave & to_inner).any()  # none of these reaches the cavity
        exit_p = np.where(leave[:, None], q, exit_p)
        left |= leave
        o = np.where(left[:, None], o, q)
        d = np.where(left[:, None], d, d - 2.0 * np.sum(d * normal, -1, keepdims=True) * normal)
    assert left.all()
    q, _d, found, cos = glass_exit.mesh_exit(p, n, v, c, eta, 0, front, back, vp, eye, vd)
    carried = found & ~np.isnan(cos[:, 1])
    radius_err = np.abs(np.linalg.norm(q - c, axis=-1) - outer)[carried]
    point_err = np.linalg.norm(q - exit_p, axis=-1)[carried]
    print(
        f"shell: {len(p)} rays guided along it, {carried.mean():.0%} carried; exit radius error median"
        f" {np.median(radius_err):.1e}, exit point error median {np.median(point_err):.1e}"
    )
    assert carried.mean() > 0.8
    assert np.median(radius_err) < 0.01 and np.median(point_err) < 0.02
