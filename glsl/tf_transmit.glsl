#include "tf_lamps.glsl"

/* tf_transmit.glsl: a transparent film's wall, its transmittance T and reflection scale S.
 *
 * numpy counterpart: shading.transmit (wall, white_reflectance, shade). From the film's
 * reflectance r per channel at the view cosine (texture tf_film, layer 0, or the row sums of
 * layers 0..2 with TF_SPECTRAL; read by tf_film_at of tf_lamps.glsl), evaluated once at the
 * macro view angle. Wall mode (tf_object.material.z) and the sheet's relative index eta
 * (tf_object.material.w): shading.transmit.WALL_SHEET (0):
 *   Rb = Fresnel(u, eta), T = (1 - r)(1 - Rb) / (1 - r Rb), S = 1 + (1 - r)^2 Rb / ((1 - r Rb) r);
 * WALL_CYCLES (1, Cycles' thin wall) with the transmission tint (tf_object.glass.yzw, a Principled
 * BSDF's Base Color; 1 untinted) absorbed c = tint^(1 / cos theta_t) per pass (tf_tint_pass):
 *   T = c (1 - r)^2 / (1 - (c r)^2), S = 1 + T c (c = 1: T = (1 - r) / (1 + r), S = 2 / (1 + r));
 * WALL_SOLID (2, solid glass of index eta): T = (1 - r)^2, S = 1, and what is behind is replaced by
 * the scene behind refracted (TF_REFRACT, tf_refract.glsl), else the World seen along
 * tf_solid_exit (with TF_SPLIT_SUM: the prefiltered World's sharpest level).
 * S is capped at TF_WALL_SCALE_MAX (policy.WALL_SCALE_MAX).
 */

/* Unpolarised Fresnel reflectance at cos_i of an interface of relative index eta (1 under TIR). */
float tf_fresnel_dielectric(float cos_i, float eta)
{
  float c = clamp(cos_i, 0.0, 1.0);
  float g2 = eta * eta - 1.0 + c * c;
  if (g2 <= 0.0) {
    return 1.0;
  }
  float g = sqrt(g2);
  float a = (g - c) / max(g + c, TF_DIVISION_FLOOR);
  float b = (c * (g + c) - 1.0) / max(c * (g - c) + 1.0, TF_DIVISION_FLOOR);
  return clamp(0.5 * a * a * (1.0 + b * b), 0.0, 1.0);
}

/* The film's reflectance of white light per channel at cosine u (shading.transmit.white_reflectance). */
vec3 tf_film_white(float u, TFLerp r)
{
#ifdef TF_SPECTRAL
  return vec3(dot(tf_film_at(u, r, 0), vec3(1.0)),
              dot(tf_film_at(u, r, 1), vec3(1.0)),
              dot(tf_film_at(u, r, 2), vec3(1.0)));
#else
  return tf_film_at(u, r, 0);
#endif
}

/* The share of light a thin wall of index eta tinted tint lets through in one pass at the outside
 * cosine cos_v: tint^(1 / cos theta_t), 0 where the light cannot enter (shading.transmit.tint_pass). */
vec3 tf_tint_pass(vec3 tint, float cos_v, float eta)
{
  float c = clamp(cos_v, 0.0, 1.0);
  float e = max(eta, TF_WALL_GUARD);
  float cos_t = sqrt(max(1.0 - (1.0 - c * c) / (e * e), 0.0));
  if (cos_t <= 0.0) {
    return vec3(0.0);
  }
  return pow(clamp(tint, vec3(0.0), vec3(1.0)), vec3(1.0 / max(cos_t, TF_WALL_GUARD)));
}

/* T and S of the wall at view cosine cos_v (shading.transmit.wall); tint: the transmission tint
 * (solid glass's T stays untinted: the caller tints what passes through). */
