#include "tf_common.glsl"

/* tf_glass_frag.glsl: solid glass's faces into the glass buffers (addon/gpu/glass_buffers.py).
 *
 * numpy counterpart: shading.glass.glass_exit.glass_texel (the decoding). Drawn after tf_main_vert.glsl with
 * the front or the back faces culled: .xyz the unit outward normal times (id + 1), id the object's
 * tf_object.glass.x; .w the depth along the camera axis (as tf_glass_exit.glsl reads it). With
 * TF_GLASS_GEOMETRIC: .xy the face's geometric normal, outward, octahedral (tf_oct_encode;
 * shading.glass.glass_exit.geometric_texel), for Cycles' rules at smooth-shaded faces (tf_valid_normal).
 * With TF_GLASS_FURTHER (the further layers, depth peeling): only faces more than TF_GLASS_PEEL x their
 * depth behind the layer before (tf_glass_peel, the same side's: .w its depth, 0 where empty).
 */

/* Unit n -> its octahedral coordinates in [-1, 1]^2, the lower half folded over the diagonals
 * (shading.glass.glass_exit.octahedral). */
vec2 tf_oct_encode(vec3 n)
{
  vec3 a = n / max(abs(n.x) + abs(n.y) + abs(n.z), TF_DIVISION_FLOOR);
  if (a.z >= 0.0) {
    return a.xy;
  }
  return (vec2(1.0) - abs(a.yx)) * vec2(a.x >= 0.0 ? 1.0 : -1.0, a.y >= 0.0 ? 1.0 : -1.0);
}

void main()
{
  vec3 n = tf_safe_normalize(tf_world_nor, tf_view.view_dir.xyz);
  float depth = dot(tf_view.camera.xyz - tf_world_pos, tf_view.view_dir.xyz);
#ifdef TF_GLASS_GEOMETRIC
  /* the face's own (flat) normal, outward: a front face's towards the viewer, a back face's away
   * (each pass culls the other side); taken before any discard */
  vec3 toward = (tf_view.camera.w > 0.5) ? tf_view.view_dir.xyz : tf_view.camera.xyz - tf_world_pos;
  vec3 g = tf_safe_normalize(cross(dFdx(tf_world_pos), dFdy(tf_world_pos)), n);
  if ((dot(g, toward) >= 0.0) != gl_FrontFacing) {
    g = -g;
  }
#endif
#ifdef TF_GLASS_FURTHER
  vec4 before = texelFetch(tf_glass_peel, ivec2(gl_FragCoord.xy), 0);
  if (before.w <= 0.0 || depth <= before.w * (1.0 + TF_GLASS_PEEL)) {
    discard;
  }
#endif
#ifdef TF_GLASS_GEOMETRIC
  tf_frag_color = vec4(tf_oct_encode(g), 0.0, 0.0);
#else
  tf_frag_color = vec4(n * (tf_object.glass.x + 1.0), depth);
#endif
}
