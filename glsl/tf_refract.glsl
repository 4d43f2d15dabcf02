#include "tf_common.glsl"
#include "tf_transmit.glsl"

/* tf_refract.glsl: solid glass refracts the scene behind it (TF_REFRACT).
 *
 * numpy counterpart: shading.glass.refract (exit_ray, march, seen). The scene drawn without the films is
 * the texture tf_behind (.rgb its colour, .a its depth: distance along the camera axis,
 * policy.REFRACT_FAR where empty; row 0 at the bottom) and tf_behind_view.screen maps the drawn
 * window's [0, 1] coordinates to its uv. tf_solid_exit_ray: the ray refracted in at the shaded
 * point, across the sphere about the object's origin through that point, and out;
 * tf_refract_march: that ray sampled at depths growing by TF_REFRACT_GROWTH from
 * TF_REFRACT_FIRST x the exit point's depth (nearest texels), the first crossing of the depth behind
 * bisected TF_REFRACT_REFINE times against the depth between texel centres (tf_behind_depth_at),
 * accepted within TF_REFRACT_THICKNESS x its depth, its colour bilinear there; a ray that leaves
 * the picture takes the texel of its last sample inside (TF_REFRACT_EDGE), unless a scene probe
 * was rendered (tf_behind_view.probe.w): that knows where the scene beyond the edge ends; false
 * where it hits nothing (the caller reads the probe or the World along it). The exit through the
 * real mesh (the glass buffers) is tf_glass_exit.glsl's.
 */

/* Exit point and direction of the ray from the viewer (v) entering glass of index eta at p with
 * normal n, the glass being the sphere about c through p (shading.glass.refract.exit_ray). */
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

/* uv of world point q in tf_behind and q's depth; false behind the camera. */
bool tf_refract_uv(vec3 q, out vec2 uv, out float depth_q)
{
  mat4 view_proj = mat4(tf_view.view_proj[0], tf_view.view_proj[1], tf_view.view_proj[2], tf_view.view_proj[3]);
  vec4 clip = view_proj * vec4(q, 1.0);
  depth_q = dot(tf_view.camera.xyz - q, tf_view.view_dir.xyz);
  uv = (clip.xy / max(abs(clip.w), TF_DIVISION_FLOOR) * sign(clip.w) * 0.5 + 0.5) * tf_behind_view.screen.xy +
       tf_behind_view.screen.zw;
  return clip.w > 0.0 && depth_q > 0.0;
}

/* The texel of tf_behind under world point q, and q's depth; false off the picture or behind the
 * camera. */
bool tf_refract_sample(vec3 q, out ivec2 texel, out float depth_q)
{
  vec2 uv;
  bool ahead = tf_refract_uv(q, uv, depth_q);
  vec2 size = tf_behind_view.size.xy;
  vec2 cell = floor(uv * size);
  texel = ivec2(clamp(cell, vec2(0.0), size - 1.0));
  return ahead && all(greaterThanEqual(cell, vec2(0.0))) && all(lessThan(cell, size));
}

/* The four texels of tf_behind around uv (edge texels held beyond the picture) and the weights
 * between them (shading.glass.refract.bilinear). */
void tf_behind_corners(vec2 uv, out ivec2 lo, out ivec2 hi, out vec2 f)
{
  vec2 size = tf_behind_view.size.xy;
  vec2 p = uv * size - 0.5;
  vec2 base = floor(p);
  f = p - base;
  lo = ivec2(clamp(base, vec2(0.0), size - 1.0));
  hi = ivec2(clamp(base + 1.0, vec2(0.0), size - 1.0));
}

/* The depth behind at uv (shading.glass.refract._Scene.surface): where the four texels around it hold one
 * surface (depths within 1 + TF_REFRACT_THICKNESS of each other), between their centres, bilinear
 * in 1 / depth (exact for a plane); else the nearest texel's, uv moved to its centre (its colour
 * then read unmixed across the edge). */