void tf_wall(float cos_v, TFLerp r, float mode, float eta, vec3 tint, out vec3 t, out vec3 s)
{
  float u = clamp(cos_v, 0.0, 1.0);
  vec3 refl = clamp(tf_film_white(u, r), vec3(0.0), vec3(1.0));
  if (mode > 1.5) { /* WALL_SOLID: in through the film, out through it again (reciprocity) */
    t = (vec3(1.0) - refl) * (vec3(1.0) - refl);
    s = vec3(1.0);
    return;
  }
  if (mode > 0.5) {
    vec3 c = tf_tint_pass(tint, u, eta);
    vec3 one_minus = vec3(1.0) - refl;
    t = c * one_minus * one_minus / max(vec3(1.0) - c * c * refl * refl, vec3(TF_WALL_GUARD));
    s = vec3(1.0) + t * c;
    return;
  }
  float rb = tf_fresnel_dielectric(max(u, TF_MIN_COS), eta);
  vec3 denominator = max(vec3(1.0) - refl * rb, vec3(TF_WALL_GUARD));
  vec3 one_minus = vec3(1.0) - refl;
  t = one_minus * (1.0 - rb) / denominator;
  vec3 extra = one_minus * one_minus * rb / denominator;
  s = min(vec3(1.0) + extra / max(refl, vec3(TF_WALL_GUARD)), vec3(TF_WALL_SCALE_MAX));
}

/* The direction a ray leaves a glass sphere of index eta after one reflection inside it, entered at
 * normal n from the viewer (v): turned towards -n by pi + 2 theta_i - 4 theta_t
 * (shading.transmit.solid_internal). */
vec3 tf_solid_internal(vec3 n, vec3 v, float eta)
{
  float ci = clamp(dot(n, v), 0.0, 1.0);
  float si = sqrt(max(1.0 - ci * ci, 0.0));
  float theta_i = asin(min(si, 1.0));
  float theta_t = asin(min(si / max(eta, TF_WALL_GUARD), 1.0));
  float deviation = TF_PI + 2.0 * theta_i - 4.0 * theta_t;
  vec3 w = tf_safe_normalize(ci * v - n, vec3(0.0));
  return tf_safe_normalize(-cos(deviation) * v + sin(deviation) * w, v);
}

/* The direction a ray leaves a glass sphere of index eta it entered at normal n from the viewer
 * (v): turned towards -n by 2 (theta_i - theta_t) (shading.transmit.solid_exit). */
vec3 tf_solid_exit(vec3 n, vec3 v, float eta)
{
  float ci = clamp(dot(n, v), 0.0, 1.0);
  float si = sqrt(max(1.0 - ci * ci, 0.0));
  float deviation = 2.0 * (asin(min(si, 1.0)) - asin(min(si / max(eta, TF_WALL_GUARD), 1.0)));
  vec3 w = tf_safe_normalize(ci * v - n, vec3(0.0));
  return tf_safe_normalize(-cos(deviation) * v + sin(deviation) * w, -v);
}

/* One hit of a ray inside the sphere about centre through p (shading.transmit.inside_path): from p
 * along d (into the sphere) across the chord to the next point, d reflected there about the
 * sphere's normal; cos_hit: the cosine met there (0 where d does not enter: p stays). */
void tf_inside_step(inout vec3 p, inout vec3 d, vec3 centre, out float cos_hit)
{
  float chord = max(-2.0 * dot(p - centre, d), 0.0);
  p += chord * d;
  vec3 n = tf_safe_normalize(p - centre, -d);
  float dn = dot(d, n);
  cos_hit = (chord > 0.0) ? clamp(dn, 0.0, 1.0) : 0.0;
  d -= 2.0 * dn * n;
}

/* A thin wall's reflectance R = S r and transmittance T at cosine u where its thickness parameter
 * is t01 (shading.transmit.inside_reflections' wall_at). */
void tf_wall_rt(float u, float t01, float mode, float eta, vec3 tint, out vec3 refl, out vec3 t)
{
  float c = clamp(u, 0.0, 1.0);
  TFLerp r = tf_table_lerp(c, sqrt(max(1.0 - c * c, 0.0)), t01);
  vec3 s;
  tf_wall(c, r, mode, eta, tint, t, s);
  refl = s * clamp(tf_film_white(c, r), vec3(0.0), vec3(1.0));
}
