/* tf_shade.glsl: one pixel of thin-film SH shading.
 *
 * numpy counterpart: render.shade_sh. Frame, rotation of the World's SH into it, table
 * lookup at theta_o (and thickness), out = max(sum_i M_i L_i, 0) over the kept (m >= 0)
 * coefficients i = l(l+1)+m, ordered by l then m (bake.coefficient_indices).
 *
 * n, v: unit normal and unit direction towards the viewer (world space); thickness01: the
 * position on the table's thickness axis in [0, 1] (ignored without TF_VARY_THICKNESS).
 */

vec3 tf_shade(vec3 n, vec3 v, float thickness01)
{
  TFFrame f = tf_view_aligned_frame(n, v);
  vec2 a, b, c;
  tf_zyz_from_frame(f, a, b, c);
  tf_local_coefficients(a, b, c);
  TFLerp r = tf_table_lerp(f.cos_o, f.sin_o, thickness01);

  vec3 sum = vec3(0.0);
  int k = 0;
  for (int l = 0; l <= TF_L_MAX; l++) {
    for (int m = 0; m <= l; m++) {
      vec3 radiance = tf_c[l * (l + 1) + m];
#ifdef TF_SPECTRAL
      sum.r += dot(tf_table_fetch(r, 3 * k + 0), radiance);
      sum.g += dot(tf_table_fetch(r, 3 * k + 1), radiance);
      sum.b += dot(tf_table_fetch(r, 3 * k + 2), radiance);
#else
      sum += tf_table_fetch(r, k) * radiance;
#endif
      k++;
    }
  }
  return max(sum, vec3(0.0));
}
