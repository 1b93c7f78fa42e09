/* fastmath.h: vector noise and elementary functions that PoCL can vectorise.
 *
 * PoCL's libm calls (log, sincos, pow, exp) run lane by lane; these polynomial versions are
 * pure arithmetic, so a work-item handling 16 lanes runs them as SIMD (3-10x faster here).
 * CLFX_DEFINE_FASTMATH(N) defines clfx_logN, clfx_sincos2piN, clfx_exp2_N and clfx_expN for
 * floatN; a kernel file instantiates the widths it needs.  clfx_uniform16 (and its two halves,
 * clfx_hash_xy16 and clfx_stream16) is the 16-lane form of common.h's clfx_uniform, bit
 * for bit.
 */
#ifndef CLFX_FASTMATH_H
#define CLFX_FASTMATH_H
#include "lib/common.h"

/* Polynomial log, sin/cos(2 pi u) and exp2 in float32: pure arithmetic, so PoCL vectorises
 * them (its libm calls run lane by lane, ~10x slower here).  Relative error <= ~2e-7 for
 * the arguments used (normal positive floats; exp2 arguments in [-126, 126]). */
#define CLFX_DEFINE_FASTMATH(N)                                                                    \
inline float##N clfx_log##N(const float##N x)                                                   \
{                                                                                              \
  /* x = m 2^e, m in [sqrt(1/2), sqrt(2)); log m = 2 atanh(s), s = (m - 1) / (m + 1) */       \
  const int##N bits = as_int##N(x);                                                            \
  float##N m = as_float##N((bits & 0x007fffff) | 0x3f800000);                                 \
  const int##N big = m > 1.41421356f;                                                          \
  m = select(m, m * 0.5f, big);                                                                \
  const int##N e = ((bits >> 23) & 0xff) - 127 - big;                                          \
  const float##N s = (m - 1.0f) / (m + 1.0f), s2 = s * s;                                      \
  const float##N p = s * (2.0f + s2 * (0.66666667f + s2 * (0.4f + s2 * (0.28571429f           \
                     + s2 * 0.22222222f))));                                                   \
  return convert_float##N(e) * 0.69314718f + p;                                                \
}                                                                                              \
inline float##N clfx_sincos2pi##N(const float##N u, float##N *cosine)                           \
{                                                                                              \
  /* quadrant q = rint(4u); a = 2 pi (u - q/4) in [-pi/4, pi/4]; Taylor to a^9 / a^8 */       \
  const float##N q = rint(4.0f * u);                                                           \
  const float##N a = 6.28318531f * (u - 0.25f * q), a2 = a * a;                                \
  const float##N sa = a * (1.0f + a2 * (-1.6666667e-1f + a2 * (8.3333333e-3f                  \
                      + a2 * (-1.9841270e-4f + a2 * 2.7557319e-6f))));                         \
  const float##N ca = 1.0f + a2 * (-0.5f + a2 * (4.1666667e-2f + a2 * (-1.3888889e-3f         \
                      + a2 * 2.4801587e-5f)));                                                 \
  const int##N qi = convert_int##N(q) & 3;                                                     \
  const int##N odd = (qi & 1) != 0;                                                            \
  const float##N s = select(sa, ca, odd), c = select(ca, sa, odd);                             \
  *cosine = select(c, -c, (qi == 1) | (qi == 2));                                              \
  return select(s, -s, qi >= 2);                                                               \
}                                                                                              \
inline float##N clfx_exp2_##N(const float##N x)                                                  \
{                                                                                              \
  const float##N xc = clamp(x, -126.0f, 126.0f), k = rint(xc);                                 \
  const float##N t = (xc - k) * 0.69314718f;                                                   \
  const float##N p = 1.0f + t * (1.0f + t * (0.5f + t * (1.6666667e-1f + t * (4.1666667e-2f   \
                     + t * (8.3333333e-3f + t * (1.3888889e-3f + t * 1.9841270e-4f))))));      \
  return p * as_float##N((convert_int##N(k) + 127) << 23);                                     \
}                                                                                              \
/* exp(x) for x * log2(e) in [-126, 126] (clamped): clfx_exp2_N's polynomial with the          \
 * rounding to the nearest integer done by the 1.5 * 2^23 trick (PoCL expands rint() into      \
 * a dozen instructions); bit for bit clfx_exp2_N(x * log2 e) there. */                        \
