#include "tf_common.glsl"

/* tf_background_frag.glsl: the World's equirectangular image behind everything.
 *
 * numpy counterpart: hdri.equirect_lookup (conventions.md mapping): u = 1/2 - phi / 2pi with
 * phi = atan2(y, x), texture row 0 = the image's top row (theta = 0), so t = theta / pi.
 * Texture `tf_environment`: addon/gpu/resources.py EnvironmentTexture (hardware LINEAR filtering).
 * The ray is unprojected through the inverse view-projection matrix (perspective or ortho).
 */

void main()
{
  mat4 inv_vp = mat4(tf_view.inv_view_proj[0], tf_view.inv_view_proj[1], tf_view.inv_view_proj[2],
                     tf_view.inv_view_proj[3]);
  vec4 near = inv_vp * vec4(tf_ndc, -1.0, 1.0);
  vec4 far = inv_vp * vec4(tf_ndc, 1.0, 1.0);
  vec3 d = tf_safe_normalize(far.xyz / far.w - near.xyz / near.w, vec3(1.0, 0.0, 0.0));
  float u = 0.5 - atan(d.y, d.x) / (2.0 * TF_PI);
  float t = acos(clamp(d.z, -1.0, 1.0)) / TF_PI;
  vec3 rgb = texture(tf_environment, vec2(u, t)).rgb;
#ifdef TF_DISPLAY_SRGB
  rgb = tf_srgb_oetf(clamp(rgb * tf_view.params.x, 0.0, 1.0));
#endif
  tf_frag_color = vec4(rgb, 1.0);
}
