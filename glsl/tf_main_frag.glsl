#include "tf_shade.glsl"
#include "tf_display.glsl"

/* tf_main_frag.glsl: shade a mesh fragment.
 *
 * numpy counterpart: shading.sh_sum.shade_sh (via tf_shade) with image_io.srgb_encode for display.
 * v = normalize(camera - position) in perspective, the constant direction towards the viewer
 * in orthographic views (tf_view.camera.w = 1); the normal is flipped to face the viewer
 * (two-sided). Output: scene-linear RGB, or with TF_DISPLAY_SRGB: 2^exposure, clamp, OETF (with
 * TF_DISPLAY_LUT: 2^exposure, the scene's view through tf_display.glsl).
 * A transparent film (TF_TRANSMIT, tf_transmit.glsl) is drawn in two blend passes: pass 1 writes
 * (T, mean T) for a multiply blend, pass 2 (S R L, 1 - mean T) for an additive one
 * (addon/gpu/draw.py); alpha ends as 1 - (1 - alpha_behind) mean T.
 * Solid glass with TF_REFRACT sees the scene behind along its exit ray (tf_refract.glsl). A closed
 * thin wall's far side adds its reflections inside (tf_wall_inside, shading.transmit; TF_SPLIT_SUM).
 * tf_lamps.glsl (TF_LAMPS), tf_lights.glsl (TF_LIGHTS), tf_split_sum.glsl (TF_SPLIT_SUM) and
 * tf_glass_exit.glsl with tf_refract.glsl (TF_REFRACT) are joined before this chunk for the
 * variants that have them (addon/gpu/shaders.py). With TF_THICKNESS_MAP the thickness parameter
 * is read per pixel from tf_thickness_map at the interpolated UV tf_uv (bilinear, numpy:
 * thickness.maps.sample_bilinear), with TF_THICKNESS_NOISE computed from the object-space position
 * (tf_noise.glsl, tf_perlin.glsl), else interpolated from the corners (tf_thickness).
 */

#if defined(TF_TRANSMIT) && defined(TF_SPLIT_SUM)
/* Solid glass's one reflection inside: T r times the World along tf_solid_internal, T = (1 - r)^2
 * (shading.transmit.solid_internal). */
vec3 tf_solid_glint(vec3 n, vec3 v, vec3 wall_t)
{
  vec3 unused_moment;
  float unused_weight;
  vec3 r = vec3(1.0) - sqrt(max(wall_t, vec3(0.0)));
  return wall_t * r *
         tf_prefiltered_lookup(tf_solid_internal(n, v, tf_object.material.w), 0.0, unused_moment, unused_weight);
}
#endif

#if defined(TF_TRANSMIT) && TF_TRANSMIT == 2 && defined(TF_SPLIT_SUM)
/* A thin wall's thickness parameter at world point p: the mesh's linear fit (shading.transmit.world_fit). */
float tf_inside_thickness(vec3 p)
{
#ifdef TF_VARY_THICKNESS
  return clamp(dot(tf_object.fit.xyz, p) + tf_object.fit.w, 0.0, 1.0);
#else
  return 0.0;
#endif
}

/* A closed thin wall's far side (shading.transmit.inside_reflections): its reflection along
 * reflect(-v, n) leaves through the wall it meets next (exit_t, T2) and is reflected on inside,
 * TF_INSIDE_ORDERS times: returns sum_k (R2..Rk) T(k+1) L(d_k), L the World prefiltered at the film's
 * roughness; exit_t 1 and nothing more where the ray does not enter the sphere. */
