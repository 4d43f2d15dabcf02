#include "tf_sh_rotate.glsl"

/* tf_sh_rotate_loops.glsl: the reference z-y-z rotation, X(+-90) as generic loops (tests only).
 *
 * Not part of the product (tests/ is not shipped): addon/gpu/shaders.py joins it only when asked
 * (shading_library(..., reference_rotation=<this file>), a library without TF_X90_GENERATED, in
 * which tf_shade_at calls tf_local_coefficients at every order). tests/drawing/test_gpu_draw.py checks it
 * against numpy like the generated code; benchmarks.gpu_frame times it ("sh-loops" cases).
 *
 * numpy counterpart: shading.sh_rotation.rotate_z_batch, apply_bands, local_coefficients.
 * Z(angle) is written out band by band so that every array index is a constant: GPUs (and
 * llvmpipe) keep tf_c in registers only when no index is computed at run time.
 */

/* Pair (c_m, s_m) -> (c cos - s sin, c sin + s cos) with cm = (cos m*angle, sin m*angle). */
void tf_zpair(int pos, int neg, vec2 cm)
{
  vec3 c = tf_c[pos];
  vec3 s = tf_c[neg];
  tf_c[pos] = c * cm.x - s * cm.y;
  tf_c[neg] = c * cm.y + s * cm.x;
}

/* Z(angle) with cs = (cos angle, sin angle): tf_zpair(l(l+1)+m, l(l+1)-m, c_m), m = 1..l. */
void tf_rotate_z(vec2 cs)
{
#if TF_L_MAX >= 1
  vec2 c1 = cs;
  tf_zpair(3, 1, c1);
#endif
#if TF_L_MAX >= 2
  vec2 c2 = tf_cmul(c1, cs);
  tf_zpair(7, 5, c1);
  tf_zpair(8, 4, c2);
#endif
#if TF_L_MAX >= 3
  vec2 c3 = tf_cmul(c2, cs);
  tf_zpair(13, 11, c1);
  tf_zpair(14, 10, c2);
  tf_zpair(15, 9, c3);
#endif
#if TF_L_MAX >= 4
  vec2 c4 = tf_cmul(c3, cs);
  tf_zpair(21, 19, c1);
  tf_zpair(22, 18, c2);
  tf_zpair(23, 17, c3);
  tf_zpair(24, 16, c4);
#endif
#if TF_L_MAX >= 5
  vec2 c5 = tf_cmul(c4, cs);
  tf_zpair(31, 29, c1);
  tf_zpair(32, 28, c2);
  tf_zpair(33, 27, c3);
  tf_zpair(34, 26, c4);
  tf_zpair(35, 25, c5);
#endif
#if TF_L_MAX >= 6
  vec2 c6 = tf_cmul(c5, cs);
  tf_zpair(43, 41, c1);
  tf_zpair(44, 40, c2);
  tf_zpair(45, 39, c3);
  tf_zpair(46, 38, c4);
  tf_zpair(47, 37, c5);
  tf_zpair(48, 36, c6);
#endif
#if TF_L_MAX >= 7
  vec2 c7 = tf_cmul(c6, cs);
  tf_zpair(57, 55, c1);
  tf_zpair(58, 54, c2);
  tf_zpair(59, 53, c3);
  tf_zpair(60, 52, c4);
  tf_zpair(61, 51, c5);
  tf_zpair(62, 50, c6);
  tf_zpair(63, 49, c7);
#endif
#if TF_L_MAX >= 8
  vec2 c8 = tf_cmul(c7, cs);
  tf_zpair(73, 71, c1);
  tf_zpair(74, 70, c2);
  tf_zpair(75, 69, c3);
  tf_zpair(76, 68, c4);
  tf_zpair(77, 67, c5);
  tf_zpair(78, 66, c6);
  tf_zpair(79, 65, c7);
  tf_zpair(80, 64, c8);
#endif
#if TF_L_MAX >= 9
  vec2 c9 = tf_cmul(c8, cs);
  tf_zpair(91, 89, c1);
  tf_zpair(92, 88, c2);
  tf_zpair(93, 87, c3);
  tf_zpair(94, 86, c4);
  tf_zpair(95, 85, c5);
  tf_zpair(96, 84, c6);
  tf_zpair(97, 83, c7);
  tf_zpair(98, 82, c8);
  tf_zpair(99, 81, c9);
#endif
#if TF_L_MAX >= 10
  vec2 c10 = tf_cmul(c9, cs);
  tf_zpair(111, 109, c1);
  tf_zpair(112, 108, c2);
  tf_zpair(113, 107, c3);
  tf_zpair(114, 106, c4);
  tf_zpair(115, 105, c5);
  tf_zpair(116, 104, c6);
  tf_zpair(117, 103, c7);
  tf_zpair(118, 102, c8);
  tf_zpair(119, 101, c9);
  tf_zpair(120, 100, c10);
#endif
#if TF_L_MAX >= 11
  vec2 c11 = tf_cmul(c10, cs);
  tf_zpair(133, 131, c1);
  tf_zpair(134, 130, c2);
  tf_zpair(135, 129, c3);
  tf_zpair(136, 128, c4);
  tf_zpair(137, 127, c5);
  tf_zpair(138, 126, c6);
  tf_zpair(139, 125, c7);
  tf_zpair(140, 124, c8);
  tf_zpair(141, 123, c9);
  tf_zpair(142, 122, c10);
  tf_zpair(143, 121, c11);
#endif
#if TF_L_MAX >= 12
  vec2 c12 = tf_cmul(c11, cs);
  tf_zpair(157, 155, c1);
  tf_zpair(158, 154, c2);
  tf_zpair(159, 153, c3);
  tf_zpair(160, 152, c4);
  tf_zpair(161, 151, c5);
  tf_zpair(162, 150, c6);
  tf_zpair(163, 149, c7);
  tf_zpair(164, 148, c8);
  tf_zpair(165, 147, c9);
  tf_zpair(166, 146, c10);
  tf_zpair(167, 145, c11);
  tf_zpair(168, 144, c12);
#endif
}

