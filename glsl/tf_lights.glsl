#include "tf_common.glsl"
#include "tf_brdf.glsl"
#include "tf_frame.glsl"
#include "tf_lamps.glsl"

/* tf_lights.glsl: Blender's light objects (sun, point, spot, area), sampled over their extent.
 *
 * numpy counterpart: shading.lights.shade (samples: lights.light_samples, weight:
 * lights.sample_weight). Lights in the uniform buffer tf_lights (layout: addon/gpu/resources.py
 * LIGHTS, packing: lights.Lights.pack; TF_LIGHT_VEC4 = 5 vec4s a light): [5k] position, kind;
 * [5k+1] direction (-Z), radius;
 * [5k+2] energy (sun E, point/spot I, area L), cos_half_spot | tan_half_spread;
 * [5k+3] axis_u, spot_smooth | normalize_spread; [5k+4] axis_v, ellipse.
 * Film reflectance from tf_film_response (tf_lamps.glsl). Each sample: D_alpha' G2 F(v.h) /
 * (4 cos_o) x E_perp (tf_ggx_weight, tf_brdf.glsl), alpha'^2 = alpha^2 + rho^2 (the sample's
 * footprint, lights.footprint); under a film with a diffuse base also E_perp cos_i (times
 * 1 - R(cos_i) for a spectral film, lights.diffuse_in) into the base, whose BRDF at the view is
 * tf_film_diffuse.
 * No shadows from other objects.
 */

/* TF_LIGHT_SUN / _POINT / _SPOT / _AREA, TF_MIN_LIGHT_DISTANCE, TF_AREA_MIN_AXIS,
 * TF_AREA_MAX_WIDTH and TF_AREA_UNIFORM_WIDTH: policy.LIGHT_KINDS, policy.MIN_LIGHT_DISTANCE,
 * policy.AREA_MIN_AXIS, policy.AREA_MAX_WIDTH and policy.AREA_UNIFORM_WIDTH. */

