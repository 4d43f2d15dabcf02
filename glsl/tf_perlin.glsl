/* tf_perlin.glsl: a Noise Texture per pixel (TF_THICKNESS_PERLIN): the Blender Noise thickness
 * source, and a Noise Texture linked into a Principled BSDF's Thin Film Thickness.
 *
 * numpy counterpart: materials.perlin (NoiseSpec, noise_texture, fbm, perlin, hash3, hash4):
 * Blender's Noise Texture, fBm, normalized. Gradient noise on the 3-D or 4-D integer lattice,
 * each point's gradient picked by Bob Jenkins' lookup3 hash of its coordinates (wrapping uint
 * arithmetic), blended with the quintic fade, scaled by 0.9820 (3-D) or 0.8344 (4-D). float32
 * as numpy's mirror computes it. Uniforms: tf_object's noise members (addon/gpu/layout.py).
 */

uint tf_perlin_rot(uint x, uint k)
{
  return (x << k) | (x >> (32u - k));
}

/* Half of lookup3's mix: three subtract-xor-rotate steps with the rotations r. */
void tf_perlin_mix3(inout uint a, inout uint b, inout uint c, uvec3 r)
{
  a = (a - c) ^ tf_perlin_rot(c, r.x);
  c += b;
  b = (b - a) ^ tf_perlin_rot(a, r.y);
  a += c;
  c = (c - b) ^ tf_perlin_rot(b, r.z);
  b += a;
}

/* lookup3's final avalanche of (a, b, c): its c (materials.perlin._final). */
uint tf_perlin_final(uint a, uint b, uint c)
{
  c = (c ^ b) - tf_perlin_rot(b, 14u);
  a = (a ^ c) - tf_perlin_rot(c, 11u);
  b = (b ^ a) - tf_perlin_rot(a, 25u);
  c = (c ^ b) - tf_perlin_rot(b, 16u);
  a = (a ^ c) - tf_perlin_rot(c, 4u);
  b = (b ^ a) - tf_perlin_rot(a, 14u);
  c = (c ^ b) - tf_perlin_rot(b, 24u);
  return c;
}

/* lookup3's hashword of the four lattice coordinates (materials.perlin.hash4). */
uint tf_perlin_hash(uvec4 k)
{
  uint start = 0xDEADBEEFu + 29u; /* 0xdeadbeef + (4 << 2) + 13 */
  uint a = k.x + start;
  uint b = k.y + start;
  uint c = k.z + start;
  tf_perlin_mix3(a, b, c, uvec3(4u, 6u, 8u)); /* mix */
  tf_perlin_mix3(a, b, c, uvec3(16u, 19u, 4u));
  a += k.w;
  return tf_perlin_final(a, b, c);
}

/* The lattice corner c + d's gradient dotted with the position f - d in the cell. */
float tf_perlin_corner(uvec4 c, vec4 f, uvec4 d)
{
  uint h = tf_perlin_hash(c + d) & 31u;
  vec4 q = f - vec4(d);
  float u = (h < 24u) ? q.x : q.y;
  float v = (h < 16u) ? q.y : q.z;
  float s = (h < 8u) ? q.z : q.w;
  return (((h & 1u) != 0u) ? -u : u) + (((h & 2u) != 0u) ? -v : v) + (((h & 4u) != 0u) ? -s : s);
}

/* The eight corners with w-offset dw, blended over x, y and z. */
float tf_perlin_cube(uvec4 c, vec4 f, vec4 t, uint dw)
{
  float x00 = mix(tf_perlin_corner(c, f, uvec4(0u, 0u, 0u, dw)), tf_perlin_corner(c, f, uvec4(1u, 0u, 0u, dw)), t.x);
  float x10 = mix(tf_perlin_corner(c, f, uvec4(0u, 1u, 0u, dw)), tf_perlin_corner(c, f, uvec4(1u, 1u, 0u, dw)), t.x);
  float x01 = mix(tf_perlin_corner(c, f, uvec4(0u, 0u, 1u, dw)), tf_perlin_corner(c, f, uvec4(1u, 0u, 1u, dw)), t.x);
  float x11 = mix(tf_perlin_corner(c, f, uvec4(0u, 1u, 1u, dw)), tf_perlin_corner(c, f, uvec4(1u, 1u, 1u, dw)), t.x);
  return mix(mix(x00, x10, t.y), mix(x01, x11, t.y), t.z);
}

/* Signed 4-D gradient noise scaled as Blender's (materials.perlin.perlin). */
float tf_perlin(vec4 p)
{
  vec4 cell = floor(p);
  vec4 f = p - cell;
  vec4 t = f * f * f * (f * (f * 6.0 - 15.0) + 10.0);
  uvec4 c = uvec4(ivec4(cell));
  return 0.8344 * mix(tf_perlin_cube(c, f, t, 0u), tf_perlin_cube(c, f, t, 1u), t.w);
}

/* lookup3's hashword of three lattice coordinates: the final alone (materials.perlin.hash3). */
uint tf_perlin_hash3(uvec3 k)
{
  uint start = 0xDEADBEEFu + 25u; /* 0xdeadbeef + (3 << 2) + 13 */
  uint a = k.x + start;
  uint b = k.y + start;
  uint c = k.z + start;
  return tf_perlin_final(a, b, c);
}

/* A 3-D lattice corner c + d's gradient (Perlin's 12 edges) dotted with f - d. */
float tf_perlin_corner3(uvec3 c, vec3 f, uvec3 d)
{
  uint h = tf_perlin_hash3(c + d) & 15u;
  vec3 q = f - vec3(d);
  float u = (h < 8u) ? q.x : q.y;
  float v = (h < 4u) ? q.y : (((h == 12u) || (h == 14u)) ? q.x : q.z);
  return (((h & 1u) != 0u) ? -u : u) + (((h & 2u) != 0u) ? -v : v);
}

