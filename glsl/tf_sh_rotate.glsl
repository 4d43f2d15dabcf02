#include "tf_common.glsl"
#include "tf_frame.glsl"

/* tf_sh_rotate.glsl: rotate the World's radiance SH into the view-aligned frame.
 *
 * numpy counterpart: shading.sh_rotation.rotate_z_batch, apply_bands, local_coefficients.
 * rotation(Rz(a) Ry(b) Rz(c)) = Z(a) X(-90) Z(b) X(+90) Z(c), applied right to left
 * (Kautz, Sloan & Snyder 2002, section 4), because Ry(b) = Rx(-90) Rz(b) Rx(+90).
 * Z(angle) turns each (+m, -m) pair of band l by (cos m*angle, sin m*angle), obtained by the
 * recurrence c_m = c_(m-1) * c_1 (tf_cmul: complex product, same order of operations as numpy).
 * X(+-90) are constant band blocks read from the lighting buffer (tf_rx: tf_lighting.rx, layout
 * in addon/gpu/resources.py LIGHTING); X(-90) is read as the transpose of X(+90).
 *
 * The library (TF_X90_GENERATED) rotates for TF_L_MAX <= 2 straight from the frame rows
 * (tf_local_coefficients_direct, below); above, codegen.banded_source generates the z-y-z
 * operations as straight-line code over the structurally non-zero X(+-90) entries, one band at a
 * time, summed as it goes (tf_banded_sum). The readable reference, the same operations as
 * generic loops (tf_local_coefficients), is tests/glsl/tf_sh_rotate_loops.glsl, never shipped;
 * the tests compare all of them with numpy.
 */

/* Coefficients being rotated (file scope: arrays are not passed to functions). */
vec3 tf_c[TF_K_FULL];

float tf_rx(int k)
{
  return tf_lighting.rx[k >> 2][k & 3];
}

/* Complex product: (cos, sin) of the summed angles. */
vec2 tf_cmul(vec2 a, vec2 b)
{
  return vec2(a.x * b.x - a.y * b.y, a.y * b.x + a.x * b.y);
}

/* Bands 0..2 straight from the frame rows, for TF_L_MAX <= 2 (with TF_X90_GENERATED): the
 * radiance of band 1 is linear and that of band 2 quadratic in the direction, so turning them
 * into the frame needs a few dot products instead of five rotations and the z-y-z angles
 * (docs/tuning.md#direct-low-bands). Only the kept m >= 0 coefficients are written (tf_shade
 * reads no others); the result is rotation(frame) @ world like tf_local_coefficients
 * (numpy: sh_rotation.local_coefficients).
 *
 * Band 1 (Y = K1 (y, z, x) for m = -1, 0, 1, K1 = sqrt(3/4pi)): L(w) = K1 a.w with
 * a = (c3, c1, c2); in the frame w = F^T w', so a' = F a: c'2 = z.a, c'3 = x.a.
 * Band 2 (K2 = sqrt(15/pi)/2, K20 = sqrt(5/pi)/4): Y(-2..2) = K2 xy, K2 yz, K20 (3z^2 - 1),
 * K2 xz, K2/2 (x^2 - y^2); on the sphere 3z^2 - 1 = 2z^2 - x^2 - y^2, so L(w) = w^T Q w with
 * Q symmetric and traceless: Qxx = K2/2 c8 - K20 c6, Qyy = -K2/2 c8 - K20 c6, Qzz = 2 K20 c6,
 * Qxy = K2/2 c4, Qyz = K2/2 c5, Qxz = K2/2 c7. In the frame Q' = F Q F^T and
 * c'6 = Q'zz / (2 K20), c'7 = 2 Q'xz / K2, c'8 = (Q'xx - Q'yy) / K2 = (2 Q'xx + Q'zz) / K2
 * (the trace of Q' is 0). Each Q entry is an RGB triple. */
#define TF_K2 1.0925484305920792  /* sqrt(15 / pi) / 2 */
#define TF_K20 0.31539156525252005 /* sqrt(5 / pi) / 4 */

void tf_local_coefficients_direct(TFFrame f)
{
  tf_c[0] = tf_lighting.sh[0].rgb;
#if TF_L_MAX >= 1
  vec3 ax = tf_lighting.sh[3].rgb;
  vec3 ay = tf_lighting.sh[1].rgb;
  vec3 az = tf_lighting.sh[2].rgb;
  tf_c[2] = f.z.x * ax + f.z.y * ay + f.z.z * az;
  tf_c[3] = f.x.x * ax + f.x.y * ay + f.x.z * az;
#endif
#if TF_L_MAX >= 2
  vec3 c6 = tf_lighting.sh[6].rgb;
  vec3 c8 = tf_lighting.sh[8].rgb;
  vec3 qxy = (0.5 * TF_K2) * tf_lighting.sh[4].rgb;
  vec3 qyz = (0.5 * TF_K2) * tf_lighting.sh[5].rgb;
  vec3 qxz = (0.5 * TF_K2) * tf_lighting.sh[7].rgb;
  vec3 qzz = (2.0 * TF_K20) * c6;
  vec3 qxx = (0.5 * TF_K2) * c8 - TF_K20 * c6;
  vec3 qyy = -qxx - qzz;
  /* u = Q z, w = Q x (rows of Q times the frame axes) */
  vec3 ux = qxx * f.z.x + qxy * f.z.y + qxz * f.z.z;
  vec3 uy = qxy * f.z.x + qyy * f.z.y + qyz * f.z.z;
  vec3 uz = qxz * f.z.x + qyz * f.z.y + qzz * f.z.z;
  vec3 wx = qxx * f.x.x + qxy * f.x.y + qxz * f.x.z;
  vec3 wy = qxy * f.x.x + qyy * f.x.y + qyz * f.x.z;
  vec3 wz = qxz * f.x.x + qyz * f.x.y + qzz * f.x.z;
  vec3 q_zz = f.z.x * ux + f.z.y * uy + f.z.z * uz;
  vec3 q_xz = f.x.x * ux + f.x.y * uy + f.x.z * uz;
  vec3 q_xx = f.x.x * wx + f.x.y * wy + f.x.z * wz;
  tf_c[6] = q_zz * (1.0 / (2.0 * TF_K20));
  tf_c[7] = q_xz * (2.0 / TF_K2);
  tf_c[8] = (2.0 * q_xx + q_zz) * (1.0 / TF_K2);
#endif
}
