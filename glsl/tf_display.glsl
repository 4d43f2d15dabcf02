#include "tf_common.glsl"

/* tf_display.glsl: the scene's display transform (view, look, display, gamma) through the LUT
 * baked from OCIO on the CPU (addon/drawing/display.py).
 *
 * numpy counterpart: precompute.display_lut.apply (shaper, then the eight corners of the cell
 * fetched and interpolated: no hardware filtering, so both agree to float32 rounding).
 * The LUT texture (tf_display_lut, RGBA32F): width N * N (x = r + N * g), height N + 1 (y = b;
 * row N: the input matrix's rows in texels 0..2), N = TF_DISPLAY_LUT_SIZE. Compiled only for
 * TF_DISPLAY_LUT variants.
 */

#ifdef TF_DISPLAY_LUT
vec3 tf_display_shaper(vec3 x)
{
  float lo = log2(TF_DISPLAY_LUT_FLOOR);
  float hi = log2(TF_DISPLAY_LUT_MAX + TF_DISPLAY_LUT_FLOOR);
  return clamp((log2(max(x, vec3(0.0)) + TF_DISPLAY_LUT_FLOOR) - lo) / (hi - lo), 0.0, 1.0);
}

vec3 tf_display_at(ivec3 i)
{
  return texelFetch(tf_display_lut, ivec2(i.x + TF_DISPLAY_LUT_SIZE * i.y, i.z), 0).rgb;
}

/* Display-referred RGB of a scene-linear colour (exposure already applied). */
vec3 tf_display_lut_apply(vec3 rgb)
{
  vec3 m0 = texelFetch(tf_display_lut, ivec2(0, TF_DISPLAY_LUT_SIZE), 0).rgb;
  vec3 m1 = texelFetch(tf_display_lut, ivec2(1, TF_DISPLAY_LUT_SIZE), 0).rgb;
  vec3 m2 = texelFetch(tf_display_lut, ivec2(2, TF_DISPLAY_LUT_SIZE), 0).rgb;
  vec3 x = vec3(dot(m0, rgb), dot(m1, rgb), dot(m2, rgb)); /* into the LUT's input space */
  vec3 s = tf_display_shaper(x) * float(TF_DISPLAY_LUT_SIZE - 1);
  ivec3 i = min(ivec3(floor(s)), ivec3(TF_DISPLAY_LUT_SIZE - 2));
  vec3 f = s - vec3(i);
  vec3 c00 = mix(tf_display_at(i), tf_display_at(i + ivec3(1, 0, 0)), f.x);
  vec3 c01 = mix(tf_display_at(i + ivec3(0, 1, 0)), tf_display_at(i + ivec3(1, 1, 0)), f.x);
  vec3 c10 = mix(tf_display_at(i + ivec3(0, 0, 1)), tf_display_at(i + ivec3(1, 0, 1)), f.x);
  vec3 c11 = mix(tf_display_at(i + ivec3(0, 1, 1)), tf_display_at(i + ivec3(1, 1, 1)), f.x);
  return mix(mix(c00, c01, f.y), mix(c10, c11, f.y), f.z);
}
#endif
