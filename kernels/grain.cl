/* grain.cl: film grain as Poisson dye clouds, in density relative to exposure
 * (clfx/plugins/grain.py has the model).
 *
 * Pipeline (preview/final/reference):
 *   grain_noise    white Gaussian noise N(0, 1) per (seed, frame, X, Y, channel) over the
 *                  output window grown by RADIUS on every side (X, Y = frame coordinates, so
 *                  a crop or an overscan render sees the same noise at the same pixel);
 *   grain_blur_h   separable Gaussian along x, per-channel weights (float4 per tap);
 *   grain_apply    the same along y, then the tone model (grain_mix16) on RGB.
 * Draft runs grain_apply_white only: unfiltered white noise in one pass.
 *
 * Each work-item handles 4 consecutive pixels as one 16-lane vector (rows are padded to 4
 * pixels), so PoCL runs hashing, Box-Muller and the taps as vectors; grain_noise and
 * grain_apply take two quads (8 pixels, two independent chains at a time; grain_apply's
 * last quad of a row of pitch % 8 == 4 alone).  Lane 4k+3 (alpha) carries zero noise and
 * alpha is copied bit for bit.  COVERAGE=1 (clfx/fx/noise.py's
 * coverage resolved to alpha) weights the grain by alpha.
 *
 * A build with CLFX_FP64 (the reference level, kernels/lib/precision.h) generates the noise,
 * stores the intermediate buffers and accumulates the taps in double precision.
 */
#include "lib/common.h"
#include "lib/precision.h"
#include "lib/coverage.h"

#ifndef RADIUS
#define RADIUS 0
#endif
#ifndef MONO
#define MONO 0
#endif
#ifndef GRAIN_GAMMA
#define GRAIN_GAMMA 0.6
#endif
#ifndef GRAIN_FOG
#define GRAIN_FOG 0.1
#endif
#ifndef GRAIN_TOE
#define GRAIN_TOE 0.0625
#endif
/* density of middle grey, D(1) = FOG + GAMMA log10(1 + 1 / TOE) (the host passes all four) */
#ifndef GRAIN_D_GREY
#define GRAIN_D_GREY 0.8382738
#endif
/* |v| is clamped here first; the exponent of the log-normal factor to [-87, 80] */
#define GRAIN_VALUE_CAP 1e30
#define GRAIN_EXP_MIN (-87)
#define GRAIN_EXP_MAX 80

#ifndef COVERAGE
#define COVERAGE 0          /* 1: weight the grain by alpha (lib/coverage.h) */
#endif

#ifndef RESPONSE_MODE
#define RESPONSE_MODE 3     /* 0: response 0, 1: 0.5 (Nutting), 2: 1, 3: any (pow) */
#endif

#include "lib/fastmath.h"
CLFX_DEFINE_FASTMATH(8)
CLFX_DEFINE_FASTMATH(16)

/* Unit Gaussian white noise for 4 pixels (Box-Muller): per pixel the uniforms of channels
 * (0, 1) give R = r cos, G = r sin; channels (2, 3) give B = r cos.  MONO: R = G = B. */
inline REAL16 grain_white16(uint seed, int frame, int x, int y)
{
  const REAL16 u = TO_REAL16(clfx_uniform16(seed, frame, x, y, 0));
  REAL8 co;
#if REAL_IS_DOUBLE
  const REAL8 r = sqrt((REAL)(-2) * log(u.even));
  const REAL8 si = sincos((REAL)6.283185307179586 * u.odd, &co);
#else
  const REAL8 r = sqrt(-2.0f * clfx_log8(u.even));
  const REAL8 si = clfx_sincos2pi8(u.odd, &co);
#endif
  const REAL8 a = r * co, b = r * si;
  const REAL z = (REAL)0;
#if MONO
  return (REAL16)(a.s0, a.s0, a.s0, z, a.s2, a.s2, a.s2, z,
                  a.s4, a.s4, a.s4, z, a.s6, a.s6, a.s6, z);
#else
  return (REAL16)(a.s0, b.s0, a.s1, z, a.s2, b.s2, a.s3, z,
                  a.s4, b.s4, a.s5, z, a.s6, b.s6, a.s7, z);
#endif
}