vec3 tf_wall_inside(vec3 n, vec3 v, out vec3 exit_t)
{
  vec3 p = tf_world_pos;
  vec3 d = reflect(-v, n);
  vec3 centre = tf_object.model[3].xyz;
  vec3 tint = tf_object.glass.yzw;
  float mode = tf_object.material.z;
  float eta = tf_object.material.w;
  float cos_hit;
  tf_inside_step(p, d, centre, cos_hit);
  exit_t = vec3(1.0);
  if (cos_hit <= 0.0) {
    return vec3(0.0);
  }
  vec3 refl, t_next;
  tf_wall_rt(cos_hit, tf_inside_thickness(p), mode, eta, tint, refl, exit_t);
  vec3 carried = vec3(1.0);
  vec3 extra = vec3(0.0);
  for (int k = 0; k < TF_INSIDE_ORDERS; k++) {
    vec3 along = d;
    carried *= refl;
    tf_inside_step(p, d, centre, cos_hit);
    tf_wall_rt(cos_hit, tf_inside_thickness(p), mode, eta, tint, refl, t_next);
    vec3 unused_moment;
    float unused_weight;
    extra += carried * t_next * tf_prefiltered_lookup(along, tf_object.material.x, unused_moment, unused_weight);
  }
  return extra;
}
#endif

#ifdef TF_REFRACT
/* Solid glass's id in the glass buffers (-1: none). */
int tf_glass_own()
{
  return int(floor(tf_object.glass.x + 0.5));
}

/* What the ray from o along dir sees: the scene behind where it meets it, else the scene around
 * the glass where the probe shows it (tf_probe_seen), else the World along it (TF_SPLIT_SUM) with
 * the lamps in its tails (tf_lamp_tails: a rough glass path that entered at p and spreads spread;
 * vec2(0.0): none), else nothing. */
vec3 tf_refract_seen(vec3 o, vec3 dir, vec3 p, vec2 spread)
{
  vec3 colour;
  if (tf_refract_march(o, dir, colour) || tf_probe_seen(o, dir, colour)) {
    return colour;
  }
#ifdef TF_SPLIT_SUM
  vec3 unused_moment;
  float unused_weight;
  return tf_prefiltered_lookup(dir, 0.0, unused_moment, unused_weight) + tf_lamp_tails(p, o, dir, spread);
#else
  return vec3(0.0);
#endif
}

/* What a branch of solid glass own's path sees (tf_glass_follow's mirror and inner), times what it
 * carries (shading.glass.glass_exit.branch_exit): inner, inside the glass, is followed until it
 * leaves; mirror, in the air, enters the object where it meets it again (a bowl's near wall, from
 * behind), through the film there, and is followed; each out through the film, seeing the scene
 * where it meets it, else the World (tf_refract_seen). A mirror that meets the object no more
 * sees along its ray, as does one whose march meets no face; an inner one then sees nothing. */
vec3 tf_glass_branch(TFGlassBranch b, bool in_air, TFLerp r)
{
  if (!any(greaterThan(b.carried, vec3(0.0)))) {
    return vec3(0.0);
  }
  int own = tf_glass_own();
  float eta = tf_object.material.w;
  float reach = TF_GLASS_REACH * max(length(b.point - tf_object.model[3].xyz), TF_WALL_GUARD);
  vec3 o = b.point, d = b.dir, carried = b.carried;
  if (in_air) {
    float s_in;
    vec3 in_n, in_g;
    if (!tf_glass_enter(o, d, reach, own, s_in, in_n, in_g) || dot(in_g, -d) <= 0.0) {
      return carried * tf_refract_seen(o, d, o, vec2(0.0));
    }
    vec3 n_in, d_in;
    if (!tf_glass_refract_in(in_g, -d, (dot(in_n, -d) < 0.0) ? -in_n : in_n, eta, n_in, d_in)) {
      return vec3(0.0); /* Cycles ends it */
    }
    carried *= vec3(1.0) - clamp(tf_film_white(clamp(dot(-d, n_in), 0.0, 1.0), r), vec3(0.0), vec3(1.0));
    o += s_in * d;
    d = d_in;
  }
  vec3 exit_point, dir;
  vec2 cosines;
  TFGlassBranch unused_mirror, unused_inner;
  if (!tf_glass_follow(o, d, reach, eta, own, 0, r, carried, exit_point, dir, cosines, unused_mirror, unused_inner)) {
    return in_air ? b.carried * tf_refract_seen(b.point, b.dir, b.point, vec2(0.0)) : vec3(0.0);
  }
  vec3 seen = tf_refract_seen(exit_point, dir, exit_point, vec2(0.0)); /* the branches' tails: not drawn */
  return carried * (vec3(1.0) - tf_glass_back_r(cosines.y, r, eta, own)) * seen;
}

