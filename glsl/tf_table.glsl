#include "tf_common.glsl"

/* tf_table.glsl: bilinear lookup of the baked table at (theta_o, thickness).
 *
 * numpy counterpart: shading.table.lerp_index and shading.table.lookup.
 * Texture `tf_table`: width A = view angles (theta_o uniform 0..90 deg inclusive), height T =
 * thickness rows, one layer per table row (3 per kept coefficient with TF_SPECTRAL); layout in
 * addon/gpu/resources.py (TableTexture). Without TF_VARY_THICKNESS the first thickness row is
 * used (table.lookup without thickness).
 * With TF_TABLE_UBO the same texels come from the uniform buffer tf_table_data instead (small
 * tables on policy.TABLE_UBO_DEVICES; layout: resources.TABLE).
 * Interpolation is done here with texelFetch (4 fetches, 2 for one thickness row), in full
 * float32: hardware filtering quantises the weights (8 bits of sub-texel precision on common
 * GPUs) and would not reproduce table.lookup to 1e-4.
 */

/* The table's size (A, T, layers) and one texel's .rgb, from the texture or, with TF_TABLE_UBO,
 * from the uniform buffer tf_table_data (the same values; resources.TABLE). */
#ifdef TF_TABLE_UBO
ivec3 tf_table_size()
{
  return ivec3(tf_table_data.size.xyz);
}

vec3 tf_table_texel(int column, int row, int layer)
{
  ivec3 size = tf_table_size();
  return tf_table_data.texel[(row * size.x + column) * size.z + layer].rgb;
}
#else
ivec3 tf_table_size()
{
  return textureSize(tf_table, 0);
}

vec3 tf_table_texel(int column, int row, int layer)
{
  return texelFetch(tf_table, ivec3(column, row, layer), 0).rgb;
}
#endif

struct TFLerp {
  ivec2 i0; /* (theta column, thickness row) */
  ivec2 i1;
  vec2 w;
};

/* shading.table.lerp_index: position clamped to [0, count - 1], lower index <= count - 2. */
void tf_lerp_index(float pos, int count, out int i0, out int i1, out float w)
{
  pos = clamp(pos, 0.0, float(count - 1));
  i0 = min(int(floor(pos)), max(count - 2, 0));
  i1 = min(i0 + 1, count - 1);
  w = pos - float(i0);
}

/* The table position of r at another view angle theta in [0, pi/2]; the thickness part is kept. */
TFLerp tf_table_at_theta(TFLerp r, float theta)
{
  ivec3 size = tf_table_size();
  float w;
  int i0, i1;
  tf_lerp_index(theta / TF_HALF_PI * float(size.x - 1), size.x, i0, i1, w);
  r.i0.x = i0;
  r.i1.x = i1;
  r.w.x = w;
  return r;
}

/* theta_o from (cos, sin) and the thickness position in [0, 1] (0 = first row). */
TFLerp tf_table_lerp(float cos_o, float sin_o, float thickness01)
{
  TFLerp r;
  r.i0 = ivec2(0);
  r.i1 = ivec2(0);
  r.w = vec2(0.0);
  /* theta = acos(clip(cos_o, 0, 1)) */
  r = tf_table_at_theta(r, (cos_o > 0.0) ? atan(max(sin_o, 0.0), cos_o) : TF_HALF_PI);
#ifdef TF_VARY_THICKNESS
  ivec3 size = tf_table_size();
  if (size.y > 1) {
    float w;
    int i0, i1;
    tf_lerp_index(thickness01 * float(size.y - 1), size.y, i0, i1, w);
    r.i0.y = i0;
    r.i1.y = i1;
    r.w.y = w;
    return r;
  }
#endif
  r.i0.y = 0;
  r.i1.y = 0;
  r.w.y = 0.0;
  return r;
}

vec3 tf_table_fetch(TFLerp r, int layer)
{
  vec3 lo = mix(tf_table_texel(r.i0.x, r.i0.y, layer), tf_table_texel(r.i1.x, r.i0.y, layer), r.w.x);
#ifdef TF_VARY_THICKNESS
  vec3 hi = mix(tf_table_texel(r.i0.x, r.i1.y, layer), tf_table_texel(r.i1.x, r.i1.y, layer), r.w.x);
  return mix(lo, hi, r.w.y);
#else
  return lo;
#endif
}