/* The tone model of clfx/plugins/grain.py on 4 RGBA pixels, with grey = the exposure
 * reference E and n the unit grain field:
 *   e   = clamp(v / E, 0, cap)            relative exposure (MONO: the luminance's)
 *   D   = FOG + GAMMA log10(1 + e / TOE)  density on the characteristic curve
 *   s   = amt_c (D / D(1))^response       log-exposure deviation (Nutting: response 0.5)
 *   out = v + E (e_c + TOE) (exp(s n - s^2 / 2) - 1)
 * COVERAGE: out = v + alpha (out - v) where alpha < 1 (clfx_cover16), so the empty
 * background of a CG element stays empty.  Non-finite values become 0 first (they must not
 * spread); alpha is copied unchanged (0 if it was not finite); the result is clamped to the
 * float range. */
inline float16 grain_mix16(const float16 c, const REAL16 n, const REAL4 amt, const REAL response,
                           const REAL grey, const REAL inv_grey)
{
  const float16 c0 = clfx_finite16_or_zero(c);
  const REAL16 cs = TO_REAL16(clamp(c0, (float16)(-GRAIN_VALUE_CAP), (float16)GRAIN_VALUE_CAP));
  const REAL16 e = clamp(cs * inv_grey, (REAL)0, (REAL)GRAIN_VALUE_CAP);
#if MONO
  const REAL4 lum = (REAL)(CLFX_LUMA_R) * e.s048c + (REAL)(CLFX_LUMA_G) * e.s159d
                  + (REAL)(CLFX_LUMA_B) * e.s26ae;
  const REAL4 l = max(lum, (REAL)0);
  const REAL16 ed = (REAL16)(l.x, l.x, l.x, l.x, l.y, l.y, l.y, l.y,
                             l.z, l.z, l.z, l.z, l.w, l.w, l.w, l.w);
#else
  const REAL16 ed = e;
#endif
  const REAL16 x = (REAL)1 + ed * (REAL)(1.0 / GRAIN_TOE);
  /* D / D(1); the response's common values are build variants (no pow) */
#if REAL_IS_DOUBLE
  const REAL16 dr = ((REAL)GRAIN_FOG + (REAL)(GRAIN_GAMMA * 0.4342944819032518) * log(x))
                  * (REAL)(1.0 / GRAIN_D_GREY);
#else
  const float16 dr = ((float)GRAIN_FOG + (float)(GRAIN_GAMMA * 0.4342944819032518)
                      * clfx_log16(x)) * (float)(1.0 / GRAIN_D_GREY);
#endif
#if RESPONSE_MODE == 0
  const REAL16 q = (REAL16)((REAL)1);
#elif RESPONSE_MODE == 1
  const REAL16 q = sqrt(dr);
#elif RESPONSE_MODE == 2
  const REAL16 q = dr;
#elif REAL_IS_DOUBLE
  const REAL16 q = pow(dr, (REAL16)(response));
#else
  const float16 q = clfx_exp2_16(response * 1.44269504f * clfx_log16(dr));
#endif
  const REAL16 s = (REAL16)(amt, amt, amt, amt) * q;
  const REAL16 ex = s * n - (REAL)0.5 * s * s;
#if REAL_IS_DOUBLE
  const REAL16 f = exp(clamp(ex, (REAL)GRAIN_EXP_MIN, (REAL)GRAIN_EXP_MAX));
#else
  const float16 f = clfx_exp16(clamp(ex, (float)GRAIN_EXP_MIN, (float)GRAIN_EXP_MAX));
#endif
  const REAL16 dev = grey * (e + (REAL)GRAIN_TOE) * (f - (REAL)1);
#if COVERAGE
  const REAL16 o = clamp(clfx_cover16(cs, cs + dev, c0), (REAL)(-FLT_MAX), (REAL)FLT_MAX);
#else
  const REAL16 o = clamp(cs + dev, (REAL)(-FLT_MAX), (REAL)FLT_MAX);
#endif
  const int16 alpha = (int16)(0, 0, 0, -1, 0, 0, 0, -1, 0, 0, 0, -1, 0, 0, 0, -1);
  return select(TO_FLOAT16(o), c0, alpha);
}