/* lights.spot_attenuation: smoothstep of (cos - cos_half) * smooth. */
float tf_spot_attenuation(float cos_axis, float cos_half, float smooth_inv)
{
  float x = clamp((cos_axis - cos_half) * smooth_inv, 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}

/* lights.spread_attenuation (tan_half_spread < 0: a full spread). */
float tf_spread_attenuation(float cos_l, float tan_half, float norm)
{
  if (tan_half < 0.0) {
    return 1.0;
  }
  float c = clamp(cos_l, TF_MIN_COS, 1.0);
  float tan_a = sqrt(max(1.0 - c * c, 0.0)) / c;
  return max((tan_half - tan_a) * norm, 0.0);
}

/* lights.area_grid: cell centre (i, j) of S x S in [-1/2, 1/2]^2, or on the disc (concentric). */
vec2 tf_area_cell(int i, int j, bool ellipse)
{
  float a = (float(i) + 0.5) / float(TF_AREA_SAMPLES) * 2.0 - 1.0;
  float b = (float(j) + 0.5) / float(TF_AREA_SAMPLES) * 2.0 - 1.0;
  if (!ellipse) {
    return 0.5 * vec2(a, b);
  }
  float r, phi;
  if (abs(a) > abs(b)) {
    r = a;
    phi = (TF_PI / 4.0) * b / a;
  }
  else {
    r = b;
    phi = TF_HALF_PI - (TF_PI / 4.0) * a / b;
  }
  return 0.5 * r * vec2(cos(phi), sin(phi));
}

/* One sample: lights.sample_weight times the film at its half vector times e; with a diffuse
 * base (base) what it brings the base is added to diffuse (lights.diffuse_in). */
vec3 tf_light_sample(TFLerp r, vec3 n, vec3 v, vec3 l, vec3 e, float rho2, TFGgxView g, bool base,
                     inout vec3 diffuse)
{
  float cos_i = dot(n, l);
  if (cos_i <= 0.0) {
    return vec3(0.0);
  }
  if (base) {
#ifdef TF_SPECTRAL
    diffuse += cos_i * e * clamp(vec3(1.0) - tf_film_response(min(cos_i, 1.0), r, vec3(1.0)), 0.0, 1.0);
#else
    diffuse += cos_i * e;
#endif
  }
  vec3 h = tf_safe_normalize(v + l, n);
  float nh = clamp(dot(n, h), 0.0, 1.0);
  float weight = tf_ggx_weight(nh, g.a2 + rho2, cos_i, g);
  float u = clamp(dot(v, h), 0.0, 1.0);
  return weight * tf_film_response(u, r, e);
}

/* lights.lobe_cells: S + 1 cell edges along one axis, equal shares of a Cauchy (c, w) on [-1/2, 1/2]. */
void tf_lobe_edges(float c, float w, out float edges[TF_AREA_SAMPLES + 1])
{
  c = clamp(c, -TF_AREA_MAX_WIDTH, TF_AREA_MAX_WIDTH);
  w = clamp(w, TF_AREA_MIN_WIDTH, TF_AREA_MAX_WIDTH);
  float lo = atan((-0.5 - c) / w);
  float hi = atan((0.5 - c) / w);
  edges[0] = -0.5;
  for (int i = 1; i < TF_AREA_SAMPLES; i++) {
    edges[i] = clamp(c + w * tan(lo + (hi - lo) * float(i) / float(TF_AREA_SAMPLES)), -0.5, 0.5);
  }
  edges[TF_AREA_SAMPLES] = 0.5;
}

/* One area light: lights._area_samples with lights.area_lobe (rectangles) or the concentric grid. */
vec3 tf_area_light(int k, TFLerp r, vec3 p, vec3 n, vec3 v, TFGgxView g, bool base, inout vec3 diffuse)
{
  vec4 s0 = tf_lights.light[TF_LIGHT_VEC4 * k];
  vec4 s1 = tf_lights.light[TF_LIGHT_VEC4 * k + 1];
  vec4 s2 = tf_lights.light[TF_LIGHT_VEC4 * k + 2];
  vec4 s3 = tf_lights.light[TF_LIGHT_VEC4 * k + 3];
  vec4 s4 = tf_lights.light[TF_LIGHT_VEC4 * k + 4];
  vec3 axis = s1.xyz;
  bool ellipse = s4.w > 0.5;
  float len_u = max(length(s3.xyz), TF_AREA_MIN_AXIS);
  float len_v = max(length(s4.xyz), TF_AREA_MIN_AXIS);
  float size = length(s3.xyz) * length(s4.xyz);
  /* lights.area_lobe: the mirror ray meets the light's plane */
  vec3 refl = 2.0 * dot(n, v) * n - v;
  float facing = -dot(refl, axis);
  float safe = max(facing, TF_MIN_COS);
  float t = max(dot(p - s0.xyz, axis), 0.0) / safe;
  vec3 hit = p + t * refl - s0.xyz;
  bool meets = facing > TF_MIN_COS;
  float cu = meets ? dot(hit, s3.xyz) / (len_u * len_u) : 0.0;
  float cv = meets ? dot(hit, s4.xyz) / (len_v * len_v) : 0.0;
  float wu = meets ? TF_AREA_LOBE_SCALE * g.alpha * t / (safe * len_u) : TF_AREA_UNIFORM_WIDTH;
  float wv = meets ? TF_AREA_LOBE_SCALE * g.alpha * t / (safe * len_v) : TF_AREA_UNIFORM_WIDTH;
  float eu[TF_AREA_SAMPLES + 1];
  float ev[TF_AREA_SAMPLES + 1];
  tf_lobe_edges(cu, wu, eu);
  tf_lobe_edges(cv, wv, ev);
  vec3 sum = vec3(0.0);
  for (int i = 0; i < TF_AREA_SAMPLES; i++) {
    for (int j = 0; j < TF_AREA_SAMPLES; j++) {
      vec2 c;
      float cell;
      if (ellipse) {
        c = tf_area_cell(i, j, true);
        cell = size * (TF_PI / 4.0) / float(TF_AREA_SAMPLES * TF_AREA_SAMPLES);
      }
      else {
        c = vec2(0.5 * (eu[i] + eu[i + 1]), 0.5 * (ev[j] + ev[j + 1]));
        cell = (eu[i + 1] - eu[i]) * (ev[j + 1] - ev[j]) * size;
      }
      vec3 to = s0.xyz + c.x * s3.xyz + c.y * s4.xyz - p;
      float d2 = max(dot(to, to), TF_MIN_LIGHT_DISTANCE * TF_MIN_LIGHT_DISTANCE);
      vec3 l = to * inversesqrt(d2);
      float cos_l = -dot(l, axis);
      if (cos_l <= 0.0) {
        continue;
      }
      float omega = cell * cos_l / d2;
      float scale = omega * tf_spread_attenuation(cos_l, s2.w, s3.w);
      sum += tf_light_sample(r, n, v, l, scale * s2.rgb, 0.25 * omega, g, base, diffuse);
    }
  }
  return sum;
}

vec3 tf_shade_lights(TFFrame f, TFLerp r, vec3 p, vec3 n, vec3 v, float roughness)
{
  int count = int(tf_lights.count.x);
  TFGgxView g = tf_ggx_view(roughness, f.cos_o);
  vec3 sum = vec3(0.0);
  bool base = tf_film_has_diffuse();
  vec3 diffuse = vec3(0.0);
  for (int k = 0; k < TF_MAX_LIGHTS; k++) {
    if (k >= count) {
      break;
    }
    vec4 s0 = tf_lights.light[TF_LIGHT_VEC4 * k];
    vec4 s1 = tf_lights.light[TF_LIGHT_VEC4 * k + 1];
    vec4 s2 = tf_lights.light[TF_LIGHT_VEC4 * k + 2];
    int kind = int(s0.w + 0.5);
    vec3 axis = s1.xyz;
    if (kind == TF_LIGHT_SUN) {
      float s = sin(s1.w);
      sum += tf_light_sample(r, n, v, -axis, s2.rgb, 0.25 * s * s, g, base, diffuse);
    }
    else if (kind == TF_LIGHT_POINT || kind == TF_LIGHT_SPOT) {
      vec3 to = s0.xyz - p;
      float radius = s1.w;
      float d2 = max(dot(to, to), max(radius * radius, TF_MIN_LIGHT_DISTANCE * TF_MIN_LIGHT_DISTANCE));
      vec3 l = to * inversesqrt(d2);
      float scale = 1.0 / d2;
      if (kind == TF_LIGHT_SPOT) {
        scale *= tf_spot_attenuation(-dot(l, axis), s2.w, tf_lights.light[TF_LIGHT_VEC4 * k + 3].w);
      }
      sum += tf_light_sample(r, n, v, l, scale * s2.rgb, 0.25 * radius * radius / d2, g, base, diffuse);
    }
    else if (kind == TF_LIGHT_AREA) {
      sum += tf_area_light(k, r, p, n, v, g, base, diffuse);
    }
  }
  sum *= tf_film_multiscatter(g.cos_o, r);
  return base ? sum + diffuse * tf_film_diffuse(g.cos_o, r) : sum;
}
