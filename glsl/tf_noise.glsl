/* tf_noise.glsl: the Noise thickness source per pixel (TF_THICKNESS_NOISE).
 *
 * numpy counterpart: materials.noise.value_noise, the same fractal 3-D value noise of the
 * object-space position: an integer lattice hashed with MurmurHash3's fmix32 finaliser in
 * wrapping uint arithmetic (numpy's uint32), the eight corners blended with the quintic fade
 * 6t^5 - 15t^4 + 10t^3, three octaves weighted 2^-o. Positions are float32 here (numpy:
 * float64): a point within an ulp of a lattice plane may take the neighbouring cell's values,
 * which the fade makes equal there to within that ulp. Uniform: tf_object.noise (x: scale,
 * y: seed; addon/gpu/layout.py OBJECT).
 */

/* The lattice point c's value in [0, 1) for one octave's seed (value_noise's _hash01). */
float tf_noise_hash01(ivec3 c, int seed)
{
  uint h = uint(c.x) * 0x8DA6B343u;
  h ^= uint(c.y) * 0xD8163841u;
  h ^= uint(c.z) * 0xCB1AB31Fu;
  h ^= uint(seed) * 0x9E3779B9u;
  h ^= h >> 16u;
  h *= 0x85EBCA6Bu;
  h ^= h >> 13u;
  h *= 0xC2B2AE35u;
  h ^= h >> 16u;
  return float(h) / 4294967296.0;
}

/* Fractal value noise in [0, 1] at object-space point p (value_noise, octaves 3). */
float tf_value_noise(vec3 p, float scale, int seed)
{
  vec3 ps = p * scale;
  float total = 0.0;
  float weight = 0.0;
  float amplitude = 1.0;
  for (int octave = 0; octave < 3; octave++) {
    vec3 q = ps * exp2(float(octave)) + 17.0 * float(octave);
    vec3 cell = floor(q);
    vec3 f = q - cell;
    vec3 w = f * f * f * (f * (f * 6.0 - 15.0) + 10.0);
    ivec3 c = ivec3(cell);
    int s = seed + octave;
    /* the eight corners blended by the fade: value_noise's sum of wx wy wz corner, as lerps */
    float x00 = mix(tf_noise_hash01(c, s), tf_noise_hash01(c + ivec3(1, 0, 0), s), w.x);
    float x10 = mix(tf_noise_hash01(c + ivec3(0, 1, 0), s), tf_noise_hash01(c + ivec3(1, 1, 0), s), w.x);
    float x01 = mix(tf_noise_hash01(c + ivec3(0, 0, 1), s), tf_noise_hash01(c + ivec3(1, 0, 1), s), w.x);
    float x11 = mix(tf_noise_hash01(c + ivec3(0, 1, 1), s), tf_noise_hash01(c + ivec3(1, 1, 1), s), w.x);
    float value = mix(mix(x00, x10, w.y), mix(x01, x11, w.y), w.z);
    total += amplitude * value;
    weight += amplitude;
    amplitude *= 0.5;
  }
  return clamp(total / weight, 0.0, 1.0);
}
