/* tf_common.glsl: constants and safe helpers shared by every Thin Film SH shader.
 *
 * numpy counterpart: the np.clip / norm guards of precompute/shading/ and image_io.srgb_encode.
 *
 * Variant defines (set from Python through GPUShaderCreateInfo.define):
 *   TF_L_MAX           SH order of the baked table, 0..12
 *   TF_SPECTRAL        3x3 colour matrix per coefficient (else one RGB triple, per channel)
 *   TF_VARY_THICKNESS  thickness from the per-vertex attribute `thickness` in [0, 1]
 *   TF_DISPLAY_SRGB    output display-encoded (exposure, clamp, sRGB OETF), else scene-linear
 *   TF_DISPLAY_LUT     with TF_DISPLAY_SRGB: the scene's view through the display LUT (tf_display.glsl)
 * Set at the top of the joined library by addon/gpu/shaders.py shading_library:
 *   TF_X90_GENERATED   the X(+-90) products come as generated straight-line code
 * Shading rules, never typed here (precompute/shading/policy.py glsl_defines, declared with
 * the variant's defines):
 *   TF_GIMBAL_SIN      below this sin(beta) the z-y-z split is a single z-rotation
 *   TF_TANGENT_EPS     below this |v - n (n.v)| the view is taken as parallel to n (float32)
 *   TF_DIVISION_FLOOR  the floor of a divisor or a squared length: 0/0 stays finite
 *   TF_MIN_COS, TF_MIN_ALPHA, TF_MAX_LAMPS, TF_LAMP_LEVEL, TF_GRAZING(x),
 *   TF_LADDER_ROUGHNESS(x), TF_LADDER_POSITION(r)   (see policy.py)
 */

#define TF_PI 3.14159265358979323846
#define TF_HALF_PI 1.57079632679489661923
/* Number of SH coefficients up to band TF_L_MAX: all of them, and those with m >= 0. */
#define TF_K_FULL ((TF_L_MAX + 1) * (TF_L_MAX + 1))
#define TF_K_KEPT ((TF_L_MAX + 1) * (TF_L_MAX + 2) / 2)
#define TF_BAND_MAX (2 * TF_L_MAX + 1)

float tf_clamp_cos(float c)
{
  return clamp(c, 0.0, 1.0);
}

/* normalize(v), or `fallback` when v is (nearly) zero: never NaN. */
vec3 tf_safe_normalize(vec3 v, vec3 fallback)
{
  float len2 = dot(v, v);
  return (len2 > TF_DIVISION_FLOOR) ? v * inversesqrt(len2) : fallback;
}

vec2 tf_safe_normalize2(vec2 v, vec2 fallback)
{
  float len2 = dot(v, v);
  return (len2 > TF_DIVISION_FLOOR) ? v * inversesqrt(len2) : fallback;
}

/* sRGB OETF (IEC 61966-2-1) of a value already clamped to [0, 1]. */
vec3 tf_srgb_oetf(vec3 x)
{
  vec3 lo = 12.92 * x;
  vec3 hi = 1.055 * pow(x, vec3(1.0 / 2.4)) - 0.055;
  return mix(hi, lo, vec3(lessThanEqual(x, vec3(0.0031308))));
}
