#include "tf_common.glsl"

/* tf_refract.glsl: solid glass refracts the scene behind it (TF_REFRACT).
 *
 * numpy counterpart: shading.refract (exit_ray, march, seen). The scene drawn without the films is
 * the texture tf_behind (.rgb its colour, .a its depth: distance along the camera axis,
 * policy.REFRACT_FAR where empty; row 0 at the bottom) and tf_behind_view.screen maps the drawn
 * window's [0, 1] coordinates to its uv. tf_solid_exit_ray: the ray refracted in at the shaded
 * point, across the sphere about the object's origin through that point, and out;
 * tf_refract_march: that ray sampled at depths growing by TF_REFRACT_GROWTH from
 * TF_REFRACT_FIRST x the exit point's depth, the first crossing of the depth behind bisected
 * TF_REFRACT_REFINE times, accepted within TF_REFRACT_THICKNESS x its depth; false where the ray
 * leaves the picture or hits nothing (the caller reads the World along it).
 */

/* Exit point and direction of the ray from the viewer (v) entering glass of index eta at p with
 * normal n, the glass being the sphere about c through p (shading.refract.exit_ray). */
void tf_solid_exit_ray(vec3 p, vec3 n, vec3 v, vec3 c, float eta, out vec3 exit_point, out vec3 dir)
{
  float e = max(eta, TF_WALL_GUARD);
  vec3 inner = tf_safe_normalize(refract(-v, n, 1.0 / e), -v);
  float chord = max(-2.0 * dot(p - c, inner), 0.0);
  exit_point = p + chord * inner;
  vec3 n2 = tf_safe_normalize(exit_point - c, inner);
  vec3 out_dir = refract(inner, -n2, e);
  dir = (dot(out_dir, out_dir) < TF_TIR_EPS) ? inner : normalize(out_dir);
}

/* The texel of tf_behind under world point q, and q's depth; false off the picture or behind the
 * camera. */
bool tf_refract_sample(vec3 q, out ivec2 texel, out float depth_q)
{
  mat4 view_proj = mat4(tf_view.view_proj[0], tf_view.view_proj[1], tf_view.view_proj[2], tf_view.view_proj[3]);
  vec4 clip = view_proj * vec4(q, 1.0);
  depth_q = dot(tf_view.camera.xyz - q, tf_view.view_dir.xyz);
  if (clip.w <= 0.0 || depth_q <= 0.0) {
    return false;
  }
  vec2 uv = (clip.xy / clip.w * 0.5 + 0.5) * tf_behind_view.screen.xy + tf_behind_view.screen.zw;
  vec2 size = tf_behind_view.size.xy;
  vec2 cell = floor(uv * size);
  texel = ivec2(clamp(cell, vec2(0.0), size - 1.0));
  return all(greaterThanEqual(cell, vec2(0.0))) && all(lessThan(cell, size));
}

/* Whether the ray o + s w passes behind the scene at s (its texel, false off the picture). */
bool tf_refract_behind(vec3 o, vec3 w, float s, out ivec2 texel, out float gap, out bool inside)
{
  float depth_q;
  inside = tf_refract_sample(o + s * w, texel, depth_q);
  float depth_behind = texelFetch(tf_behind, texel, 0).a;
  gap = (depth_q - depth_behind) / max(depth_q, TF_WALL_GUARD);
  return depth_q >= depth_behind;
}

/* Where the exit ray o + s w first hits the scene behind (shading.refract.march): true and its
 * colour, or false. */
bool tf_refract_march(vec3 o, vec3 w, out vec3 colour)
{
  float scale = max(dot(tf_view.camera.xyz - o, tf_view.view_dir.xyz), TF_WALL_GUARD);
  float prev_s = 0.0;
  bool prev_behind = false;
  colour = vec3(0.0);
  for (int k = 0; k < TF_REFRACT_STEPS; k++) {
    float s = scale * (TF_REFRACT_FIRST * pow(TF_REFRACT_GROWTH, float(k)));
    ivec2 texel;
    float gap;
    bool inside;
    bool behind = tf_refract_behind(o, w, s, texel, gap, inside);
    if (!inside) {
      return false;
    }
    if (behind && !prev_behind) {
      float lo = prev_s, hi = s;
      for (int j = 0; j < TF_REFRACT_REFINE; j++) {
        float mid = 0.5 * (lo + hi);
        ivec2 t_mid;
        float g_mid;
        bool in_mid;
        if (tf_refract_behind(o, w, mid, t_mid, g_mid, in_mid)) {
          hi = mid;
        }
        else {
          lo = mid;
        }
      }
      tf_refract_behind(o, w, hi, texel, gap, inside);
      if (gap <= TF_REFRACT_THICKNESS) {
        colour = texelFetch(tf_behind, texel, 0).rgb;
        return true;
      }
    }
    prev_behind = behind;
    prev_s = s;
  }
  return false;
}
