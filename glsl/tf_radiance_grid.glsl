#include "tf_frame.glsl"

/* tf_radiance_grid.glsl: the SH half read from the outgoing-radiance grid (TF_RADIANCE_GRID).
 *
 * numpy counterpart: shading.radiance_grid.coordinates and shading.radiance_grid.lookup.
 * Texture `tf_radiance_grid` (addon/gpu/resources.py RadianceGridTexture): a 2-D array, W x H
 * equirect cells of the mirror direction r (as the prefilter: u = 0.5 - phi/2pi, t = theta/pi;
 * LINEAR, REPEAT in u, EXTEND in t), layer j * TF_GRID_AZIMUTHS + k = view angle node j
 * (theta_o = pi/2 j / (T - 1), T = layers / TF_GRID_AZIMUTHS: the table's view angles) and
 * view azimuth k (psi = 2 pi k / TF_GRID_AZIMUTHS)
 * about r, measured from a1 = d r / d theta_r towards a2 = d r / d phi_r (unit). theta_o and psi
 * are interpolated here (four fetches), the mirror direction by the texture's filter. The cost
 * does not depend on TF_L_MAX: shading.radiance_grid.build holds the SH sum at every node.
 * The grid holds the World's content (tf_lighting.world: its turn Q and strength, as the
 * prefilter lookup reads them): r and e1 are turned by Q and the sum scaled by the strength.
 * Without TF_RADIANCE_GRID this chunk is empty.
 */

#ifdef TF_RADIANCE_GRID
vec3 tf_grid_fetch(vec2 uv, int layer)
{
  return texture(tf_radiance_grid, vec3(uv, float(layer))).rgb;
}

/* Where a pixel reads the grid: its mirror direction's uv, the view-angle nodes j0, j0 + 1 of
 * view_count and their weight, the azimuths k0, k1 and theirs. */
struct TFGridAt {
  vec2 uv;
  int j0;
  float wj;
  int k0;
  int k1;
  float wk;
};

TFGridAt tf_grid_at(TFFrame f, int view_count)
{
  /* (cos, sin) theta_o, cos >= 0; r = reflect(-v, n) and e1 = d r / d(2 theta_o) in the frame's
   * xz plane (v = cos n + sin x) */
  vec2 cs = tf_safe_normalize2(vec2(max(f.cos_o, 0.0), f.sin_o), vec2(1.0, 0.0));
  vec3 r = cs.x * f.z - cs.y * f.x;
  vec3 e1 = cs.x * f.x + cs.y * f.z;
  vec3 q0 = tf_lighting.world[0].xyz; /* rows of Q: into the content's frame */
  vec3 q1 = tf_lighting.world[1].xyz;
  vec3 q2 = tf_lighting.world[2].xyz;
  r = vec3(dot(q0, r), dot(q1, r), dot(q2, r));
  e1 = vec3(dot(q0, e1), dot(q1, e1), dot(q2, e1));
  float rho = length(r.xy);
  vec2 p = tf_safe_normalize2(r.xy, vec2(1.0, 0.0));
  vec2 uv = vec2(0.5 - atan(r.y, r.x) / (2.0 * TF_PI), acos(clamp(r.z, -1.0, 1.0)) / TF_PI);
  float along = r.z * dot(e1.xy, p) - e1.z * rho; /* e1 . a1 */
  float across = e1.y * p.x - e1.x * p.y;         /* e1 . a2 */

  float views = float(view_count - 1);
  float jp = clamp(atan(cs.y, cs.x) / TF_HALF_PI * views, 0.0, views);
  int j0 = min(int(floor(jp)), view_count - 2);
  float wj = jp - float(j0);
  float kp = atan(across, along) / (2.0 * TF_PI) * float(TF_GRID_AZIMUTHS);
  kp = (kp < 0.0) ? kp + float(TF_GRID_AZIMUTHS) : kp;
  int k0 = min(int(floor(kp)), TF_GRID_AZIMUTHS - 1);
  float wk = kp - float(k0);
  int k1 = (k0 + 1 == TF_GRID_AZIMUTHS) ? 0 : k0 + 1;

  TFGridAt g; /* set field by field: a struct constructor is not portable across backends */
  g.uv = uv;
  g.j0 = j0;
  g.wj = wj;
  g.k0 = k0;
  g.k1 = k1;
  g.wk = wk;
  return g;
}

/* The grid at view node j of the block starting at layer base, between the two azimuths. */
vec3 tf_grid_node(TFGridAt g, int base, int j)
{
  int l = base + j * TF_GRID_AZIMUTHS;
  return mix(tf_grid_fetch(g.uv, l + g.k0), tf_grid_fetch(g.uv, l + g.k1), g.wk);
}

vec3 tf_shade_grid(TFFrame f)
{
  TFGridAt g = tf_grid_at(f, textureSize(tf_radiance_grid, 0).z / TF_GRID_AZIMUTHS);
  return tf_lighting.world[0].w * mix(tf_grid_node(g, 0, g.j0), tf_grid_node(g, 0, g.j0 + 1), g.wj);
}
#endif