/* Unit Gaussian white noise for 8 pixels (x .. x + 7) as two float16s, bit for bit two
 * grain_white16: the float32 levels take both quads' logarithms, roots and sines as one
 * 16-lane evaluation (grain_white16 runs them 8 lanes wide; at 1080p the noise cost
 * 27 ms of CPU a frame that way, its long dependency chain per work-item idle half the time).
 * Always inlined: PoCL kept it out of line, its two outputs through the stack (1080p: with
 * clfx_uniform32's shared hashes, grain_noise 18-23 -> 15.5-20.5 ms of CPU). */
inline __attribute__((always_inline)) void grain_white32(uint seed, int frame, int x, int y,
                                                       REAL16 *n0, REAL16 *n1)
{
#if REAL_IS_DOUBLE
  *n0 = grain_white16(seed, frame, x, y);
  *n1 = grain_white16(seed, frame, x + 4, y);
#else
  float16 u0, u1;
  clfx_uniform32(seed, frame, x, y, 0, &u0, &u1);
  float16 co;
  const float16 r = sqrt(-2.0f * clfx_log16((float16)(u0.even, u1.even)));
  const float16 si = clfx_sincos2pi16((float16)(u0.odd, u1.odd), &co);
  const float16 a = r * co, b = r * si;
#if MONO
  *n0 = (float16)(a.s0, a.s0, a.s0, 0.0f, a.s2, a.s2, a.s2, 0.0f,
                  a.s4, a.s4, a.s4, 0.0f, a.s6, a.s6, a.s6, 0.0f);
  *n1 = (float16)(a.s8, a.s8, a.s8, 0.0f, a.sa, a.sa, a.sa, 0.0f,
                  a.sc, a.sc, a.sc, 0.0f, a.se, a.se, a.se, 0.0f);
#else
  *n0 = (float16)(a.s0, b.s0, a.s1, 0.0f, a.s2, b.s2, a.s3, 0.0f,
                  a.s4, b.s4, a.s5, 0.0f, a.s6, b.s6, a.s7, 0.0f);
  *n1 = (float16)(a.s8, b.s8, a.s9, 0.0f, a.sa, b.sa, a.sb, 0.0f,
                  a.sc, b.sc, a.sd, 0.0f, a.se, b.se, a.sf, 0.0f);
#endif
#endif
}

/* 8 pixels per work-item (npitch is a multiple of 8) */
kernel void grain_noise(global REAL *noise, const int npitch, const int rows,
                        const int fx0, const int fy0, const uint seed, const int frame)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= rows || qx * 8 >= npitch) return;
  const int x = qx * 8;
  REAL16 n0, n1;
  grain_white32(seed, frame, fx0 + x, fy0 + y, &n0, &n1);
  global REAL *p = noise + (size_t)(y * npitch + x) * 4;
  vstore16(n0, 0, p);
  vstore16(n1, 1, p);
}

/* sum_k w_k * v_k, k = 0..2R, for 4 pixels (16 lanes): v_k = vload16 at p + k * step
 * (step = one pixel for the horizontal pass, one row for the vertical one). */
inline REAL16 grain_taps16(global const REAL *p, const size_t step, global const REAL *weights)
{
  REAL16 acc = (REAL16)(0);
  for(int k = 0; k <= 2 * RADIUS; ++k)
  {
    const REAL4 w = vload4(k, weights);
    acc += (REAL16)(w, w, w, w) * vload16(0, p + (size_t)k * step);
  }
  return acc;
}

/* grain_taps16 for two quads at once, at p and p + 16 (the next 4 pixels): each sum takes
 * grain_taps16's operations in its order, interleaved, so the two dependent chains of 2R + 1
 * multiply-adds overlap (one chain a work-item left the core waiting on each add: 1080p
 * grain_apply 36 -> 27.5 ms of CPU). */
