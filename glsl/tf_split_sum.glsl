#include "tf_shade.glsl"

/* tf_split_sum.glsl: glossy films by the split sum, blended with SH by roughness.
 *
 * numpy counterpart: shading.split_sum.shade_split_sum and shading.split_sum.shade_combined,
 * with the prefiltered levels resampled to one size (prefilter.Prefiltered.resampled).
 * Texture `tf_prefiltered` (addon/gpu/resources.py PrefilterTexture), depth 2 J: slice j < J =
 * the World prefiltered by a GGX lobe of roughness TF_LADDER_ROUGHNESS(j / (J - 1)), equirect
 * (conventions.md mapping); slice J + j = its moment (Prefiltered.moments). The blend of two
 * levels is the linear filter in z: one fetch each.
 * With TF_LAMPS, tf_lamps.glsl is joined before this chunk (addon/gpu/shaders.py).
 * Split sum (Karis 2013): film albedo (the l = 0 table entry x sqrt(4 pi), a 3x3 matrix or 3
 * factors) times the prefiltered radiance in the reflection direction; with TF_MOMENT the albedo
 * is read at the half-vector angle of the lobe's light-weighted mean direction
 * (shading.split_sum.dominant_cosine), without it at the view angle (policy.uses_moment:
 * split-only films and l_max >= policy.MOMENT_MIN_L; the moment is a second fetch).
 */

const float TF_SQRT_4PI = 3.5449077018110318;

vec3 tf_prefiltered_lookup(vec3 d_world, float roughness, out vec3 moment, out float lamp_weight)
{
  /* the World's turn and strength (tf_lighting.world; shading.split_sum._blend): the levels hold
   * the image as read, looked up at Q d and scaled; a moment m turns back by Q^T */
  vec3 q0 = tf_lighting.world[0].xyz;
  vec3 q1 = tf_lighting.world[1].xyz;
  vec3 q2 = tf_lighting.world[2].xyz;
  float strength = tf_lighting.world[0].w;
  vec3 d = vec3(dot(q0, d_world), dot(q1, d_world), dot(q2, d_world));
  int depth = textureSize(tf_prefiltered, 0).z;
  int levels = depth / 2;
  float u = 0.5 - atan(d.y, d.x) / (2.0 * TF_PI);
  float t = acos(clamp(d.z, -1.0, 1.0)) / TF_PI;
  /* shading.split_sum.level_blend: level k holds roughness TF_LADDER_ROUGHNESS(k / (J - 1)); the
   * two levels around r are weighted so that the blend's alpha^2 = r^4 is the material's (GGX
   * tails scale as alpha^2). */
  float r = clamp(roughness, 0.0, 1.0);
  float steps = float(levels - 1);
  int lo = min(int(floor(TF_LADDER_POSITION(r) * steps)), levels - 2);
  float x0 = float(lo) / steps;
  float x1 = float(lo + 1) / steps;
  float r0 = TF_LADDER_ROUGHNESS(x0);
  float r1 = TF_LADDER_ROUGHNESS(x1);
  float a4 = r0 * r0 * r0 * r0;
  float b4 = r1 * r1 * r1 * r1;
  float w = clamp((r * r * r * r - a4) / max(b4 - a4, TF_DIVISION_FLOOR), 0.0, 1.0);
  /* slice centres at (k + 0.5) / depth: z between slices lo and lo + 1 with weight w */
  float z = (float(lo) + w + 0.5) / float(depth);
  /* shading.lamps.lamp_weight: levels from TF_LAMP_LEVEL on hold the World without its lamps, which
   * tf_shade_lamps adds with this weight (0 where the texture keeps them) */
#ifdef TF_LAMPS
  lamp_weight = (1.0 - w) * float(lo >= TF_LAMP_LEVEL) + w * float(lo + 1 >= TF_LAMP_LEVEL);
#else
  lamp_weight = 0.0;
#endif
#ifdef TF_MOMENT
  vec3 m = texture(tf_prefiltered, vec3(u, t, z + 0.5)).rgb; /* + J slices */
  moment = strength * (m.x * q0 + m.y * q1 + m.z * q2);
#else
  moment = vec3(0.0); /* not read: policy.uses_moment */
#endif
  return strength * texture(tf_prefiltered, vec3(u, t, z)).rgb;
}

vec3 tf_shade_split_sum_at(TFFrame f, TFLerp r, vec3 n, vec3 v, float roughness, out float lamp_weight)
{
  vec3 refl = 2.0 * f.cos_o * n - v;
  /* policy.effective_roughness: r * cos(theta_o)^GRAZING_EXPONENT */
  float r_eff = clamp(roughness, 0.0, 1.0) * TF_GRAZING(clamp(f.cos_o, TF_MIN_COS, 1.0));
  vec3 moment;
  vec3 radiance = tf_prefiltered_lookup(refl, r_eff, moment, lamp_weight);
  /* shading.split_sum.dominant_cosine: cos theta' = sqrt((1 + v.c) / 2), c = the moment's direction;
   * a vanishing moment (black World in the lobe) keeps the view angle. (acos(v.c) / 2 is the
   * same angle, but llvmpipe's acos is off by 1.6e-4 of the peak in the per-pixel test.) */
#ifdef TF_MOMENT
  float m2 = dot(moment, moment);
  if (m2 > TF_MOMENT_EPS) {
    float c2 = clamp(0.5 * (1.0 + dot(v, moment) * inversesqrt(m2)), 0.0, 1.0);
    r = tf_table_at_theta(r, atan(sqrt(1.0 - c2), sqrt(c2)));
  }
#endif
#ifdef TF_SPECTRAL
  vec3 rgb = vec3(dot(tf_table_fetch(r, 0), radiance), dot(tf_table_fetch(r, 1), radiance),
                  dot(tf_table_fetch(r, 2), radiance));
#else
  vec3 rgb = tf_table_fetch(r, 0) * radiance;
#endif
  return max(rgb * TF_SQRT_4PI, vec3(0.0));
}

/* sh_weight = policy.sh_weight(roughness): 0 → split sum only; the TF_SPLIT_ONLY variant
 * (variant.choose_variant picks it for sh_weight 0) compiles the SH half out.
 * The frame and the table position are computed once for both halves. */
vec3 tf_shade_combined(vec3 n, vec3 v, float thickness01, float roughness, float sh_weight)
{
  TFFrame f = tf_view_aligned_frame(n, v);
  TFLerp r = tf_table_lerp(f.cos_o, f.sin_o, thickness01);
  vec3 rgb = vec3(0.0);
  float lamp_weight = 0.0;
  if (sh_weight < 1.0) {
    rgb += (1.0 - sh_weight) * tf_shade_split_sum_at(f, r, n, v, roughness, lamp_weight);
  }
#ifndef TF_SPLIT_ONLY
  if (sh_weight > 0.0) {
    rgb += sh_weight * tf_shade_at(f, r);
  }
#endif
#ifdef TF_LAMPS
  /* shading.split_sum.shade_combined: the SH half sees the World without its lamps; the split sum
   * keeps them in its sharpest levels */
  rgb += (sh_weight + (1.0 - sh_weight) * lamp_weight) * tf_shade_lamps(f, r, n, v, roughness);
#endif
  return rgb;
}
