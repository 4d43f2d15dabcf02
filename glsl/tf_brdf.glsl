#include "tf_common.glsl"

/* tf_brdf.glsl: the GGX microfacet terms, written once for every light the shader loops over
 * (the World's lamps, tf_lamps.glsl; Blender's light objects, tf_lights.glsl).
 *
 * numpy counterpart: precompute/brdf.py (alpha_from_roughness, D_ggx, lambda_ggx,
 * G2_smith_height_correlated). GGX D: Walter et al. 2007, eq. 33; height-correlated Smith G2 =
 * 1 / (1 + Lambda_i + Lambda_o): Heitz 2014, eq. 99, with Lambda from eq. 72.
 */

/* brdf.alpha_from_roughness: GGX alpha = roughness^2, clamped to TF_MIN_ALPHA. */
float tf_alpha_from_roughness(float roughness)
{
  float rr = clamp(roughness, 0.0, 1.0);
  return max(rr * rr, TF_MIN_ALPHA);
}

/* brdf.D_ggx with alpha^2 = a2 at n.h = nh (clamped to [0, 1] by the caller); 0 below the surface. */
float tf_d_ggx(float nh, float a2)
{
  float t = nh * nh * (a2 - 1.0) + 1.0;
  return (nh > 0.0) ? a2 / (TF_PI * t * t) : 0.0;
}

/* Smith Lambda for GGX with alpha^2 = a2 (brdf.lambda_ggx). */
float tf_lambda_ggx(float c, float a2)
{
  c = clamp(c, TF_MIN_COS, 1.0);
  return 0.5 * (sqrt(1.0 + a2 * (1.0 - c * c) / (c * c)) - 1.0);
}

/* What every light loop needs of its pixel once (numpy: shading.lamps.lit_pixels): GGX alpha and
 * alpha^2, cos theta_o clamped to [TF_MIN_COS, 1] and Lambda(theta_o). */
struct TFGgxView {
  float alpha;
  float a2;
  float cos_o;
  float lambda_o;
};

TFGgxView tf_ggx_view(float roughness, float cos_o)
{
  TFGgxView g;
  g.alpha = tf_alpha_from_roughness(roughness);
  g.a2 = g.alpha * g.alpha;
  g.cos_o = clamp(cos_o, TF_MIN_COS, 1.0);
  g.lambda_o = tf_lambda_ggx(g.cos_o, g.a2);
  return g;
}

/* D G2 / (4 cos_o) of one light direction: D at alpha^2 = d_a2 (a light's footprint may widen
 * it), G2 at the view's alpha^2. */
float tf_ggx_weight(float nh, float d_a2, float cos_i, TFGgxView g)
{
  return tf_d_ggx(nh, d_a2) / ((1.0 + tf_lambda_ggx(cos_i, g.a2) + g.lambda_o) * 4.0 * g.cos_o);
}