float tf_behind_depth_at(inout vec2 uv)
{
  ivec2 lo, hi;
  vec2 f;
  tf_behind_corners(uv, lo, hi, f);
  vec4 d = vec4(texelFetch(tf_behind, lo, 0).a, texelFetch(tf_behind, ivec2(hi.x, lo.y), 0).a,
                texelFetch(tf_behind, ivec2(lo.x, hi.y), 0).a, texelFetch(tf_behind, hi, 0).a);
  float d_min = min(min(d.x, d.y), min(d.z, d.w));
  float d_max = max(max(d.x, d.y), max(d.z, d.w));
  if (d_max > (1.0 + TF_REFRACT_THICKNESS) * d_min) {
    vec2 size = tf_behind_view.size.xy;
    vec2 cell = clamp(floor(uv * size), vec2(0.0), size - 1.0);
    uv = (cell + 0.5) / size;
    return texelFetch(tf_behind, ivec2(cell), 0).a;
  }
  if (d_min >= TF_REFRACT_FAR) {
    return TF_REFRACT_FAR;
  }
  vec4 inv = vec4(1.0) / max(d, vec4(TF_DIVISION_FLOOR));
  return 1.0 / mix(mix(inv.x, inv.y, f.x), mix(inv.z, inv.w, f.x), f.y);
}

/* The colour behind at uv, bilinear between texel centres (shading.glass.refract.bilinear). */
vec3 tf_behind_bilinear(vec2 uv)
{
  ivec2 lo, hi;
  vec2 f;
  tf_behind_corners(uv, lo, hi, f);
  return mix(mix(texelFetch(tf_behind, lo, 0).rgb, texelFetch(tf_behind, ivec2(hi.x, lo.y), 0).rgb, f.x),
             mix(texelFetch(tf_behind, ivec2(lo.x, hi.y), 0).rgb, texelFetch(tf_behind, hi, 0).rgb, f.x), f.y);
}

/* Catmull-Rom's four weights at fraction t between the middle two samples. */
vec4 tf_catmull_rom(float t)
{
  float t2 = t * t, t3 = t2 * t;
  return vec4(-0.5 * t3 + t2 - 0.5 * t, 1.5 * t3 - 2.5 * t2 + 1.0, -1.5 * t3 + 2.0 * t2 + 0.5 * t, 0.5 * t3 - 0.5 * t2);
}

/* The colour behind at uv (shading.glass.refract.sharp): Catmull-Rom between the 4 x 4 texel
 * centres around it, held within the range of the four nearest, where the sixteen lie on one
 * surface (depths within 1 + TF_REFRACT_THICKNESS of each other) inside the picture; else
 * bilinear (tf_behind_bilinear). */
vec3 tf_behind_colour_at(vec2 uv)
{
  vec2 size = tf_behind_view.size.xy;
  vec2 p = uv * size - 0.5;
  vec2 base = floor(p);
  vec2 f = p - base;
  if (any(lessThan(base, vec2(1.0))) || any(greaterThan(base, size - 3.0))) {
    return tf_behind_bilinear(uv);
  }
  ivec2 b = ivec2(base) - 1;
  float d_min = 1e30, d_max = 0.0;
  vec3 lo = vec3(1e30), hi = vec3(-1e30);
  vec4 wx = tf_catmull_rom(f.x), wy = tf_catmull_rom(f.y);
  vec3 sum = vec3(0.0);
  for (int j = 0; j < 4; j++) {
    for (int i = 0; i < 4; i++) {
      vec4 t = texelFetch(tf_behind, b + ivec2(i, j), 0);
      d_min = min(d_min, t.a);
      d_max = max(d_max, t.a);
      sum += wx[i] * wy[j] * t.rgb;
      if ((i == 1 || i == 2) && (j == 1 || j == 2)) { /* the four nearest */
        lo = min(lo, t.rgb);
        hi = max(hi, t.rgb);
      }
    }
  }
  if (d_max > (1.0 + TF_REFRACT_THICKNESS) * d_min) {
    return tf_behind_bilinear(uv);
  }
  return clamp(sum, lo, hi);
}

/* Whether the ray o + s w passes behind the scene at s against the depth between texel centres
 * (tf_behind_depth_at): its uv and how far behind, relative to its depth. */
bool tf_refract_surface(vec3 o, vec3 w, float s, out vec2 uv, out float gap)
{
  float depth_q;
  tf_refract_uv(o + s * w, uv, depth_q);
  float depth_behind = tf_behind_depth_at(uv);
  gap = (depth_q - depth_behind) / max(depth_q, TF_WALL_GUARD);
  return gap >= 0.0;
}

