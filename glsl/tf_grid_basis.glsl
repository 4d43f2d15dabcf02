#include "tf_radiance_grid.glsl"
#include "tf_lamps.glsl"

/* tf_grid_basis.glsl: a varying film's SH half from the film-free basis grid (TF_RADIANCE_GRID
 * with TF_VARY_THICKNESS).
 *
 * numpy counterpart: shading.lobe_grid.lookup_basis. The texture (shading.lobe_grid.build_basis)
 * holds T x TF_GRID_AZIMUTHS layers and TF_GRID_AZIMUTHS more, each TF_GRID_HATS bands of mirror
 * cells with a column of padding each side: band k is the lobe's integral weighted by the hat
 * of u node k / (TF_GRID_HATS - 1), and texel (j, 0) of the last layers holds the first and last
 * hat view node j's lobe reaches. A film of any
 * thickness reads sum_k F(u_k) H_k at each of the two view nodes (its reflectance linear in u
 * between the nodes), then interpolates in theta_o and applies its multiple-scattering factor.
 */

#if defined(TF_RADIANCE_GRID) && defined(TF_VARY_THICKNESS)
vec3 tf_grid_basis_node(TFGridAt g, ivec3 size, int j, TFLerp r)
{
  vec2 used = texelFetch(tf_radiance_grid, ivec3(j, 0, size.z - TF_GRID_AZIMUTHS), 0).xy;
  int first = int(used.x + 0.5);
  int last = int(used.y + 0.5);
  int width = size.x;
  int cells = width / TF_GRID_HATS - 2;
  vec3 sum = vec3(0.0);
  for (int k = 0; k < TF_GRID_HATS; k++) {
    if (k >= first && k <= last) {
      TFGridAt h = g; /* hat k's padded columns */
      h.uv.x = (float(k * (cells + 2) + 1) + g.uv.x * float(cells)) / float(width);
      float u = float(k) / float(TF_GRID_HATS - 1);
      sum += tf_film_response(u, r, tf_grid_node(h, 0, j));
    }
  }
  return sum;
}

vec3 tf_shade_grid_basis(TFFrame f, TFLerp r)
{
  ivec3 size = textureSize(tf_radiance_grid, 0);
  TFGridAt g = tf_grid_at(f, size.z / TF_GRID_AZIMUTHS - 1);
  vec3 lo = tf_grid_basis_node(g, size, g.j0, r);
  vec3 hi = tf_grid_basis_node(g, size, g.j0 + 1, r);
  float cos_o = clamp(f.cos_o, TF_MIN_COS, 1.0);
  return tf_lighting.world[0].w * mix(lo, hi, g.wj) * tf_film_multiscatter(cos_o, r);
}
#endif
