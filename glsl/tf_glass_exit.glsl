#include "tf_refract.glsl"

/* tf_glass_exit.glsl: solid glass leaves through its real mesh (TF_REFRACT with the glass buffers).
 *
 * numpy counterpart: shading.glass.glass_exit (mesh_exit and its helpers). The ray refracted in at the
 * shaded point is marched over the object's spans in the glass buffers until it leaves
 * (tf_glass_march), meets each face as Cycles' smooth glass does (tf_valid_normal, tf_glass_face),
 * reflects totally, and enters a concave glass's further spans again (tf_glass_enter);
 * tf_glass_exit gives where it leaves for good, tf_refract.glsl's march what it sees there.
 */

/* The glass buffers tf_glass_front and tf_glass_back (2D arrays; .xyz the outward normal times
 * (id + 1), .w the depth along the camera axis; 0 where empty) hold the object's TF_GLASS_LAYERS
 * nearest front and back faces per pixel of the drawn window, nearest first: layer k is array
 * layer k (tf_glass_geom the same). */

/* Decode a glass-buffer texel: its object id (-1 where empty), unit normal and depth. */
int tf_glass_decode(vec4 texel, out vec3 normal, out float depth)
{
  float len = length(texel.xyz);
  normal = texel.xyz / max(len, TF_DIVISION_FLOOR);
  depth = texel.w;
  return int(floor(len + 0.5)) - 1;
}

/* Octahedral coordinates -> unit vector (shading.glass.glass_exit.from_octahedral). */
vec3 tf_oct_decode(vec2 e)
{
  vec3 n = vec3(e, 1.0 - abs(e.x) - abs(e.y));
  float t = max(-n.z, 0.0);
  n.x += (n.x >= 0.0) ? -t : t;
  n.y += (n.y >= 0.0) ? -t : t;
  return normalize(n);
}

/* The shading normal Cycles uses for smooth glass (shading.glass.glass_exit.valid_normal, Cycles'
 * ensure_valid_specular_reflection): n where the mirror of wi about it rises at least
 * min(TF_VALID_REFLECTION_SCALE cos, TF_VALID_REFLECTION_RISE) above the face (geometric
 * normal ng, cos = wi . ng), else n turned towards ng in their plane until it rises exactly that
 * much; ng, wi and n face the same side. */
vec3 tf_valid_normal(vec3 ng, vec3 wi, vec3 n)
{
  vec3 mirror = reflect(-wi, n);
  float iz = dot(wi, ng);
  float threshold = min(TF_VALID_REFLECTION_SCALE * iz, TF_VALID_REFLECTION_RISE);
  if (dot(ng, mirror) >= threshold) {
    return n;
  }
  vec3 x = tf_safe_normalize(n - dot(n, ng) * ng, n);
  float ix = dot(wi, x);
  float a = max(ix * ix + iz * iz, TF_DIVISION_FLOOR);
  float b = 2.0 * (a + iz * threshold);
  float c = (threshold + iz) * (threshold + iz);
  float root = sqrt(max(b * b - 4.0 * a * c, 0.0));
  float nz2 = (ix < 0.0) ? 0.25 * (b + root) / a : 0.25 * (b - root) / a;
  return sqrt(max(1.0 - nz2, 0.0)) * x + sqrt(max(nz2, 0.0)) * ng;
}

/* One face met from inside by the unit ray d (outward shading normal face_n, geometric face_g) as
 * Cycles' smooth glass meets it (shading.glass.glass_exit._face_step): the cosine inside, the refracted
 * direction out (0 under total internal reflection), the mirrored one, and whether each is valid
 * (it leaves on its side of the face and of the normal; Cycles ends the path otherwise). */
void tf_glass_face(vec3 d, vec3 face_n, vec3 face_g, float eta, out float cos_face, out vec3 out_dir,
                   out vec3 mirrored, out bool out_ok, out bool mirror_ok)
{
  vec3 g_in = -face_g;
  vec3 n_in = tf_valid_normal(g_in, -d, -face_n);
  cos_face = clamp(-dot(d, n_in), 0.0, 1.0);
  out_dir = refract(d, n_in, eta);
  mirrored = tf_safe_normalize(reflect(d, n_in), d);
  bool facing = dot(n_in, -d) > 0.0;
  out_ok = facing && dot(g_in, out_dir) < 0.0 && dot(n_in, out_dir) < 0.0;
  mirror_ok = facing && dot(g_in, mirrored) > 0.0 && dot(n_in, mirrored) > 0.0;
}