/* Dense band-by-band product with the X(+90) blocks, or (transpose) with X(-90) = X(+90)^T. */
void tf_apply_x90(bool transpose)
{
  vec3 tmp[TF_BAND_MAX];
  for (int l = 1; l <= TF_L_MAX; l++) {
    int size = 2 * l + 1;
    int first = l * l;
    int off = l * (2 * l - 1) * (2 * l + 1) / 3;
    for (int i = 0; i < size; i++) {
      vec3 acc = vec3(0.0);
      for (int j = 0; j < size; j++) {
        acc += tf_rx(off + (transpose ? j * size + i : i * size + j)) * tf_c[first + j];
      }
      tmp[i] = acc;
    }
    for (int i = 0; i < size; i++) {
      tf_c[first + i] = tmp[i];
    }
  }
}

void tf_apply_x90_pos()
{
  tf_apply_x90(false);
}

void tf_apply_x90_neg()
{
  tf_apply_x90(true);
}

void tf_load(int i)
{
  tf_c[i] = tf_lighting.sh[i].rgb;
}

/* tf_c = the world radiance coefficients, band by band with constant indices
 * (docs/tuning.md#constant-indices). */
void tf_load_world()
{
  tf_load(0);
#if TF_L_MAX >= 1
  tf_load(1); tf_load(2); tf_load(3);
#endif
#if TF_L_MAX >= 2
  tf_load(4); tf_load(5); tf_load(6); tf_load(7); tf_load(8);
#endif
#if TF_L_MAX >= 3
  tf_load(9); tf_load(10); tf_load(11); tf_load(12); tf_load(13); tf_load(14); tf_load(15);
#endif
#if TF_L_MAX >= 4
  tf_load(16); tf_load(17); tf_load(18); tf_load(19); tf_load(20); tf_load(21); tf_load(22);
  tf_load(23); tf_load(24);
#endif
#if TF_L_MAX >= 5
  tf_load(25); tf_load(26); tf_load(27); tf_load(28); tf_load(29); tf_load(30); tf_load(31);
  tf_load(32); tf_load(33); tf_load(34); tf_load(35);
#endif
#if TF_L_MAX >= 6
  tf_load(36); tf_load(37); tf_load(38); tf_load(39); tf_load(40); tf_load(41); tf_load(42);
  tf_load(43); tf_load(44); tf_load(45); tf_load(46); tf_load(47); tf_load(48);
#endif
#if TF_L_MAX >= 7
  tf_load(49); tf_load(50); tf_load(51); tf_load(52); tf_load(53); tf_load(54); tf_load(55);
  tf_load(56); tf_load(57); tf_load(58); tf_load(59); tf_load(60); tf_load(61); tf_load(62);
  tf_load(63);
#endif
#if TF_L_MAX >= 8
  tf_load(64); tf_load(65); tf_load(66); tf_load(67); tf_load(68); tf_load(69); tf_load(70);
  tf_load(71); tf_load(72); tf_load(73); tf_load(74); tf_load(75); tf_load(76); tf_load(77);
  tf_load(78); tf_load(79); tf_load(80);
#endif
#if TF_L_MAX >= 9
  tf_load(81); tf_load(82); tf_load(83); tf_load(84); tf_load(85); tf_load(86); tf_load(87);
  tf_load(88); tf_load(89); tf_load(90); tf_load(91); tf_load(92); tf_load(93); tf_load(94);
  tf_load(95); tf_load(96); tf_load(97); tf_load(98); tf_load(99);
#endif
#if TF_L_MAX >= 10
  tf_load(100); tf_load(101); tf_load(102); tf_load(103); tf_load(104); tf_load(105); tf_load(106);
  tf_load(107); tf_load(108); tf_load(109); tf_load(110); tf_load(111); tf_load(112); tf_load(113);
  tf_load(114); tf_load(115); tf_load(116); tf_load(117); tf_load(118); tf_load(119); tf_load(120);
#endif
#if TF_L_MAX >= 11
  tf_load(121); tf_load(122); tf_load(123); tf_load(124); tf_load(125); tf_load(126); tf_load(127);
  tf_load(128); tf_load(129); tf_load(130); tf_load(131); tf_load(132); tf_load(133); tf_load(134);
  tf_load(135); tf_load(136); tf_load(137); tf_load(138); tf_load(139); tf_load(140); tf_load(141);
  tf_load(142); tf_load(143);
#endif
#if TF_L_MAX >= 12
  tf_load(144); tf_load(145); tf_load(146); tf_load(147); tf_load(148); tf_load(149); tf_load(150);
  tf_load(151); tf_load(152); tf_load(153); tf_load(154); tf_load(155); tf_load(156); tf_load(157);
  tf_load(158); tf_load(159); tf_load(160); tf_load(161); tf_load(162); tf_load(163); tf_load(164);
  tf_load(165); tf_load(166); tf_load(167); tf_load(168);
#endif
}

/* Fill tf_c with the radiance SH in the frame whose z-y-z angles are a, b, c. */
void tf_local_coefficients(vec2 a, vec2 b, vec2 c)
{
  tf_load_world();
  tf_rotate_z(c);
  tf_apply_x90_pos();
  tf_rotate_z(b);
  tf_apply_x90_neg();
  tf_rotate_z(a);
}
