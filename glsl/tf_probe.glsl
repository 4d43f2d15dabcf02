#include "tf_refract.glsl"

/* tf_probe.glsl: the scene around solid glass, for the paths that leave the picture (TF_REFRACT;
 * numpy counterpart: shading.glass.probe). The texture tf_probe is the scene seen from one point
 * (tf_behind_view.probe.xyz; .w 1 where a probe was rendered): an equirect panorama (row 0 at the
 * top, docs/conventions.md's mapping) of colour and, in .a, the distance from that point (0: the
 * World). A path leaving at o along d is marched through it: TF_PROBE_STEPS samples at distances
 * growing by TF_PROBE_GROWTH from TF_PROBE_FIRST x (|o - c| + the probe's distance along d), the
 * first beyond the probe's surface (farther from its point than the distance its direction holds)
 * bisected TF_PROBE_REFINE times. Where the point it met lies in the picture tf_behind holds, the
 * march has read it there: the World stands. */

/* The probe's texel (column, row) holding direction u (u wraps, rows clamp), and the fractional
 * position there: .xy the texel, .zw the position in texels (shading.glass.probe._distance). */
vec4 tf_probe_texel(vec3 u)
{
  ivec2 size = textureSize(tf_probe, 0);
  float x = (0.5 - atan(u.y, u.x) / (2.0 * TF_PI)) * float(size.x);
  float y = acos(clamp(u.z, -1.0, 1.0)) / TF_PI * float(size.y);
  int col = int(floor(x)) % size.x; /* x lies in [0, width]: % on non-negative ints only */
  int row = clamp(int(floor(y)), 0, size.y - 1);
  return vec4(float(col), float(row), x, y);
}

/* The probe's distance along u (its nearest texel; 0: the World). */
float tf_probe_distance(vec3 u)
{
  return texelFetch(tf_probe, ivec2(tf_probe_texel(u).xy), 0).a;
}

/* The probe's colour along u, bilinear between texel centres (hdri.equirect_lookup). */
vec3 tf_probe_colour(vec3 u)
{
  ivec2 size = textureSize(tf_probe, 0);
  vec4 at = tf_probe_texel(u);
  float x = at.z - 0.5;
  float y = at.w - 0.5;
  float x0 = floor(x);
  int y0 = clamp(int(floor(y)), 0, size.y - 1);
  float fx = x - x0;
  float fy = clamp(y - float(y0), 0.0, 1.0);
  int y1 = min(y0 + 1, size.y - 1);
  int c0 = (int(x0) + size.x) % size.x; /* x0 >= -1: both operands of % stay non-negative */
  int c1 = (c0 + 1) % size.x;
  vec3 top = mix(texelFetch(tf_probe, ivec2(c0, y0), 0).rgb, texelFetch(tf_probe, ivec2(c1, y0), 0).rgb, fx);
  vec3 bottom = mix(texelFetch(tf_probe, ivec2(c0, y1), 0).rgb, texelFetch(tf_probe, ivec2(c1, y1), 0).rgb, fx);
  return mix(top, bottom, fy);
}

/* Whether point q lies beyond the probe's surface in its direction from the probe's point (never
 * where that direction holds the World; shading.glass.probe._behind). */
bool tf_probe_behind(vec3 q)
{
  vec3 v = q - tf_behind_view.probe.xyz;
  float r = length(v);
  if (!(r > 0.0)) {
    return false;
  }
  float dist = tf_probe_distance(v / r);
  return dist > 0.0 && r > dist;
}

/* What the path leaving at o along unit d sees in the probe (shading.glass.probe.lookup): false
 * where there is no probe, the path passes behind none of its surface or the point met is in the
 * picture (the caller reads the World). */
bool tf_probe_seen(vec3 o, vec3 d, out vec3 colour)
{
  colour = vec3(0.0);
  if (tf_behind_view.probe.w < 0.5) {
    return false;
  }
  vec3 c = tf_behind_view.probe.xyz;
  float scale = length(o - c) + tf_probe_distance(d);
  float lo = 0.0;
  float hi = 0.0;
  bool found = false;
  float previous = 0.0;
  float reach = scale * TF_PROBE_FIRST; /* not "step": the built-in function's name */
  for (int k = 0; k < TF_PROBE_STEPS; k++) {
    if (tf_probe_behind(o + reach * d)) {
      lo = previous;
      hi = reach;
      found = true;
      break;
    }
    previous = reach;
    reach *= TF_PROBE_GROWTH;
  }
  if (!found) {
    return false;
  }
  for (int i = 0; i < TF_PROBE_REFINE; i++) {
    float mid = 0.5 * (lo + hi);
    if (tf_probe_behind(o + mid * d)) {
      hi = mid;
    }
    else {
      lo = mid;
    }
  }
  vec3 v = o + hi * d - c;
  float r = length(v);
  vec3 u = (r > 0.0) ? v / r : d;
  float dist = tf_probe_distance(u);
  ivec2 unused_texel;
  float unused_depth;
  if (!(dist > 0.0) || tf_refract_sample(c + dist * u, unused_texel, unused_depth)) {
    return false;
  }
  colour = tf_probe_colour(u);
  return true;
}