/* The width and height of the glass buffers. */
ivec2 tf_glass_size()
{
  return textureSize(tf_glass_back, 0).xy;
}

/* The glass buffers' cell under world point q (clamped to the picture) and q's depth; false off the
 * picture or behind the camera. */
bool tf_glass_cell(vec3 q, out ivec2 cell, out float z)
{
  mat4 view_proj = mat4(tf_view.view_proj[0], tf_view.view_proj[1], tf_view.view_proj[2], tf_view.view_proj[3]);
  vec4 clip = view_proj * vec4(q, 1.0);
  z = dot(tf_view.camera.xyz - q, tf_view.view_dir.xyz);
  vec2 size = vec2(tf_glass_size());
  vec2 uv = (clip.xy / max(abs(clip.w), TF_DIVISION_FLOOR) * sign(clip.w) * 0.5 + 0.5);
  vec2 at = floor(uv * size);
  cell = ivec2(clamp(at, vec2(0.0), size - 1.0));
  return clip.w > 0.0 && z > 0.0 && all(greaterThanEqual(at, vec2(0.0))) && all(lessThan(at, size));
}

/* Layer k of object own's spans along cell's camera ray (shading.glass.glass_exit._Glass.spans): whether it
 * is one (layer 0: own's back face there; a further layer: own's front and back faces), its front
 * depth (-TF_REFRACT_FAR where the front face there is not own's) and its back depth. */
bool tf_glass_span(ivec2 cell, int k, int own, out float f, out float b)
{
  ivec3 texel = ivec3(cell, k);
  vec3 normal;
  int id_f = tf_glass_decode(texelFetch(tf_glass_front, texel, 0), normal, f);
  int id_b = tf_glass_decode(texelFetch(tf_glass_back, texel, 0), normal, b);
  if (id_f != own) {
    f = -TF_REFRACT_FAR;
  }
  return id_b == own && (k == 0 || id_f == own);
}

/* The normal (and geometric normal) of layer k's back (or front) face at q on cell, q's nearest
 * texel (shading.glass.glass_exit._Glass.face, _blend; tf_glass_geom: .xy the front face's geometric
 * normal, .zw the back face's): bilinear between the four texel centres around
 * q over the texels of the same face (object own's, their normal within TF_GLASS_BLEND_COS of
 * the nearest texel's, their depth within TF_GLASS_BLEND_DEPTH x its depth). */
void tf_glass_face_near(vec3 q, ivec2 cell, int k, bool back, int own, out vec3 face_normal, out vec3 face_geom)
{
  float depth0;
  vec3 nearest;
  tf_glass_decode(back ? texelFetch(tf_glass_back, ivec3(cell, k), 0) : texelFetch(tf_glass_front, ivec3(cell, k), 0),
                  nearest, depth0);
  vec4 geom = texelFetch(tf_glass_geom, ivec3(cell, k), 0);
  face_geom = tf_oct_decode(back ? geom.zw : geom.xy);
  mat4 view_proj = mat4(tf_view.view_proj[0], tf_view.view_proj[1], tf_view.view_proj[2], tf_view.view_proj[3]);
  vec4 clip = view_proj * vec4(q, 1.0);
  vec2 size = vec2(tf_glass_size());
  vec2 at = (clip.xy / max(abs(clip.w), TF_DIVISION_FLOOR) * sign(clip.w) * 0.5 + 0.5) * size - 0.5;
  vec2 base = floor(at);
  vec2 f = at - base;
  vec3 total = vec3(0.0);
  for (int j = 0; j < 4; j++) {
    vec2 step_xy = vec2(float(j & 1), float(j >> 1));
    ivec3 texel = ivec3(ivec2(clamp(base + step_xy, vec2(0.0), size - 1.0)), k);
    vec3 n_j;
    float depth_j;
    int id = tf_glass_decode(back ? texelFetch(tf_glass_back, texel, 0) : texelFetch(tf_glass_front, texel, 0), n_j,
                             depth_j);
    vec2 w = mix(vec2(1.0) - f, f, step_xy);
    if (id == own && dot(n_j, nearest) >= TF_GLASS_BLEND_COS && abs(depth_j - depth0) <= TF_GLASS_BLEND_DEPTH * depth0) {
      total += w.x * w.y * n_j;
    }
  }
  face_normal = tf_safe_normalize(total, nearest);
}

/* The object id in the back buffer's nearest layer under world point q (-1: none or off the
 * picture). */
