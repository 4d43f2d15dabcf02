"""Analytic glass buffers for the mesh-refraction tests (tests/optics/test_refract_mesh.py,
tests/drawing/test_refract_mesh_draw.py): the texel encoding of addon/gpu/glass_buffers.py and a
turned box with its exact ray trace (Snell's law at each face, total internal reflection followed).
"""

import numpy as np

from precompute.shading.glass import refract


def unit(v):
    """``v`` (…, 3) normalised along its last axis."""
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def encode(ids, normals, depth):
    """Glass-buffer texels (H, W, 4): normal × (id + 1), depth; 0 where ``ids`` < 0."""
    out = np.zeros(ids.shape + (4,))
    on = ids >= 0
    out[on, :3] = normals[on] * (ids[on] + 1)[:, None]
    out[on, 3] = depth[on]
    return out


class Box:
    """A box of half sizes ``half`` turned by ``turn`` (3 × 3) about ``centre``."""

    def __init__(self, centre, half, turn):
        self.c, self.h, self.m = np.asarray(centre, float), np.asarray(half, float), np.asarray(turn, float)

    def hits(self, origins, dirs):
        """(t_near, t_far, near normal, far normal) of rays (…, 3) by the slab method; inf where missed."""
        o = (origins - self.c) @ self.m  # local: columns of m are the box axes
        d = dirs @ self.m
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-self.h - o) / d
            t2 = (self.h - o) / d
        lo, hi = np.minimum(t1, t2), np.maximum(t1, t2)
        t_near, axis_near = lo.max(-1), lo.argmax(-1)
        t_far, axis_far = hi.min(-1), hi.argmin(-1)
        miss = t_near > t_far
        axes = np.eye(3)
        sign_near = -np.sign(np.take_along_axis(d, axis_near[..., None], -1))[..., 0]
        sign_far = np.sign(np.take_along_axis(d, axis_far[..., None], -1))[..., 0]
        n_near = (axes[axis_near] * sign_near[..., None]) @ self.m.T
        n_far = (axes[axis_far] * sign_far[..., None]) @ self.m.T
        return np.where(miss, np.inf, t_near), np.where(miss, np.inf, t_far), n_near, n_far

    def buffers(self, rays, eye, view_dir, own=0):
        t_near, t_far, n_near, n_far = self.hits(np.broadcast_to(eye, rays.shape), rays)
        hit = np.isfinite(t_near) & (t_near > 0)
        out = []
        for t, n in ((t_near, n_near), (t_far, n_far)):
            q = eye + np.where(hit, t, 0.0)[..., None] * rays
            out.append(encode(np.where(hit, own, -1), n, (eye - q) @ view_dir))
        return out

    def trace(self, p, d, eta, bounces=3):
        """Exit (point, direction) of inner rays from ``p`` along ``d`` (N, 3), TIR followed."""
        p, d = p.copy(), d.copy()
        inside = np.ones(p.shape[0], bool)
        for _ in range(bounces):
            _tn, t_far, _nn, n_far = self.hits(p + 1e-9 * d, d)
            q = p + t_far[:, None] * d
            out = refract.refract(d, -n_far, eta)
            tir = np.sum(out * out, -1) < 1e-12
            with np.errstate(invalid="ignore"):
                new_d = np.where(
                    tir[:, None], d - 2.0 * np.sum(d * n_far, -1, keepdims=True) * n_far, unit(out)
                )
            p = np.where(inside[:, None], q, p)
            d = np.where(inside[:, None], new_d, d)
            inside &= tir
        return p, d
