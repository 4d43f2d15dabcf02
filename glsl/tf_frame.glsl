#include "tf_common.glsl"

/* tf_frame.glsl: the view-aligned shading frame and its z-y-z Euler angles.
 *
 * numpy counterpart: shading.frame.view_aligned_frame and shading.frame.zyz_from_frame.
 * Rows (x, y, z) of the frame: z = n, x = normalise(v - n (n.v)), y = z cross x. When v is
 * parallel to n the tangent closest to world +x (or +y when n is near x) is used.
 *
 * float32 care (same maths, better conditioned):
 *  - t.z = v.z (nx^2 + ny^2) - nz (nx vx + ny vy) equals v.z - nz (n.v) for a unit n but
 *    does not cancel near the poles, so the angle a = atan2(x.z, y.z) stays accurate there;
 *  - sin(beta) = |n.xy| instead of sqrt(1 - nz^2);
 *  - sin(theta_o) = |t| so theta_o = atan(|t|, n.v) is accurate at normal incidence.
 */

struct TFFrame {
  vec3 x;
  vec3 y;
  vec3 z;
  float cos_o; /* n.v, not clamped */
  float sin_o; /* |v - n (n.v)| */
};

TFFrame tf_view_aligned_frame(vec3 n, vec3 v)
{
  TFFrame f;
  float nv = dot(n, v);
  vec3 t = v - n * nv;
  t.z = v.z * dot(n.xy, n.xy) - n.z * dot(n.xy, v.xy);
  float tl = length(t);
  if (!(tl > TF_TANGENT_EPS)) {
    vec3 helper = (abs(n.x) < TF_HELPER_AXIS_MAX) ? vec3(1.0, 0.0, 0.0) : vec3(0.0, 1.0, 0.0);
    t = helper - n * dot(n, helper);
  }
  f.x = normalize(t);
  f.y = cross(n, f.x);
  f.z = n;
  f.cos_o = nv;
  f.sin_o = tl;
  return f;
}

/* (cos, sin) of a, b, c with frame = Rz(a) Ry(b) Rz(c); entries r_ij = row i, column j.
 * cos b = r22, a = atan2(r12, r02), c = atan2(r21, -r20); at the poles (sin b < GIMBAL_SIN)
 * c = 0 and a carries the whole z-rotation: R = Rz(a + c) (b = 0) or, for b = pi,
 * r00 = -cos(a - c), hence the sign flip. */
void tf_zyz_from_frame(TFFrame f, out vec2 a, out vec2 b, out vec2 c)
{
  float sb = length(f.z.xy);
  b = tf_safe_normalize2(vec2(f.z.z, sb), vec2(1.0, 0.0));
  if (sb < TF_GIMBAL_SIN) {
    float s = (f.z.z > 0.0) ? 1.0 : -1.0;
    a = tf_safe_normalize2(s * vec2(f.x.x, f.y.x), vec2(1.0, 0.0));
    c = vec2(1.0, 0.0);
  }
  else {
    a = tf_safe_normalize2(vec2(f.x.z, f.y.z), vec2(1.0, 0.0));
    c = tf_safe_normalize2(vec2(-f.z.x, f.z.y), vec2(1.0, 0.0));
  }
}
