/* tf_perlin.glsl: the Blender Noise thickness source per pixel (TF_THICKNESS_PERLIN).
 *
 * numpy counterpart: materials.perlin (blender_noise, fbm, perlin, hash4): Blender's Noise
 * Texture, 4-D, of (object-space position, seed) times the scale, Detail 2, Roughness 0.5,
 * Lacunarity 2, normalized. Gradient noise on the 4-D integer lattice, each point's gradient
 * picked by Bob Jenkins' lookup3 hash of its four coordinates (wrapping uint arithmetic),
 * blended with the quintic fade, scaled by 0.8344; three octaves of fBm. float32 as numpy's
 * mirror computes it. Uniform: tf_object.noise (x: scale, y: seed).
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
  c = (c ^ b) - tf_perlin_rot(b, 14u);
  a = (a ^ c) - tf_perlin_rot(c, 11u);
  b = (b ^ a) - tf_perlin_rot(a, 25u);
  c = (c ^ b) - tf_perlin_rot(b, 16u);
  a = (a ^ c) - tf_perlin_rot(c, 4u);
  b = (b ^ a) - tf_perlin_rot(a, 14u);
  c = (c ^ b) - tf_perlin_rot(b, 24u);
  return c;
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

/* The Blender Noise source's Fac at object-space point pos (materials.perlin.blender_noise). */
float tf_blender_noise(vec3 pos, float scale, float seed)
{
  vec4 p = vec4(pos, seed) * scale;
  float total = 0.0;
  float amplitude = 1.0;
  float weight = 0.0;
  float frequency = 1.0;
  for (int octave = 0; octave < 3; octave++) {
    total += amplitude * tf_perlin(frequency * p);
    weight += amplitude;
    amplitude *= 0.5;
    frequency *= 2.0;
  }
  return 0.5 * total / weight + 0.5;
}
