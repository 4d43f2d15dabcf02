#include "tf_glass_exit.glsl"

/* tf_glass_tails.glsl: the World's lamps in the tails of rough solid glass's paths (TF_REFRACT;
 * numpy counterpart: shading.glass.tails). Solid glass's paths are followed as smooth glass
 * (tf_glass_exit.glsl); a rough face turns each by its gain times its facet's tilt, and GGX's
 * tails (alpha^2 / psi^4) show a bright lamp a few pixels around every glint on a ball's rim.
 * tf_main_frag.glsl's tf_refract_seen adds them where the refracted ray or a glint sees the
 * World. Lamps: tf_lighting.lamps (TF_LAMPS; without it, none). */

/* How far a rough glass path spreads the directions it leaves in (shading.glass.tails.path_spread):
 * (in its plane of incidence, across it), in units of alpha^2, for a path that enters at cos_o
 * outside (refracted by Snell's law), reflects at reflections faces inside and leaves at cos_exit
 * inside (TF_GLASS_TAIL_MAX_GAIN bounds the exit's gain at the critical angle). Each rough face
 * turns the path by its gain times its facet's tilt; a later refraction magnifies what came
 * before; the gains' squares add. */
vec2 tf_glass_spread(float cos_o, float cos_exit, float eta, int reflections)
{
  float e = max(eta, TF_WALL_GUARD);
  float co = clamp(cos_o, 0.0, 1.0);
  float ci = max(tf_inner_cosine(co, e), TF_MIN_COS);
  float cx = clamp(cos_exit, 0.0, 1.0);
  float ct = sqrt(max(1.0 - e * e * (1.0 - cx * cx), 0.0));
  float m = e * cx / max(ct, max(e * cx / TF_GLASS_TAIL_MAX_GAIN, TF_DIVISION_FLOOR));
  float in_plane = co / (e * ci) - 1.0, in_across = co / e - ci;
  float out_plane = m - 1.0, out_across = e * cx - ct;
  float k4 = 4.0 * float(reflections);
  return vec2((in_plane * in_plane + k4) * m * m + out_plane * out_plane,
              (in_across * in_across + k4) * e * e + out_across * out_across);
}

/* The World's lamps seen in the tails of a rough path leaving at o along dir
 * (shading.glass.tails.lamp_tails): each lamp's power times the path's lobe (GGX's shape in
 * slope space, widths a^2 = spread alpha^2 widened by the lamp's own radius TF_GLASS_TAIL_CORE,
 * scaled to the part a lamp of that radius leaves outside its image) at the lamp's slope, the
 * plane of incidence taken through dir and the path's last chord (from p). */
vec3 tf_lamp_tails(vec3 p, vec3 o, vec3 dir, vec2 spread)
{
  vec3 sum = vec3(0.0);
#ifdef TF_LAMPS
  float alpha = tf_object.material.x * tf_object.material.x;
  vec2 a2 = spread * alpha * alpha;
  if (a2.x <= 0.0 || a2.y <= 0.0) {
    return sum;
  }
  float c2 = TF_GLASS_TAIL_CORE * TF_GLASS_TAIL_CORE;
  vec2 wide = a2 + vec2(c2);
  float scale = sqrt(a2.x * a2.y) / (TF_PI * wide.x * wide.y);
  vec3 chord = o - p;
  /* the plane's axis, else (the chord along dir) one across dir */
  vec3 across = tf_safe_normalize(cross(dir, vec3(0.0, 0.0, 1.0)), vec3(1.0, 0.0, 0.0));
  vec3 e1 = tf_safe_normalize(chord - dot(chord, dir) * dir, across);
  vec3 e2 = cross(dir, e1);
  int count = int(tf_lighting.lamps[0].x);
  for (int k = 0; k < TF_MAX_LAMPS; k++) {
    if (k >= count) {
      break;
    }
    vec3 l = tf_lighting.lamps[1 + 2 * k].xyz;
    float along = dot(l, dir);
    if (along <= 0.0) {
      continue;
    }
    vec2 slope = vec2(dot(l, e1), dot(l, e2)) / along;
    float s2 = dot(slope, slope);
    float q = 1.0 + dot(slope * slope, vec2(1.0) / wide);
    sum += tf_lighting.lamps[2 + 2 * k].rgb * (scale / (q * q) * s2 / (s2 + c2));
  }
#endif
  return sum;
}