inline void grain_taps16x2(global const REAL *p, const size_t step, global const REAL *weights,
                           REAL16 *a0, REAL16 *a1)
{
  REAL16 acc0 = (REAL16)(0), acc1 = (REAL16)(0);
  for(int k = 0; k <= 2 * RADIUS; ++k)
  {
    const REAL4 w = vload4(k, weights);
    acc0 += (REAL16)(w, w, w, w) * vload16(0, p + (size_t)k * step);
    acc1 += (REAL16)(w, w, w, w) * vload16(1, p + (size_t)k * step);
  }
  *a0 = acc0;
  *a1 = acc1;
}

/* tmp(x, y) = sum_k w_k * noise(x + k, y), k = 0..2R: noise is offset by R in x.  (8 pixels a
 * work-item through grain_taps16x2 ran no faster here: memory-bound.) */
kernel void grain_blur_h(global const REAL *noise, global REAL *tmp, global const REAL *weights,
                         const int npitch, const int pitch, const int rows)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= rows || qx * 4 >= pitch) return;
  const int x = qx * 4;
  vstore16(grain_taps16(noise + (size_t)(y * npitch + x) * 4, 4, weights), 0,
           tmp + (size_t)(y * pitch + x) * 4);
}

/* Vertical taps (tmp is offset by R rows) and the mix with the source; 8 pixels a work-item
 * (grain_taps16x2), the row's last quad alone where pitch % 8 == 4. */
kernel void grain_apply(global const float *src, global float *dst, global const REAL *tmp,
                        global const REAL *weights, const int pitch, const int height,
                        const float ar, const float ag, const float ab, const float response,
                        const float grey, const float inv_grey)
{
  const int ox = get_global_id(0), y = get_global_id(1);
  if(y >= height || ox * 8 >= pitch) return;
  const int x = ox * 8;
  const size_t i = (size_t)(y * pitch + x) * 4;
  const REAL4 amt = (REAL4)(ar, ag, ab, 0);
  if(x + 4 < pitch)
  {
    REAL16 a0, a1;
    grain_taps16x2(tmp + i, (size_t)pitch * 4, weights, &a0, &a1);
    vstore16(grain_mix16(vload16(0, src + i), a0, amt, response, grey, inv_grey), 0, dst + i);
    vstore16(grain_mix16(vload16(1, src + i), a1, amt, response, grey, inv_grey), 1, dst + i);
  }
  else
    vstore16(grain_mix16(vload16(0, src + i), grain_taps16(tmp + i, (size_t)pitch * 4, weights),
                         amt, response, grey, inv_grey), 0, dst + i);
}

/* Draft: white noise generated in place, one pass; 8 pixels a work-item (grain_white32:
 * 1080p 42-55 -> 34-39 ms of CPU, the same pixels), the row's last quad alone where
 * pitch % 8 == 4. */
kernel void grain_apply_white(global const float *src, global float *dst, const int pitch,
                              const int height, const int fx0, const int fy0, const uint seed,
                              const int frame, const float ar, const float ag, const float ab,
                              const float response, const float grey, const float inv_grey)
{
  const int ox = get_global_id(0), y = get_global_id(1);
  if(y >= height || ox * 8 >= pitch) return;
  const int x = ox * 8;
  const size_t i = (size_t)(y * pitch + x) * 4;
  const REAL4 amt = (REAL4)(ar, ag, ab, 0);
  if(x + 4 < pitch)
  {
    REAL16 n0, n1;
    grain_white32(seed, frame, fx0 + x, fy0 + y, &n0, &n1);
    vstore16(grain_mix16(vload16(0, src + i), n0, amt, response, grey, inv_grey), 0, dst + i);
    vstore16(grain_mix16(vload16(1, src + i), n1, amt, response, grey, inv_grey), 1, dst + i);
  }
  else
    vstore16(grain_mix16(vload16(0, src + i), grain_white16(seed, frame, fx0 + x, fy0 + y),
                         amt, response, grey, inv_grey), 0, dst + i);
}
