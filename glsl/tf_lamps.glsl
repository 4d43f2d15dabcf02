#include "tf_common.glsl"
#include "tf_brdf.glsl"
#include "tf_frame.glsl"
#include "tf_table.glsl"

/* tf_lamps.glsl: the World's lamps, shaded per light direction.
 *
 * numpy counterpart: shading.lamps.shade (and the weights of shading.split_sum.shade_combined).
 * Lamps: count, directions and powers in tf_lighting.lamps (layout: addon/gpu/resources.py
 * LIGHTING). Texture `tf_film`: the film's reflectance against u = cos theta and, in its last
 * layer, the multiple-scattering factor (resources.FilmTexture); with TF_FILM_UBO the same
 * texels come from the uniform buffer tf_film_data (resources.FILM), as TF_TABLE_UBO for the
 * table. Interpolated in full float32 like tf_table.
 * Each lamp: D G2 F(v.h) / (4 cos theta_o) x power (tf_ggx_weight, tf_brdf.glsl).
 */

#ifdef TF_FILM_UBO
int tf_film_count()
{
  return int(tf_film_data.size.x);
}

int tf_film_layers()
{
  return int(tf_film_data.size.z);
}

vec3 tf_film_texel(int column, int row, int layer)
{
  ivec3 size = ivec3(tf_film_data.size.xyz);
  return tf_film_data.texel[(row * size.x + column) * size.z + layer].rgb;
}
#else
int tf_film_count()
{
  return textureSize(tf_film, 0).x;
}

int tf_film_layers()
{
  return textureSize(tf_film, 0).z;
}

vec3 tf_film_texel(int column, int row, int layer)
{
  return texelFetch(tf_film, ivec3(column, row, layer), 0).rgb;
}
#endif

vec3 tf_film_at(float u, TFLerp r, int layer)
{
  int count = tf_film_count();
  int i0, i1;
  float w;
  tf_lerp_index(u * float(count - 1), count, i0, i1, w);
  vec3 lo = mix(tf_film_texel(i0, r.i0.y, layer), tf_film_texel(i1, r.i0.y, layer), w);
#ifdef TF_VARY_THICKNESS
  vec3 hi = mix(tf_film_texel(i0, r.i1.y, layer), tf_film_texel(i1, r.i1.y, layer), w);
  return mix(lo, hi, r.w.y);
#else
  return lo;
#endif
}

/* The film's reflectance at u = v.h lit by e: the 3x3 matrices' rows dotted with e (spectral),
 * or the per-channel reflectance times e. */
vec3 tf_film_response(float u, TFLerp r, vec3 e)
{
#ifdef TF_SPECTRAL
  return vec3(dot(tf_film_at(u, r, 0), e), dot(tf_film_at(u, r, 1), e), dot(tf_film_at(u, r, 2), e));
#else
  return tf_film_at(u, r, 0) * e;
#endif
}

/* The multiple-scattering factor at the view (the film texture's layer after the reflectance). */
vec3 tf_film_multiscatter(float cos_o, TFLerp r)
{
#ifdef TF_SPECTRAL
  return tf_film_at(cos_o, r, 3);
#else
  return tf_film_at(cos_o, r, 1);
#endif
}

/* The film texture's layer of a diffuse base (film_colour.FilmTable.diffuse), after the
 * multiple-scattering factor; a film without a diffuse base has none. */
int tf_film_diffuse_layer()
{
#ifdef TF_SPECTRAL
  return 4;
#else
  return 2;
#endif
}

/* Whether the film has a diffuse base (its texture holds the layer). */
bool tf_film_has_diffuse()
{
  return tf_film_layers() > tf_film_diffuse_layer();
}

/* The diffuse base's BRDF at the view (film_colour.diffuse_view). */
vec3 tf_film_diffuse(float cos_o, TFLerp r)
{
  return tf_film_at(cos_o, r, tf_film_diffuse_layer());
}

vec3 tf_shade_lamps(TFFrame f, TFLerp r, vec3 n, vec3 v, float roughness)
{
  int count = int(tf_lighting.lamps[0].x);
  TFGgxView g = tf_ggx_view(roughness, f.cos_o);
  vec3 sum = vec3(0.0);
  for (int k = 0; k < TF_MAX_LAMPS; k++) {
    if (k >= count) {
      break;
    }
    vec3 l = tf_lighting.lamps[1 + 2 * k].xyz;
    float cos_i = dot(n, l);
    if (cos_i <= 0.0) {
      continue;
    }
    vec3 p = tf_lighting.lamps[2 + 2 * k].rgb;
    vec3 h = tf_safe_normalize(v + l, n);
    float nh = clamp(dot(n, h), 0.0, 1.0);
    float weight = tf_ggx_weight(nh, g.a2, cos_i, g);
    float u = clamp(dot(v, h), 0.0, 1.0);
    sum += weight * tf_film_response(u, r, p);
  }
  return sum * tf_film_multiscatter(g.cos_o, r);
}
