/* tf_background_vert.glsl: full-screen triangle for the environment background.
 *
 * numpy counterpart: render.sphere_view's camera rays. Input pos: clip-space xy of a triangle
 * covering the viewport; the NDC position is passed on to build the ray in the fragment.
 */

void main()
{
  tf_ndc = pos;
  gl_Position = vec4(pos, 1.0, 1.0);
}