int tf_glass_id_at(vec3 q)
{
  ivec2 cell;
  float z;
  if (!tf_glass_cell(q, cell, z)) {
    return -1;
  }
  vec3 normal;
  float depth;
  return tf_glass_decode(texelFetch(tf_glass_back, ivec3(cell, 0), 0), normal, depth);
}

/* Whether a fragment of solid glass own at q is drawn: with the glass buffers only its nearest
 * front face (a concave glass's other faces, and every back face, are inside it: the exit ray
 * crosses them); without them (own < 0, or not in the buffers there) every fragment, as before. */
bool tf_glass_nearest_front(vec3 q, int own, bool front_facing)
{
  if (own < 0 || tf_glass_id_at(q) != own) {
    return true;
  }
  if (!front_facing) {
    return false;
  }
  ivec2 cell;
  float z;
  tf_glass_cell(q, cell, z);
  vec3 normal;
  float nearest;
  int id = tf_glass_decode(texelFetch(tf_glass_front, ivec3(cell, 0), 0), normal, nearest);
  return id != own || z <= nearest + TF_GLASS_FRONT_SLACK * z;
}

/* Whether q lies outside every span of object own along its pixel's camera ray
 * (shading.glass.glass_exit._Glass.outside), and the face it lies beyond: the nearest back face it lies
 * behind or front face it lies in front of (layer 0's back face where none: off the object's
 * silhouette): which side and layer, on cell (tf_glass_face_near); inside: q on the picture. */
bool tf_glass_outside(vec3 q, int own, out bool through_back, out int layer, out ivec2 cell, out bool inside)
{
  float z;
  inside = tf_glass_cell(q, cell, z);
  float slack = TF_GLASS_SLACK * z;
  bool within = false, any = false;
  float nearest = 0.0;
  layer = 0;
  through_back = true;
  float fs[TF_GLASS_LAYERS];
  bool spans[TF_GLASS_LAYERS];
  for (int k = 0; k < TF_GLASS_LAYERS; k++) {
    float b;
    spans[k] = tf_glass_span(cell, k, own, fs[k], b);
    if (spans[k]) {
      within = within || (z <= b + slack && z >= fs[k] - slack);
      if (z > b + slack && (!any || z - b < nearest)) {
        any = true;
        nearest = z - b;
        layer = k;
      }
    }
  }
  for (int k = 0; k < TF_GLASS_LAYERS; k++) { /* the fronts after the backs, as numpy's argmin */
    float f = fs[k];
    if (spans[k] && z < f - slack && (!any || f - z < nearest)) {
      any = true;
      nearest = f - z;
      layer = k;
      through_back = false;
    }
  }
  return !within;
}

/* Where o + s d, s in (0, reach], first leaves object own (shading.glass.glass_exit._march_inside):
 * its face read where the exit lies, or, off the object's silhouette there, on the last texel
 * inside (its front or back face, the nearer in depth). */
bool tf_glass_march(vec3 o, vec3 d, float reach, int own, out float s_hit, out vec3 face_normal,
                    out vec3 face_geom)
{
  float lo = 0.0;
  s_hit = 0.0;
  bool found = false;
  bool back, inside;
  int layer;
  ivec2 cell;
  for (int k = 0; k < TF_GLASS_STEPS; k++) {
    float s = reach * float(k + 1) / float(TF_GLASS_STEPS);
    if (tf_glass_outside(o + s * d, own, back, layer, cell, inside) && inside) {
      s_hit = s;
      found = true;
      break;
    }
    lo = s;
  }
  if (!found) {
    return false;
  }
  float hi = s_hit;
  for (int j = 0; j < TF_GLASS_REFINE; j++) {
    float mid = 0.5 * (lo + hi);
    if (tf_glass_outside(o + mid * d, own, back, layer, cell, inside)) {
      hi = mid;
    }
    else {
      lo = mid;
    }
  }
  s_hit = hi;
  tf_glass_outside(o + hi * d, own, back, layer, cell, inside);
  /* a ray that leaves across the silhouette (a rim's face seen edge-on) ends on an empty texel:
   * the face is the one on the last texel inside, its front or back whichever lies nearer in
   * depth */
  vec3 unused_normal;
  float unused_depth;
  ivec3 texel = ivec3(cell, layer);
  if (tf_glass_decode(back ? texelFetch(tf_glass_back, texel, 0) : texelFetch(tf_glass_front, texel, 0), unused_normal,
                      unused_depth) != own)
  {
    float z, unused_z, f, b;
    tf_glass_cell(o + hi * d, cell, z);
    tf_glass_cell(o + lo * d, cell, unused_z);
    tf_glass_decode(texelFetch(tf_glass_front, ivec3(cell, layer), 0), unused_normal, f);
    tf_glass_decode(texelFetch(tf_glass_back, ivec3(cell, layer), 0), unused_normal, b);
    back = abs(z - b) <= abs(z - f);
  }
  tf_glass_face_near(o + hi * d, cell, layer, back, own, face_normal, face_geom);
  return true;
}

