/* grain.cl: band-limited, luminance-dependent film grain (clfx/plugins/grain.py).
 *
 * Pipeline (preview/final/reference):
 *   grain_noise    white Gaussian noise N(0, 1) per (seed, frame, X, Y, channel) over the
 *                  output window grown by RADIUS on every side (X, Y = frame coordinates, so
 *                  a crop or an overscan render sees the same noise at the same pixel);
 *   grain_blur_h   separable Gaussian along x, per-channel weights (float4 per tap);
 *   grain_apply    the same along y, then out = in + sigma(L) * amount_c * n_c on RGB.
 * Draft runs grain_apply_white only: unfiltered white noise in one pass.
 *
 * Each work-item handles 4 consecutive pixels as one 16-lane vector (rows are padded to 4
 * pixels), so PoCL runs hashing, Box-Muller and the taps as vectors.  Lane 4k+3 (alpha)
 * carries zero noise and alpha is copied bit for bit.
 *
 * A build with CLFX_FP64 (the reference level, kernels/lib/precision.h) generates the noise,
 * stores the intermediate buffers and accumulates the taps in double precision.
 */
#include "lib/common.h"
#include "lib/precision.h"

#ifndef RADIUS
#define RADIUS 0
#endif
#ifndef MONO
#define MONO 0
#endif
/* Luminance is clamped to [FLOOR, CAP]: the cap keeps sigma * noise finite for inputs near
 * FLT_MAX, the floor keeps log() finite (grain at black is then ~1e-15 * amount, not 0). */
#define GRAIN_LUMINANCE_CAP 1e30
#define GRAIN_LUMINANCE_FLOOR 1e-30
#define GRAIN_MID_GREY 0.18

#include "lib/fastmath.h"
CLFX_DEFINE_FASTMATH(4)
CLFX_DEFINE_FASTMATH(8)

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

/* out = in + sigma(L) * amount_c * n_c on RGB, sigma(L) = (L / 0.18)^response (the 0.18 of
 * "relative to mid-grey" is folded into amount_c on the host).  Non-finite values become 0
 * before the grain (they must not spread into L); alpha is copied unchanged (0 if it was
 * not finite). */
inline float16 grain_mix16(const float16 c, const REAL16 n, const REAL4 amt, const REAL response)
{
  const float16 c0 = clfx_finite16_or_zero(c);
  const REAL16 cs = TO_REAL16(c0);
  const REAL4 lum = (REAL)0.2126 * (REAL4)(cs.s0, cs.s4, cs.s8, cs.sc)
                  + (REAL)0.7152 * (REAL4)(cs.s1, cs.s5, cs.s9, cs.sd)
                  + (REAL)0.0722 * (REAL4)(cs.s2, cs.s6, cs.sa, cs.se);
  const REAL4 l = clamp(lum, (REAL)GRAIN_LUMINANCE_FLOOR, (REAL)GRAIN_LUMINANCE_CAP);
#if REAL_IS_DOUBLE
  const REAL4 s = pow(l * (REAL)(1.0 / GRAIN_MID_GREY), (REAL4)(response));
#else
  const REAL4 s = clfx_exp2_4(response * 1.44269504f * clfx_log4(l * (1.0f / 0.18f)));
#endif
  const REAL16 s16 = (REAL16)(s.x, s.x, s.x, s.x, s.y, s.y, s.y, s.y,
                              s.z, s.z, s.z, s.z, s.w, s.w, s.w, s.w);
  const float16 out = TO_FLOAT16(cs + s16 * (REAL16)(amt, amt, amt, amt) * n);
  const int16 alpha = (int16)(0, 0, 0, -1, 0, 0, 0, -1, 0, 0, 0, -1, 0, 0, 0, -1);
  return select(out, c0, alpha);
}

kernel void grain_noise(global REAL *noise, const int npitch, const int rows,
                        const int fx0, const int fy0, const uint seed, const int frame)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= rows || qx * 4 >= npitch) return;
  const int x = qx * 4;
  vstore16(grain_white16(seed, frame, fx0 + x, fy0 + y), 0, noise + (size_t)(y * npitch + x) * 4);
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

/* tmp(x, y) = sum_k w_k * noise(x + k, y), k = 0..2R: noise is offset by R in x. */
kernel void grain_blur_h(global const REAL *noise, global REAL *tmp, global const REAL *weights,
                         const int npitch, const int pitch, const int rows)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= rows || qx * 4 >= pitch) return;
  const int x = qx * 4;
  vstore16(grain_taps16(noise + (size_t)(y * npitch + x) * 4, 4, weights), 0,
           tmp + (size_t)(y * pitch + x) * 4);
}

/* Vertical taps (tmp is offset by R rows) and the mix with the source. */
kernel void grain_apply(global const float *src, global float *dst, global const REAL *tmp,
                        global const REAL *weights, const int pitch, const int height,
                        const float ar, const float ag, const float ab, const float response)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= height || qx * 4 >= pitch) return;
  const int x = qx * 4;
  const size_t i = (size_t)(y * pitch + x) * 4;
  const REAL16 acc = grain_taps16(tmp + i, (size_t)pitch * 4, weights);
  vstore16(grain_mix16(vload16(0, src + i), acc, (REAL4)(ar, ag, ab, 0), response), 0, dst + i);
}

/* Draft: white noise generated in place, one pass. */
kernel void grain_apply_white(global const float *src, global float *dst, const int pitch,
                              const int height, const int fx0, const int fy0, const uint seed,
                              const int frame, const float ar, const float ag, const float ab,
                              const float response)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= height || qx * 4 >= pitch) return;
  const int x = qx * 4;
  const size_t i = (size_t)(y * pitch + x) * 4;
  const REAL16 n = grain_white16(seed, frame, fx0 + x, fy0 + y);
  vstore16(grain_mix16(vload16(0, src + i), n, (REAL4)(ar, ag, ab, 0), response), 0, dst + i);
}