/* What solid glass shows behind it (tf_refract.glsl, tf_glass_exit.glsl): the scene behind where
 * the exit ray (through the real mesh, tf_glass_exit, else the sphere about the origin) hits it,
 * else the World along the ray (TF_SPLIT_SUM: the prefiltered World's sharpest level, and its
 * lamps in the rough path's tails, tf_lamp_tails), else the scene straight behind the pixel, times
 * what the path carries (0 where Cycles ends it); g: the face's geometric normal; cosines: inside
 * the glass at the first face and the face it leaves through; side: what the film reflects where
 * the ray enters the glass again and leaves it (a wine glass's far wall: its mirror in the bowl, its
 * reflection inside; tf_glass_branch). */
vec3 tf_refracted(vec3 n, vec3 g, vec3 v, TFLerp r, out vec2 cosines, out vec3 side)
{
  vec3 exit_point, dir, carried;
  TFGlassBranch mirror, inner;
  tf_glass_exit(tf_world_pos, n, g, v, tf_object.model[3].xyz, tf_object.material.w, tf_glass_own(), 0, r,
                exit_point, dir, cosines, carried, mirror, inner);
  side = tf_glass_branch(mirror, true, r) + tf_glass_branch(inner, false, r);
#ifdef TF_SPLIT_SUM
  vec2 spread = tf_glass_spread(dot(n, v), cosines.y, tf_object.material.w, 0);
  return carried * tf_refract_seen(exit_point, dir, tf_world_pos, spread);
#else
  vec3 colour;
  if (tf_refract_march(exit_point, dir, colour)) {
    return carried * colour;
  }
  ivec2 texel;
  float unused_depth;
  tf_refract_sample(tf_world_pos, texel, unused_depth);
  return carried * texelFetch(tf_behind, texel, 0).rgb;
#endif
}
#endif

#if defined(TF_REFRACT) && defined(TF_SPLIT_SUM)
/* Solid glass's reflections inside, the glints (shading.transmit.solid_glint for one): in through
 * the film (t_in), reflected back inside by it at the first k faces the ray could leave through
 * (k = 1 .. TF_GLASS_ORDERS; faces that reflect totally do so on every path), out through it at
 * the next, times what the ray that leaves sees: the scene behind where it meets it
 * (tf_refract_march), else the World along it (tf_glass_exit with k reflections). Where the
 * buffers do not hold the object, the sphere's one reflection inside (tf_solid_internal) stands
 * in, seeing the World. */
vec3 tf_glass_glint(vec3 n, vec3 g, vec3 v, vec3 t_in, TFLerp r)
{
  int own = tf_glass_own();
  float eta = tf_object.material.w;
  vec3 unused_moment;
  float unused_weight;
  vec3 total = vec3(0.0);
  for (int k = 1; k <= TF_GLASS_ORDERS; k++) {
    vec3 exit_point, dir, carried;
    vec2 cosines;
    TFGlassBranch unused_mirror, unused_inner;
    if (!tf_glass_exit(tf_world_pos, n, g, v, tf_object.model[3].xyz, eta, own, k, r, exit_point, dir, cosines,
                       carried, unused_mirror, unused_inner)) {
      vec3 r_in = tf_glass_back_r(cosines.x, r, eta, own);
      return t_in * r_in * (vec3(1.0) - r_in) *
             tf_prefiltered_lookup(tf_solid_internal(n, v, eta), 0.0, unused_moment, unused_weight);
    }
    vec3 seen = tf_refract_seen(exit_point, dir, tf_world_pos, tf_glass_spread(dot(n, v), cosines.y, eta, k));
    total += carried * (vec3(1.0) - tf_glass_back_r(cosines.y, r, eta, own)) * seen;
  }
  return t_in * total;
}

/* Smooth solid glass reflects the scene behind where its mirror ray meets it (else the scene
 * around it where the probe shows it), in place of the World: w r (scene - World) along
 * reflect(-v, n), r = 1 - sqrt(T), w falling from 1 at roughness 0 to 0 at
 * TF_REFRACT_MIRROR_ROUGHNESS (shading.glass.refract.mirror_weight). */