/* Whether q lies past the face of layer k of object own that a ray going away from the camera
 * (away) enters through (its front face; else its back face), on q's pixel. */
bool tf_glass_past(vec3 q, int own, int k, bool away)
{
  ivec2 cell;
  float z, f, b;
  tf_glass_cell(q, cell, z);
  float slack = TF_GLASS_SLACK * z;
  return tf_glass_span(cell, k, own, f, b) && (away ? z >= f - slack : z <= b + slack);
}

/* Where o + s d, s in (0, reach], having left object own at o, first enters one of its spans again
 * (shading.glass.glass_exit._march_enter): TF_GLASS_STEPS even steps until it leaves the picture, a step
 * entering span k where it crosses the span's near face on its pixel or lies within it, the entry
 * bisected TF_GLASS_REFINE times against that face; its normal and geometric normal. */
bool tf_glass_enter(vec3 o, vec3 d, float reach, int own, out float s_hit, out vec3 face_normal,
                    out vec3 face_geom)
{
  bool away = dot(d, tf_view.view_dir.xyz) <= 0.0;
  float prev_z = dot(tf_view.camera.xyz - o, tf_view.view_dir.xyz);
  float lo = 0.0;
  int layer = -1;
  s_hit = 0.0;
  for (int k = 0; k < TF_GLASS_STEPS && layer < 0; k++) {
    float s = reach * float(k + 1) / float(TF_GLASS_STEPS);
    ivec2 cell;
    float z;
    if (!tf_glass_cell(o + s * d, cell, z)) {
      return false;
    }
    float slack = TF_GLASS_SLACK * z;
    for (int j = 0; j < TF_GLASS_LAYERS && layer < 0; j++) {
      float f, b;
      if (tf_glass_span(cell, j, own, f, b)) {
        bool crosses = away ? (prev_z < f - slack && z >= f - slack) : (prev_z > b + slack && z <= b + slack);
        if (crosses || (z <= b + slack && z >= f - slack)) {
          layer = j;
          s_hit = s;
        }
      }
    }
    if (layer < 0) {
      lo = s;
      prev_z = z;
    }
  }
  if (layer < 0) {
    return false;
  }
  float hi = s_hit;
  for (int j = 0; j < TF_GLASS_REFINE; j++) {
    float mid = 0.5 * (lo + hi);
    if (tf_glass_past(o + mid * d, own, layer, away)) {
      hi = mid;
    }
    else {
      lo = mid;
    }
  }
  s_hit = hi;
  ivec2 cell;
  float z;
  tf_glass_cell(o + hi * d, cell, z);
  tf_glass_face_near(o + hi * d, cell, layer, !away, own, face_normal, face_geom);
  return true;
}

/* A ray arriving from outside (w: towards where it came from) refracted into glass of index eta
 * at a face of geometric normal g and shading normal n (both facing w) as Cycles' smooth glass
 * refracts it (shading.glass.glass_exit._refract_in): the normal it uses (tf_valid_normal), the
 * direction in, and false where Cycles ends the path (a refraction that does not cross the face). */
bool tf_glass_refract_in(vec3 g, vec3 w, vec3 n, float eta, out vec3 n_valid, out vec3 d_in)
{
  n_valid = tf_valid_normal(g, w, n);
  d_in = tf_safe_normalize(refract(-w, n_valid, 1.0 / max(eta, TF_WALL_GUARD)), -w);
  return dot(g, d_in) < 0.0 && dot(n_valid, w) > 0.0;
}

/* cos theta_t inside glass of index eta of a ray entering at cos_outside (shading.glass.refract.inner_cosine). */
float tf_inner_cosine(float cos_outside, float eta)
{
  float c = clamp(cos_outside, 0.0, 1.0);
  float e = max(eta, TF_WALL_GUARD);
  return sqrt(max(1.0 - (1.0 - c * c) / (e * e), 0.0));
}