/* Signed 3-D gradient noise scaled as Blender's (materials.perlin.perlin of (N, 3) points). */
float tf_perlin3(vec3 p)
{
  vec3 cell = floor(p);
  vec3 f = p - cell;
  vec3 t = f * f * f * (f * (f * 6.0 - 15.0) + 10.0);
  uvec3 c = uvec3(ivec3(cell));
  float x00 = mix(tf_perlin_corner3(c, f, uvec3(0u, 0u, 0u)), tf_perlin_corner3(c, f, uvec3(1u, 0u, 0u)), t.x);
  float x10 = mix(tf_perlin_corner3(c, f, uvec3(0u, 1u, 0u)), tf_perlin_corner3(c, f, uvec3(1u, 1u, 0u)), t.x);
  float x01 = mix(tf_perlin_corner3(c, f, uvec3(0u, 0u, 1u)), tf_perlin_corner3(c, f, uvec3(1u, 0u, 1u)), t.x);
  float x11 = mix(tf_perlin_corner3(c, f, uvec3(0u, 1u, 1u)), tf_perlin_corner3(c, f, uvec3(1u, 1u, 1u)), t.x);
  return 0.9820 * mix(mix(x00, x10, t.y), mix(x01, x11, t.y), t.z);
}

/* One octave: 3-D noise of p.xyz, or 4-D of p where four dimensions. */
float tf_perlin_octave(vec4 p, bool four)
{
  return four ? tf_perlin(p) : tf_perlin3(p.xyz);
}

/* A Noise Texture's Fac, normalized fBm (materials.perlin.fbm): floor(detail) + 1 octaves at
 * frequencies lacunarity^i with amplitudes roughness^i, the fraction of detail blending one more. */
float tf_fbm(vec4 p, bool four, float detail, float roughness, float lacunarity)
{
  float frequency = 1.0;
  float amplitude = 1.0;
  float weight = 0.0;
  float total = 0.0;
  int octaves = int(detail);
  for (int i = 0; i <= octaves; i++) {
    total += amplitude * tf_perlin_octave(frequency * p, four);
    weight += amplitude;
    amplitude *= roughness;
    frequency *= lacunarity;
  }
  float value = 0.5 * total / weight + 0.5;
  float rest = detail - float(octaves);
  if (rest > 0.0) {
    float more = total + amplitude * tf_perlin_octave(frequency * p, four);
    value = mix(value, 0.5 * more / (weight + amplitude) + 0.5, rest);
  }
  return value;
}

#ifdef TF_THICKNESS_RAMP
/* A Color Ramp at fac as Cycles reads it (materials.ramp.lookup): its table (the luminance of
 * its Color, or its Alpha, at 0, 1/256, ..., 1) at fac clamped to [0, 1] times 256, the entry at
 * the integer part blended with the next by the fraction unless the ramp is Constant
 * (tf_object.noise.z 0). */
float tf_ramp(float fac)
{
  int last = textureSize(tf_thickness_ramp, 0).x - 1;
  float f = clamp(fac, 0.0, 1.0) * float(last);
  int i = clamp(int(f), 0, last);
  float t = f - float(i);
  float a = texelFetch(tf_thickness_ramp, ivec2(i, 0), 0).r;
  if (tf_object.noise.z > 0.5 && t > 0.0) {
    a = mix(a, texelFetch(tf_thickness_ramp, ivec2(min(i + 1, last), 0), 0).r, t);
  }
  return a;
}
#endif

/* The thickness parameter in [0, 1] of the item's Noise Texture at object-space point pos
 * (materials.perlin.NoiseSpec.parameter): tf_object.noise (x scale, y w, w distortion), noise_fbm (detail,
 * roughness, lacunarity, dimensions), noise_space_x/y/z / noise_offset (its coordinates from
 * pos: a matrix's rows and an offset),
 * noise_map (gain, bias, low, high: Fac, or with TF_THICKNESS_RAMP a Color Ramp's value at it,
 * to the parameter). */
float tf_noise_texture(vec3 pos)
{
  vec3 v = vec3(dot(tf_object.noise_space_x.xyz, pos),
                dot(tf_object.noise_space_y.xyz, pos),
                dot(tf_object.noise_space_z.xyz, pos)) +
           tf_object.noise_offset.xyz;
  vec4 p = vec4(v, tf_object.noise.y) * tf_object.noise.x;
  vec4 fbm = tf_object.noise_fbm;
  bool four = fbm.w > 3.5;
  float distortion = tf_object.noise.w;
  if (distortion != 0.0) { /* one octave per axis at its fixed offset (materials.perlin.noise_texture) */
    if (four) {
      mat4 o = TF_NOISE_DISTORT4;
      p += vec4(tf_perlin(p + o[0]), tf_perlin(p + o[1]), tf_perlin(p + o[2]), tf_perlin(p + o[3])) *
           distortion;
    }
    else {
      mat3 o = TF_NOISE_DISTORT3;
      p.xyz += vec3(tf_perlin3(p.xyz + o[0]), tf_perlin3(p.xyz + o[1]), tf_perlin3(p.xyz + o[2])) *
               distortion;
    }
  }
  float fac = tf_fbm(p, four, fbm.x, fbm.y, fbm.z);
#ifdef TF_THICKNESS_RAMP
  fac = tf_ramp(fac);
#endif
  vec4 m = tf_object.noise_map;
  return clamp(clamp(m.x * fac + m.y, m.z, m.w), 0.0, 1.0);
}
