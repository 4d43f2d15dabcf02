/* tf_main_vert.glsl: world-space position and normal of a mesh vertex.
 *
 * numpy counterpart: none (geometry); the normal matrix is inverse-transpose(model) 3x3,
 * computed in Python (addon/gpu/draw.py object_uniforms). Vertex inputs: pos, nor (object space)
 * and, with TF_VARY_THICKNESS, thickness in [0, 1]; with TF_THICKNESS_MAP, uv (the thickness
 * map's); TF_THICKNESS_NOISE passes the object-space position on (TF_NOISE_ORCO: orco, the
 * vertex's before a deformation). Uniform buffers: tf_view, tf_object (layouts: addon/gpu/resources.py VIEW, OBJECT).
 */

void main()
{
  mat4 model = mat4(tf_object.model[0], tf_object.model[1], tf_object.model[2], tf_object.model[3]);
  mat3 normal_matrix = mat3(tf_object.normal[0].xyz, tf_object.normal[1].xyz, tf_object.normal[2].xyz);
  mat4 view_proj = mat4(tf_view.view_proj[0], tf_view.view_proj[1], tf_view.view_proj[2], tf_view.view_proj[3]);
  vec4 world = model * vec4(pos, 1.0);
  tf_world_pos = world.xyz;
  tf_world_nor = normal_matrix * nor;
#ifdef TF_VARY_THICKNESS
  tf_thickness = thickness;
#endif
#ifdef TF_THICKNESS_MAP
  tf_uv = uv;
#endif
#if defined(TF_NOISE_ORCO)
  tf_object_pos = orco; /* Generated after a deformation: where the vertex was before it */
#elif defined(TF_THICKNESS_NOISE)
  tf_object_pos = pos;
#endif
  gl_Position = view_proj * world;
}
