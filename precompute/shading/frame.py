"""The view-aligned shading frame and its z-y-z Euler angles (numpy twin of glsl/tf_frame.glsl).

Rows (x, y, z) of the frame: z = n, x = normalise(v − n (n·v)), y = z × x, so the view vector
has φ = 0 in it (docs/conventions.md, "Directions and frames").
"""

from __future__ import annotations

import numpy as np

from .policy import GIMBAL_SIN, HELPER_AXIS_MAX

#: |v − n (n·v)| below which the view is taken as parallel to n, in float64 (the GLSL, in
#: float32, uses policy.TANGENT_EPS).
TANGENT_EPS_F64 = 1e-9


def view_aligned_frame(normals, views) -> np.ndarray:
    """Rows (x, y, z) of the view-aligned frame, shape (…, 3, 3): z = n, x = normalise(v − n(n·v)).

    When v ∥ n the BRDF slice is rotationally symmetric, so any x works; we take the tangent
    closest to world +x (or +y when n ∥ x) so the result is continuous and never NaN.
    """
    n = np.asarray(normals, dtype=float)
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    v = np.asarray(views, dtype=float)
    t = v - n * np.sum(n * v, axis=-1, keepdims=True)
    tl = np.linalg.norm(t, axis=-1, keepdims=True)
    helper = np.where(
        np.abs(n[..., :1]) < HELPER_AXIS_MAX, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    )
    fallback = helper - n * np.sum(n * helper, axis=-1, keepdims=True)
    t = np.where(tl > TANGENT_EPS_F64, t, fallback)
    x = t / np.linalg.norm(t, axis=-1, keepdims=True)
    y = np.cross(n, x)
    return np.stack([x, y, n], axis=-2)


def zyz_from_frame(frame) -> tuple[np.ndarray, ...]:
    """(cos, sin) of a, b, c with frame = Rz(a) Ry(b) Rz(c); each array of shape (…).

    From the matrix entries: cos b = r22, a = atan2(r12, r02), c = atan2(r21, −r20). At the poles
    (sin b < :data:`~precompute.shading.policy.GIMBAL_SIN`) c = 0 and a carries the whole
    z-rotation.
    """
    r = np.asarray(frame)
    cb = np.clip(r[..., 2, 2], -1.0, 1.0)
    sb = np.sqrt(np.maximum(0.0, 1.0 - cb * cb))
    pole = sb < GIMBAL_SIN
    ax, ay = r[..., 0, 2], r[..., 1, 2]
    cx, cy = -r[..., 2, 0], r[..., 2, 1]
    # Pole: R = Rz(a + c) (b = 0) or Rz(a) Ry(π) Rz(c) (b = π, r00 = −cos(a − c)).
    px = np.where(cb > 0, r[..., 0, 0], -r[..., 0, 0])
    py = np.where(cb > 0, r[..., 1, 0], -r[..., 1, 0])
    ax, ay = np.where(pole, px, ax), np.where(pole, py, ay)
    cx, cy = np.where(pole, 1.0, cx), np.where(pole, 0.0, cy)
    na = np.hypot(ax, ay)
    nc = np.hypot(cx, cy)
    return ax / na, ay / na, cb, sb, cx / nc, cy / nc