/* The film's reflectance seen from inside solid glass of index eta at cos_inside
 * (shading.transmit.back_reflectance): Cycles' back face from row own of tf_glass_film (u uniform
 * 0..1, .a = 1 where the row holds one; linear in u), else the front film at the Snell-related
 * outside cosine (a lossless film reflects the same from both sides), 1 under total internal
 * reflection. */
vec3 tf_glass_back_r(float cos_inside, TFLerp r, float eta, int own)
{
  float c = clamp(cos_inside, 0.0, 1.0);
  ivec2 size = textureSize(tf_glass_film, 0);
  if (own >= 0 && own < size.y && size.x > 1 && texelFetch(tf_glass_film, ivec2(0, own), 0).a > 0.5) {
    float x = c * float(size.x - 1);
    int i0 = clamp(int(floor(x)), 0, size.x - 2);
    float w = x - float(i0);
    return mix(texelFetch(tf_glass_film, ivec2(i0, own), 0).rgb, texelFetch(tf_glass_film, ivec2(i0 + 1, own), 0).rgb, w);
  }
  float e = max(eta, TF_WALL_GUARD);
  float s2 = e * e * (1.0 - c * c);
  if (s2 >= 1.0) {
    return vec3(1.0);
  }
  return clamp(tf_film_white(sqrt(max(1.0 - s2, 0.0)), r), vec3(0.0), vec3(1.0));
}

/* A branch of a glass path: the ray from point along dir, carried carried (0 where none). */
struct TFGlassBranch {
  vec3 point;
  vec3 dir;
  vec3 carried;
};

/* The branch from point along dir, carried carried (its fields set one by one, as the other
 * structs here: no struct constructor). */
TFGlassBranch tf_glass_make_branch(vec3 point, vec3 dir, vec3 carried)
{
  TFGlassBranch b;
  b.point = point;
  b.dir = dir;
  b.carried = carried;
  return b;
}

/* No branch. */
TFGlassBranch tf_glass_no_branch()
{
  return tf_glass_make_branch(vec3(0.0), vec3(0.0, 0.0, 1.0), vec3(0.0));
}

/* The ray o + s d inside object own (index eta, reach its march's reach, carried what it carries so
 * far) until it leaves the object for good (shading.glass.glass_exit._follow): faces met as
 * Cycles' smooth glass meets them (tf_glass_face), total internal reflections followed up to
 * TF_GLASS_BOUNCES faces; reflections: the first that many faces it could leave through reflect
 * it instead (the glints), carried the film's reflectance from inside there (tf_glass_back_r with
 * r); a ray that leaves goes on into a further span of the object (tf_glass_enter, at most
 * TF_GLASS_LAYERS - 1 times: a concave glass), refracted in there, carried the film's
 * transmittance out and in. Where it first enters again the film's mirror there is branched off
 * (mirror: in the air, a bowl's far wall seen from inside it), and where it then leaves, the
 * film's reflection back inside (inner: that wall's outer face seen from inside the glass).
 * carried 0 on a path that does not leave within TF_GLASS_BOUNCES faces (Cycles' bounce limit
 * ends it) and on any path Cycles ends (a direction on the wrong side of a face, in or out).
 * cosines: inside the glass at the first face met and at the face it leaves through (1 where it
 * never leaves). False where the first march meets no face (the caller's fallback). */
