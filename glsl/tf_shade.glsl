#include "tf_frame.glsl"
#include "tf_sh_rotate.glsl"
#include "tf_table.glsl"
#include "tf_radiance_grid.glsl"

/* tf_shade.glsl: one pixel of thin-film SH shading.
 *
 * numpy counterpart: shading.sh_sum.shade_sh. Frame, rotation of the World's SH into it (z-y-z; in the
 * fast library, TF_X90_GENERATED, straight from the frame for l <= 2: tf_sh_rotate.glsl, and from
 * l = 3 on rotated and summed band by band, codegen.banded_source), table
 * lookup at theta_o (and thickness), out = max(sum_i M_i L_i, 0) over the kept (m >= 0)
 * coefficients i = l(l+1)+m, ordered by l then m (bake.coefficient_indices).
 *
 * The sum is written out per band, so that every index into tf_c is a constant. Above l = 2 the
 * library reaches it only with the reference rotation (tests/glsl/tf_sh_rotate_loops.glsl).
 *
 * n, v: unit normal and unit direction towards the viewer (world space); thickness01: the
 * position on the table's thickness axis in [0, 1] (ignored without TF_VARY_THICKNESS).
 * With TF_RADIANCE_GRID (policy.uses_grid) the sum is read from the outgoing-radiance grid
 * instead (tf_radiance_grid.glsl; a varying thickness from its film-free basis,
 * tf_grid_basis.glsl) and no SH code is compiled.
 */

/* sum += M_k L for kept coefficient k (table layers 3k..3k+2, or layer k) and the local
 * radiance coefficient L. */
void tf_accumulate_value(inout vec3 sum, TFLerp r, int k, vec3 radiance)
{
#ifdef TF_SPECTRAL
  sum.r += dot(tf_table_fetch(r, 3 * k + 0), radiance);
  sum.g += dot(tf_table_fetch(r, 3 * k + 1), radiance);
  sum.b += dot(tf_table_fetch(r, 3 * k + 2), radiance);
#else
  sum += tf_table_fetch(r, k) * radiance;
#endif
}

/* sum += M_k L_i with L_i = tf_c[i], i = l(l+1)+m. */
void tf_accumulate(inout vec3 sum, TFLerp r, int k, int i)
{
  tf_accumulate_value(sum, r, k, tf_c[i]);
}

#if TF_L_MAX > 2 && defined(TF_X90_GENERATED) && !defined(TF_RADIANCE_GRID)
/* Rotation and sum band by band in local variables, generated after this file
 * (codegen.banded_source): only one band's coefficients are live at a time. */
vec3 tf_banded_sum(TFLerp r, vec2 a, vec2 b, vec2 c);
#endif
#if defined(TF_RADIANCE_GRID) && defined(TF_VARY_THICKNESS)
/* A varying film's grid: the film-free basis read with its thickness (tf_grid_basis.glsl,
 * joined after this file). */
vec3 tf_shade_grid_basis(TFFrame f, TFLerp r);
#endif

/* The SH sum for a frame and table position already computed (shared with the split sum in
 * tf_shade_combined, so the combined path does not build them twice). */