vec3 tf_scene_mirror(vec3 n, vec3 v, vec3 wall_t)
{
  float w = clamp(1.0 - tf_object.material.x / TF_REFRACT_MIRROR_ROUGHNESS, 0.0, 1.0);
  vec3 mirror = reflect(-v, n);
  vec3 scene;
  if (w <= 0.0 || !(tf_refract_march(tf_world_pos, mirror, scene) || tf_probe_seen(tf_world_pos, mirror, scene))) {
    return vec3(0.0);
  }
  vec3 unused_moment;
  float unused_weight;
  vec3 world = tf_prefiltered_lookup(mirror, 0.0, unused_moment, unused_weight);
  return w * (vec3(1.0) - sqrt(max(wall_t, vec3(0.0)))) * (scene - world);
}
#endif

void main()
{
#ifdef TF_REFRACT
  /* the face's own (flat) normal, taken before anything can leave the quad's control flow */
  vec3 face_g = cross(dFdx(tf_world_pos), dFdy(tf_world_pos));
  if (tf_object.material.z > 1.5 && !tf_glass_nearest_front(tf_world_pos, tf_glass_own(), gl_FrontFacing)) {
    discard; /* solid glass is its nearest front face, the rest is inside it (tf_glass_exit) */
  }
#endif
  vec3 toward_viewer = tf_view.view_dir.xyz;
  vec3 v = (tf_view.camera.w > 0.5) ? toward_viewer :
                                      tf_safe_normalize(tf_view.camera.xyz - tf_world_pos, toward_viewer);
  vec3 n = tf_safe_normalize(tf_world_nor, v);
  if (dot(n, v) < 0.0) {
    n = -n;
  }
#ifdef TF_REFRACT
  vec3 g = n; /* solid glass: its face's own normal, facing the viewer */
  if (tf_object.material.z > 1.5) { /* the normal Cycles shades it with (tf_valid_normal) */
    g = tf_safe_normalize(face_g, n);
    g = (dot(g, v) < 0.0) ? -g : g;
    vec3 smooth_n = tf_safe_normalize(tf_world_nor, v);
    n = tf_valid_normal(g, v, (dot(smooth_n, g) < 0.0) ? -smooth_n : smooth_n);
  }
#endif
#if defined(TF_THICKNESS_PERLIN)
  /* a Noise Texture per pixel (tf_perlin.glsl): the Blender Noise source, or a linked one */
  float thickness01 = tf_noise_texture(tf_object_pos);
#elif defined(TF_THICKNESS_NOISE)
  /* the Noise source per pixel at the object-space position (tf_noise.glsl) */
  float thickness01 = tf_value_noise(tf_object_pos, tf_object.noise.x, int(tf_object.noise.y));
#elif defined(TF_THICKNESS_MAP)
  /* the thickness parameter per pixel from the film's thickness map at the mesh's UVs
   * (addon/thickness/maps.py: a texture's detail between the mesh's corners) */
  float thickness01 = clamp(texture(tf_thickness_map, tf_uv).r, 0.0, 1.0);
#elif defined(TF_VARY_THICKNESS)
  float thickness01 = tf_thickness;
#else
  float thickness01 = 0.0;
#endif
#ifdef TF_TRANSMIT /* a transparent film's wall (tf_transmit.glsl, shading.transmit.shade) */
  TFFrame fw = tf_view_aligned_frame(n, v);
  vec3 wall_t, wall_s;
  vec3 tint = tf_object.glass.yzw; /* the transmission tint: Principled Base Color, else 1 */
  TFLerp r_wall = tf_table_lerp(fw.cos_o, fw.sin_o, thickness01);
  tf_wall(fw.cos_o, r_wall, tf_object.material.z, tf_object.material.w, tint, wall_t, wall_s);
  /* solid glass tints what passes in and out (sqrt(tint) each, Cycles); its wall_t stays (1 - r)^2 */
  vec3 through = (tf_object.material.z > 1.5) ? tint : vec3(1.0);
  float wall_mean = dot(wall_t * through, vec3(1.0 / 3.0));
#if TF_TRANSMIT == 1 /* the multiply pass: what is behind times T; alpha times mean(T) */
  wall_t *= through;
#if defined(TF_SPLIT_SUM) || defined(TF_REFRACT)
  if (tf_object.material.z > 1.5) { /* solid glass: what the exit ray sees replaces it */
    wall_t = vec3(0.0);
    wall_mean = 0.0;
  }
#endif
#ifdef TF_DISPLAY_SRGB
  wall_t = tf_srgb_oetf(clamp(wall_t, 0.0, 1.0)); /* encode(T x) ~ encode(T) encode(x) */
#endif
  tf_frag_color = vec4(wall_t, wall_mean);
  return;
#endif
#endif
#ifdef TF_SPLIT_SUM
  vec3 rgb = tf_shade_combined(n, v, thickness01, tf_object.material.x, tf_object.material.y);
#else
  TFFrame f = tf_view_aligned_frame(n, v);
  TFLerp r = tf_table_lerp(f.cos_o, f.sin_o, thickness01);
  vec3 rgb = tf_shade_at(f, r);
#ifdef TF_LAMPS
  rgb += tf_shade_lamps(f, r, n, v, tf_object.material.x); /* shading.lamps.shade */
#endif
#endif
#ifdef TF_LIGHTS
  { /* Blender's light objects: shading.lights.shade */
    TFFrame fl = tf_view_aligned_frame(n, v);
    TFLerp rl = tf_table_lerp(fl.cos_o, fl.sin_o, thickness01);
    rgb += tf_shade_lights(fl, rl, tf_world_pos, n, v, tf_object.material.x);
  }
#endif
#if defined(TF_TRANSMIT) && TF_TRANSMIT == 2 /* the add pass: R L; alpha plus 1 - mean(T) */
  rgb *= wall_s;
#ifdef TF_SPLIT_SUM
  /* a closed thin wall's far side (its normal turned from the viewer): on through the next wall,
   * and reflected on inside (shading.transmit) */
  if (tf_object.material.z < 1.5 && tf_object.inside.x > 0.5 && dot(tf_world_nor, v) < 0.0) {
    vec3 exit_t;
    vec3 extra = tf_wall_inside(n, v, exit_t);
    vec3 r_far = wall_s * clamp(tf_film_white(fw.cos_o, r_wall), vec3(0.0), vec3(1.0)); /* R = S r */
    rgb = rgb * exit_t + r_far * extra;
  }
#endif
#ifdef TF_REFRACT
  if (tf_object.material.z > 1.5) { /* solid glass: in and out through the film along the exit ray */
    vec3 t_in = sqrt(max(wall_t, vec3(0.0))); /* wall_t = (1 - r)^2 */
    vec2 cosines;
    vec3 side;
    vec3 seen = tf_refracted(n, g, v, r_wall, cosines, side);
    vec3 r_out = tf_glass_back_r(cosines.y, r_wall, tf_object.material.w, tf_glass_own());
    rgb += through * t_in * ((vec3(1.0) - r_out) * seen + side);
#ifdef TF_SPLIT_SUM
    rgb += through * tf_glass_glint(n, g, v, t_in, r_wall);
    rgb = max(rgb + tf_scene_mirror(n, v, wall_t), vec3(0.0));
#endif
    wall_mean = 0.0;
  }
#elif defined(TF_SPLIT_SUM)
  if (tf_object.material.z > 1.5) { /* solid glass: T times the World along the exit ray */
    vec3 unused_moment;
    float unused_weight;
    rgb += through * wall_t *
           tf_prefiltered_lookup(tf_solid_exit(n, v, tf_object.material.w), 0.0, unused_moment, unused_weight);
    rgb += through * tf_solid_glint(n, v, wall_t);
    wall_mean = 0.0;
  }
#endif
  float alpha = 1.0 - wall_mean;
#else
  float alpha = 1.0;
#endif
#ifdef TF_DISPLAY_LUT
  rgb = tf_display_lut_apply(rgb * tf_view.params.x); /* the scene's view: display_lut.apply */
#elif defined(TF_DISPLAY_SRGB)
  rgb = tf_srgb_oetf(clamp(rgb * tf_view.params.x, 0.0, 1.0));
#endif
  tf_frag_color = vec4(rgb, alpha);
}