/* Whether the ray o + s w passes behind the scene at s (its texel and that texel's depth, false
 * off the picture). */
bool tf_refract_behind(vec3 o, vec3 w, float s, out ivec2 texel, out float gap, out bool inside,
                       out float depth_behind)
{
  float depth_q;
  inside = tf_refract_sample(o + s * w, texel, depth_q);
  depth_behind = texelFetch(tf_behind, texel, 0).a;
  gap = (depth_q - depth_behind) / max(depth_q, TF_WALL_GUARD);
  return depth_q >= depth_behind;
}

/* Whether the ray o + t w meets the line through the surface points a and b beyond t = s
 * (shading.glass.refract._meets_ahead): a and b lie under two of its samples, in the plane through the
 * camera and the ray; true where they are unknown (known false) or too close together. */
bool tf_refract_meets_ahead(vec3 o, vec3 w, float s, vec3 a, vec3 b, bool known)
{
  vec3 e = b - a;
  vec3 m = cross(w, e);
  float mm = dot(m, m);
  float ee = dot(e, e);
  if (!known || !(ee > TF_REFRACT_LINE_EPS * max(dot(a, a), 1.0))) {
    return true;
  }
  return mm > TF_REFRACT_LINE_EPS * ee && -dot(cross(o - a, e), m) > s * mm;
}

/* Where the exit ray o + s w first hits the scene behind (shading.glass.refract.march): true and its
 * colour, or false. */
bool tf_refract_march(vec3 o, vec3 w, out vec3 colour)
{
  float scale = max(dot(tf_view.camera.xyz - o, tf_view.view_dir.xyz), TF_WALL_GUARD);
  float prev_s = 0.0;
  bool prev_behind = false;
  colour = vec3(0.0);
  ivec2 last = ivec2(0);
  /* the surface points under the last two samples inside (known: both surfaces), the last's s */
  vec3 last_pt = vec3(0.0), prev_pt = vec3(0.0);
  bool last_known = false, prev_known = false;
  float last_s = 0.0;
  for (int k = 0; k < TF_REFRACT_STEPS; k++) {
    float s = scale * (TF_REFRACT_FIRST * pow(TF_REFRACT_GROWTH, float(k)));
    ivec2 texel;
    float gap;
    bool inside;
    float depth_behind;
    bool behind = tf_refract_behind(o, w, s, texel, gap, inside, depth_behind);
    if (!inside) {
#if TF_REFRACT_EDGE
      vec4 edge = texelFetch(tf_behind, last, 0);
      /* left the picture: the surface at its edge (policy.REFRACT_EDGE), if the ray heads into it
       * and no scene probe shows what lies beyond (a floor that ends) */
      if (k > 0 && edge.a < TF_REFRACT_FAR && tf_behind_view.probe.w < 0.5 &&
          (prev_behind || tf_refract_meets_ahead(o, w, last_s, prev_pt, last_pt, last_known && prev_known)))
      {
        colour = edge.rgb;
        return true;
      }
#endif
      return false;
    }
    last = texel;
    prev_pt = last_pt;
    prev_known = last_known;
    /* the surface's depth is (1 - gap) x q's: the surface point on q's camera ray */
    last_pt = tf_view.camera.xyz + (o + s * w - tf_view.camera.xyz) * (1.0 - gap);
    last_known = depth_behind < TF_REFRACT_FAR;
    last_s = s;
    if (behind && !prev_behind) {
      float lo = prev_s, hi = s;
      vec2 uv;
      for (int j = 0; j < TF_REFRACT_REFINE; j++) {
        float mid = 0.5 * (lo + hi);
        float g_mid;
        if (tf_refract_surface(o, w, mid, uv, g_mid)) {
          hi = mid;
        }
        else {
          lo = mid;
        }
      }
      tf_refract_surface(o, w, hi, uv, gap);
      if (gap <= TF_REFRACT_THICKNESS) {
        colour = tf_behind_colour_at(uv);
        return true;
      }
    }
    prev_behind = behind;
    prev_s = s;
  }
  return false;
}
