#include "tf_common.glsl"

/* tf_glass_frag.glsl: solid glass's faces into the glass buffers (addon/gpu/glass_buffers.py).
 *
 * numpy counterpart: shading.refract.glass_texel (the decoding). Drawn after tf_main_vert.glsl with
 * the front or the back faces culled: .xyz the unit outward normal times (id + 1), id the object's
 * tf_object.glass.x; .w the depth along the camera axis (as tf_refract.glsl reads it).
 */

void main()
{
  vec3 n = tf_safe_normalize(tf_world_nor, tf_view.view_dir.xyz);
  float depth = dot(tf_view.camera.xyz - tf_world_pos, tf_view.view_dir.xyz);
  tf_frag_color = vec4(n * (tf_object.glass.x + 1.0), depth);
}