bool tf_glass_follow(vec3 o, vec3 d, float reach, float eta, int own, int reflections, TFLerp r, inout vec3 carried,
                     out vec3 exit_point, out vec3 dir, out vec2 cosines, out TFGlassBranch mirror,
                     out TFGlassBranch inner)
{
  float e = max(eta, TF_WALL_GUARD);
  mirror = tf_glass_no_branch();
  inner = tf_glass_no_branch();
  exit_point = o;
  dir = d;
  cosines = vec2(1.0);
  bool first = true;
  float cos_first = 1.0;
  int chosen = 0;
  int entries = 0;
  for (int bounce = 0; bounce < TF_GLASS_BOUNCES; bounce++) {
    float s;
    vec3 face_n, face_g;
    if (!tf_glass_march(o, d, reach, own, s, face_n, face_g)) {
      if (bounce == 0) {
        return false;
      }
      break;
    }
    o = o + s * d;
    float cos_face;
    vec3 out_dir, mirrored;
    bool out_ok, mirror_ok;
    tf_glass_face(d, face_n, face_g, e, cos_face, out_dir, mirrored, out_ok, mirror_ok);
    if (first) {
      cos_first = cos_face;
    }
    bool tir = dot(out_dir, out_dir) < TF_TIR_EPS;
    if (!tir && chosen >= reflections) {
      vec3 out_n = tf_safe_normalize(out_dir, d);
      float s_in;
      vec3 in_n, in_g;
      /* out into the air: on into a further span of the object, refracted in as at the entry */
      if (out_ok && entries < TF_GLASS_LAYERS - 1 && tf_glass_enter(o, out_n, reach, own, s_in, in_n, in_g) &&
          dot(in_g, -out_n) > 0.0)
      {
        vec3 n_in, d_in;
        bool kept = tf_glass_refract_in(in_g, -out_n, in_n, e, n_in, d_in);
        entries++;
        o = o + s_in * out_n;
        if (!kept) { /* Cycles ends it */
          exit_point = o;
          dir = d_in;
          cosines = vec2(cos_first, 1.0);
          carried = vec3(0.0);
          return true;
        }
        vec3 r_out = tf_glass_back_r(cos_face, r, eta, own);
        vec3 r_in = clamp(tf_film_white(clamp(dot(-out_n, n_in), 0.0, 1.0), r), vec3(0.0), vec3(1.0));
        carried *= vec3(1.0) - r_out;
        if (entries == 1) { /* the mirror branch where it first enters again (a bowl's far wall) */
          mirror = tf_glass_make_branch(o, reflect(out_n, n_in), carried * r_in);
        }
        carried *= vec3(1.0) - r_in;
        d = d_in;
        first = false;
        continue;
      }
      exit_point = o;
      dir = out_n;
      cosines = vec2(cos_first, cos_face);
      if (!out_ok) {
        dir = d;
        carried = vec3(0.0);
      }
      else if (entries == 1 && mirror_ok) { /* the far wall's reflection back inside where it leaves */
        inner = tf_glass_make_branch(o, mirrored, carried * tf_glass_back_r(cos_face, r, eta, own));
      }
      return true;
    }
    if (!mirror_ok) {
      exit_point = o;
      dir = d;
      cosines = vec2(cos_first, 1.0);
      carried = vec3(0.0);
      return true;
    }
    if (!tir) { /* reflected by choice: a glint's path */
      carried *= tf_glass_back_r(cos_face, r, eta, own);
      chosen++;
    }
    d = mirrored;
    first = false;
  }
  exit_point = o;
  dir = d;
  cosines = vec2(cos_first, 1.0);
  carried = vec3(0.0); /* not left within TF_GLASS_BOUNCES faces: none (Cycles' bounce limit ends it) */
  return true;
}

/* The exit point and direction of the ray from the viewer (v) entering glass of index eta at p
 * (normal n, geometric normal g, both facing the viewer) and leaving object own through its real
 * faces (shading.glass.glass_exit.mesh_exit): refracted in as Cycles' smooth glass refracts it,
 * then followed (tf_glass_follow: reflections, carried, cosines, mirror and inner as there). False
 * where the buffers do not hold the object (the sphere about c stands in, tf_solid_exit_ray;
 * both cosines its cos theta_t). */
bool tf_glass_exit(vec3 p, vec3 n, vec3 g, vec3 v, vec3 c, float eta, int own, int reflections, TFLerp r,
                   out vec3 exit_point, out vec3 dir, out vec2 cosines, out vec3 carried, out TFGlassBranch mirror,
                   out TFGlassBranch inner)
{
  float e = max(eta, TF_WALL_GUARD);
  cosines = vec2(tf_inner_cosine(dot(n, v), e));
  carried = vec3(1.0);
  mirror = tf_glass_no_branch();
  inner = tf_glass_no_branch();
  if (own < 0 || tf_glass_id_at(p) != own) { /* the object is not in the buffers at its entry */
    tf_solid_exit_ray(p, n, v, c, eta, exit_point, dir);
    return false;
  }
  vec3 n_entry, d;
  if (!tf_glass_refract_in(g, v, n, e, n_entry, d)) { /* Cycles ends a refraction that does not go in */
    exit_point = p;
    dir = d;
    carried = vec3(0.0);
    return true;
  }
  float reach = TF_GLASS_REACH * max(length(p - c), TF_WALL_GUARD);
  vec2 traced;
  if (!tf_glass_follow(p, d, reach, eta, own, reflections, r, carried, exit_point, dir, traced, mirror, inner)) {
    tf_solid_exit_ray(p, n, v, c, eta, exit_point, dir);
    carried = vec3(1.0);
    return false;
  }
  cosines = traced;
  return true;
}