inline float##N clfx_exp##N(const float##N x)                                                  \
{                                                                                              \
  const float##N xc = clamp(x * 1.44269504f, -126.0f, 126.0f);                                 \
  const float##N big = xc + 12582912.0f;                /* 1.5 * 2^23: k in the low bits */    \
  const float##N k = big - 12582912.0f;                                                        \
  const float##N t = (xc - k) * 0.69314718f;                                                   \
  const float##N p = 1.0f + t * (1.0f + t * (0.5f + t * (1.6666667e-1f + t * (4.1666667e-2f    \
                    + t * (8.3333333e-3f + t * (1.3888889e-3f + t * 1.9841270e-4f))))));       \
  return p * as_float##N((as_int##N(big) - 0x4B400000 + 127) << 23);                           \
}

/* clfx_hash (lowbias32) on 16 lanes at once. */
inline uint16 clfx_hash16(uint16 x) { CLFX_LOWBIAS32(x); return x; }

/* clfx_uniform(seed, frame, x + i, y, c) in two parts, lane 4 i + c (pixels i = 0..3).  The
 * first four of its five hashes depend on (seed, frame, x, y) only, so the streams of one
 * pixel can share them: clfx_hash_xy16 once per pixel and seed, then clfx_stream16 once
 * per group of four streams. */
inline uint16 clfx_hash_xy16(uint seed, int frame, int x, int y)
{
  const uint prefix = clfx_hash(clfx_hash(seed ^ 0x9e3779b9u) ^ (uint)frame);
  const uint16 lane_px = (uint16)(0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3);
  const uint16 h = clfx_hash16((uint16)(prefix) ^ ((uint16)((uint)x) + lane_px));
  return clfx_hash16(h ^ (uint16)((uint)y * 0x85ebca6bu));
}

/* The uniforms in (0, 1) of streams c0 + c (lane 4 i + c) from clfx_hash_xy16. */
inline float16 clfx_stream16(uint16 hxy, int c0)
{
  const uint16 lane_c = (uint16)(0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3);
  const uint16 h = clfx_hash16(hxy ^ (((uint16)((uint)c0) + lane_c) * 0xc2b2ae35u));
  return (convert_float16(h >> 8) + 0.5f) * (1.0f / 16777216.0f);
}

/* clfx_uniform(seed, frame, x + i, y, c0 + c) for pixels i = 0..3 and channels c = 0..3,
 * lane 4 i + c; bit-identical to the scalar helper in common.h. */
inline float16 clfx_uniform16(uint seed, int frame, int x, int y, int c0)
{
  return clfx_stream16(clfx_hash_xy16(seed, frame, x, y), c0);
}

/* clfx_uniform16 at x (*u0) and x + 4 (*u1), bit for bit: the per-pixel hashes of the 8
 * pixels 8 lanes wide, once each (clfx_hash_xy16 runs them on 16 lanes, each value 4 times:
 * 1080p grain_noise 22.6 -> 20.5 ms of CPU). */
inline void clfx_uniform32(uint seed, int frame, int x, int y, int c0, float16 *u0, float16 *u1)
{
  const uint prefix = clfx_hash(clfx_hash(seed ^ 0x9e3779b9u) ^ (uint)frame);
  uint8 h = (uint8)(prefix) ^ ((uint8)((uint)x) + (uint8)(0, 1, 2, 3, 4, 5, 6, 7));
  CLFX_LOWBIAS32(h);
  h ^= (uint8)((uint)y * 0x85ebca6bu);
  CLFX_LOWBIAS32(h);
  *u0 = clfx_stream16(shuffle(h, (uint16)(0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3)), c0);
  *u1 = clfx_stream16(shuffle(h, (uint16)(4, 4, 4, 4, 5, 5, 5, 5, 6, 6, 6, 6, 7, 7, 7, 7)), c0);
}

#endif
