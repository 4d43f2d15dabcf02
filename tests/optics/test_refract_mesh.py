"""Solid glass's exit through its real mesh (precompute/shading/refract.py ``mesh_exit``), pure
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

from precompute.shading import refract


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
    to the buffers' resolution (a texel of normal at the exit)."""
    vp, eye, vd, rays = camera()
    centre, radius = np.array([0.1, 0.2, -0.05]), 1.0
    front, back = sphere_buffers(rays, eye, vd, centre, radius)
    mask, p, n, v = sphere_hits(rays, eye, centre, radius)
    inner_cos = np.sum(n * v, -1)
    keep = inner_cos > 0.3  # the rim's inner rays run along the silhouette, a texel apart
    q, d, found, _cos = refract.mesh_exit(p, n, v, centre, eta, 0, front, back, vp, eye, vd)
    ref_q, ref_d = trace_sphere(p, n, v, centre, eta)
    assert found[keep].all(), "the march found the sphere's far side everywhere but the rim"
    err = np.linalg.norm(d - ref_d, axis=-1)[keep]
    print(f"η {eta}: exit direction error median {np.median(err):.2e}, p99 {np.percentile(err, 99):.2e}")
    assert np.median(err) < 0.01 and np.percentile(err, 99) < 0.05
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
    q, d, found, _cos = refract.mesh_exit(p, n, v, box.c, eta, 0, front, back, vp, eye, vd)
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
    _q, d, found, _cos = refract.mesh_exit(p, n, v, centre, 1.5, 0, front, back, vp, eye, vd, reflections=1)
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
    q, d, found, _cos = refract.mesh_exit(p, n, v, centre, 1.5, 0, front, back, vp, eye, vd)
    sq, sd = refract.exit_ray(p, n, v, centre, 1.5)
    assert not found.any()
    assert np.array_equal(d, sd) and np.array_equal(q, sq)


def test_glass_texel_decodes_ids_normals_and_depth():
    ids, normals, depth = refract.glass_texel([[0.0, 0.0, 0.0, 0.0], [0.0, 0.0, -3.0, 7.5]])
    assert ids.tolist() == [-1, 2]
    assert np.allclose(normals[1], [0, 0, -1]) and depth[1] == 7.5
    assert SIZE > 0