vec3 tf_shade_at(TFFrame f, TFLerp r)
{
#if defined(TF_RADIANCE_GRID) && defined(TF_VARY_THICKNESS)
  return tf_shade_grid_basis(f, r); /* shading.lobe_grid.lookup_basis: the exact lobe, any thickness */
#elif defined(TF_RADIANCE_GRID)
  return tf_shade_grid(f); /* shading.radiance_grid.lookup: the same sum, tabulated */
#elif TF_L_MAX > 2 && defined(TF_X90_GENERATED)
  vec2 a, b, c;
  tf_zyz_from_frame(f, a, b, c);
  return max(tf_banded_sum(r, a, b, c), vec3(0.0));
#else
#if TF_L_MAX <= 2 && defined(TF_X90_GENERATED)
  tf_local_coefficients_direct(f);
#else /* the reference: tf_local_coefficients of tests/glsl/tf_sh_rotate_loops.glsl */
  vec2 a, b, c;
  tf_zyz_from_frame(f, a, b, c);
  tf_local_coefficients(a, b, c);
#endif

  /* Written out band by band, (k, i) constant: a loop that computes the index into tf_c makes
   * the compiler move tf_c out of registers (docs/tuning.md#constant-indices). */
  vec3 sum = vec3(0.0);
  tf_accumulate(sum, r, 0, 0);
#if TF_L_MAX >= 1
  tf_accumulate(sum, r, 1, 2);
  tf_accumulate(sum, r, 2, 3);
#endif
#if TF_L_MAX >= 2
  tf_accumulate(sum, r, 3, 6);
  tf_accumulate(sum, r, 4, 7);
  tf_accumulate(sum, r, 5, 8);
#endif
#if TF_L_MAX >= 3
  tf_accumulate(sum, r, 6, 12);
  tf_accumulate(sum, r, 7, 13);
  tf_accumulate(sum, r, 8, 14);
  tf_accumulate(sum, r, 9, 15);
#endif
#if TF_L_MAX >= 4
  tf_accumulate(sum, r, 10, 20);
  tf_accumulate(sum, r, 11, 21);
  tf_accumulate(sum, r, 12, 22);
  tf_accumulate(sum, r, 13, 23);
  tf_accumulate(sum, r, 14, 24);
#endif
#if TF_L_MAX >= 5
  tf_accumulate(sum, r, 15, 30);
  tf_accumulate(sum, r, 16, 31);
  tf_accumulate(sum, r, 17, 32);
  tf_accumulate(sum, r, 18, 33);
  tf_accumulate(sum, r, 19, 34);
  tf_accumulate(sum, r, 20, 35);
#endif
#if TF_L_MAX >= 6
  tf_accumulate(sum, r, 21, 42);
  tf_accumulate(sum, r, 22, 43);
  tf_accumulate(sum, r, 23, 44);
  tf_accumulate(sum, r, 24, 45);
  tf_accumulate(sum, r, 25, 46);
  tf_accumulate(sum, r, 26, 47);
  tf_accumulate(sum, r, 27, 48);
#endif
#if TF_L_MAX >= 7
  tf_accumulate(sum, r, 28, 56);
  tf_accumulate(sum, r, 29, 57);
  tf_accumulate(sum, r, 30, 58);
  tf_accumulate(sum, r, 31, 59);
  tf_accumulate(sum, r, 32, 60);
  tf_accumulate(sum, r, 33, 61);
  tf_accumulate(sum, r, 34, 62);
  tf_accumulate(sum, r, 35, 63);
#endif
#if TF_L_MAX >= 8
  tf_accumulate(sum, r, 36, 72);
  tf_accumulate(sum, r, 37, 73);
  tf_accumulate(sum, r, 38, 74);
  tf_accumulate(sum, r, 39, 75);
  tf_accumulate(sum, r, 40, 76);
  tf_accumulate(sum, r, 41, 77);
  tf_accumulate(sum, r, 42, 78);
  tf_accumulate(sum, r, 43, 79);
  tf_accumulate(sum, r, 44, 80);
#endif
#if TF_L_MAX >= 9
  tf_accumulate(sum, r, 45, 90);
  tf_accumulate(sum, r, 46, 91);
  tf_accumulate(sum, r, 47, 92);
  tf_accumulate(sum, r, 48, 93);
  tf_accumulate(sum, r, 49, 94);
  tf_accumulate(sum, r, 50, 95);
  tf_accumulate(sum, r, 51, 96);
  tf_accumulate(sum, r, 52, 97);
  tf_accumulate(sum, r, 53, 98);
  tf_accumulate(sum, r, 54, 99);
#endif
#if TF_L_MAX >= 10
  tf_accumulate(sum, r, 55, 110);
  tf_accumulate(sum, r, 56, 111);
  tf_accumulate(sum, r, 57, 112);
  tf_accumulate(sum, r, 58, 113);
  tf_accumulate(sum, r, 59, 114);
  tf_accumulate(sum, r, 60, 115);
  tf_accumulate(sum, r, 61, 116);
  tf_accumulate(sum, r, 62, 117);
  tf_accumulate(sum, r, 63, 118);
  tf_accumulate(sum, r, 64, 119);
  tf_accumulate(sum, r, 65, 120);
#endif
#if TF_L_MAX >= 11
  tf_accumulate(sum, r, 66, 132);
  tf_accumulate(sum, r, 67, 133);
  tf_accumulate(sum, r, 68, 134);
  tf_accumulate(sum, r, 69, 135);
  tf_accumulate(sum, r, 70, 136);
  tf_accumulate(sum, r, 71, 137);
  tf_accumulate(sum, r, 72, 138);
  tf_accumulate(sum, r, 73, 139);
  tf_accumulate(sum, r, 74, 140);
  tf_accumulate(sum, r, 75, 141);
  tf_accumulate(sum, r, 76, 142);
  tf_accumulate(sum, r, 77, 143);
#endif
#if TF_L_MAX >= 12
  tf_accumulate(sum, r, 78, 156);
  tf_accumulate(sum, r, 79, 157);
  tf_accumulate(sum, r, 80, 158);
  tf_accumulate(sum, r, 81, 159);
  tf_accumulate(sum, r, 82, 160);
  tf_accumulate(sum, r, 83, 161);
  tf_accumulate(sum, r, 84, 162);
  tf_accumulate(sum, r, 85, 163);
  tf_accumulate(sum, r, 86, 164);
  tf_accumulate(sum, r, 87, 165);
  tf_accumulate(sum, r, 88, 166);
  tf_accumulate(sum, r, 89, 167);
  tf_accumulate(sum, r, 90, 168);
#endif
  return max(sum, vec3(0.0));
#endif
}

vec3 tf_shade(vec3 n, vec3 v, float thickness01)
{
  TFFrame f = tf_view_aligned_frame(n, v);
  return tf_shade_at(f, tf_table_lerp(f.cos_o, f.sin_o, thickness01));
}
