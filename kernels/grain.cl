/* grain.cl: film grain as Poisson dye clouds, in density relative to exposure
 * (clfx/plugins/grain.py has the model).
 *
 * Pipeline (preview/final/reference):
 *   grain_noise    white Gaussian noise N(0, 1) per (seed, frame, X, Y, channel) over the
 *                  output window grown by RADIUS on every side (X, Y = frame coordinates, so
 *                  a crop or an overscan render sees the same noise at the same pixel);
 *   grain_blur_h   separable Gaussian along x, per-channel weights;
 *   grain_apply    the same along y, then the tone model (grain_mix16x3) on RGB.
 * Draft runs grain_apply_white only: unfiltered white noise in one pass.
 *
 * Alpha carries no grain, so the noise and the blurred noise are three planes (R, G, B) and
 * the tone model runs on colour lanes only (grain_mix16x3: 48 lanes for 16 pixels where RGBA
 * vectors took 64); alpha is copied bit for bit.  grain_noise handles 8 pixels a work-item
 * (hashing and Box-Muller as 16-lane vectors, grain_white32), the others 16: the taps and
 * the tone model as float16 planes (PoCL runs a float16 in one AVX-512 register; float8
 * planes took 3 ymm operations where an RGBA float16 of 4 pixels took 2 zmm for 8), three
 * independent chains (1080p, CPU ms against the RGBA form: grain_apply 28.6 -> 20.3,
 * grain_blur_h 9.8 -> 5.0, draft's grain_apply_white 40.7 -> 32.4; monochrome's apply
 * 26.1 -> 15.7, its density term once for three channels).  Source rows are padded to 4
 * pixels only: the last 16 of a row load and store its whole quads.  COVERAGE=1
 * (clfx/fx/noise.py's coverage resolved to alpha) weights the grain by alpha.
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
CLFX_DEFINE_FASTMATH(16)

#if REAL_IS_DOUBLE
/* Unit Gaussian white noise for 4 pixels (Box-Muller) in float64 (the reference level);
 * the lanes as grain_white32 lays them out. */
inline REAL16 grain_white16(uint seed, int frame, int x, int y)
{
  const REAL16 u = TO_REAL16(clfx_uniform16(seed, frame, x, y, 0));
  REAL8 co;
  const REAL8 r = sqrt((REAL)(-2) * log(u.even));
  const REAL8 si = sincos((REAL)6.283185307179586 * u.odd, &co);
  const REAL8 a = r * co;
  const REAL z = (REAL)0;
#if MONO
  (void)si;
  return (REAL16)(a.s0, a.s0, a.s0, z, a.s2, a.s2, a.s2, z,
                  a.s4, a.s4, a.s4, z, a.s6, a.s6, a.s6, z);
#else
  const REAL8 b = r * si;
  return (REAL16)(a.s0, b.s0, a.s1, z, a.s2, b.s2, a.s3, z,
                  a.s4, b.s4, a.s5, z, a.s6, b.s6, a.s7, z);
#endif
}
#endif

/* Unit Gaussian white noise for 8 pixels (x .. x + 7) as two REAL16s (Box-Muller): per pixel
 * the uniforms of channels (0, 1) give R = r cos, G = r sin; channels (2, 3) give B = r cos;
 * MONO: R = G = B; alpha 0.  float64: grain_white16 a quad at a time.  float32: both quads'
 * logarithms, roots and sines as one 16-lane evaluation (8 lanes wide, a quad at a time, the
 * noise cost 27 ms of CPU a 1080p frame, its long dependency chain per work-item idle half
 * the time).  Always inlined: PoCL kept it out of line, its two outputs through the stack
 * (1080p: with clfx_uniform32's shared hashes, grain_noise 18-23 -> 15.5-20.5 ms of CPU). */
CLFX_INLINE void grain_white32(uint seed, int frame, int x, int y,
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
  const float16 a = r * co;
#if MONO
  (void)si;
  *n0 = (float16)(a.s0, a.s0, a.s0, 0.0f, a.s2, a.s2, a.s2, 0.0f,
                  a.s4, a.s4, a.s4, 0.0f, a.s6, a.s6, a.s6, 0.0f);
  *n1 = (float16)(a.s8, a.s8, a.s8, 0.0f, a.sa, a.sa, a.sa, 0.0f,
                  a.sc, a.sc, a.sc, 0.0f, a.se, a.se, a.se, 0.0f);
#else
  const float16 b = r * si;
  *n0 = (float16)(a.s0, b.s0, a.s1, 0.0f, a.s2, b.s2, a.s3, 0.0f,
                  a.s4, b.s4, a.s5, 0.0f, a.s6, b.s6, a.s7, 0.0f);
  *n1 = (float16)(a.s8, b.s8, a.s9, 0.0f, a.sa, b.sa, a.sb, 0.0f,
                  a.sc, b.sc, a.sd, 0.0f, a.se, b.se, a.sf, 0.0f);
#endif
#endif
}

/* The tone model of clfx/plugins/grain.py, with grey = the exposure reference E and n the
 * unit grain field:
 *   e   = clamp(v / E, 0, cap)            relative exposure (MONO: the luminance's)
 *   D   = FOG + GAMMA log10(1 + e / TOE)  density on the characteristic curve
 *   s   = amt_c (D / D(1))^response       log-exposure deviation (Nutting: response 0.5)
 *   out = v + E (e_c + TOE) (exp(s n - s^2 / 2) - 1)
 * COVERAGE: out = v + alpha (out - v) where alpha < 1 (lib/coverage.h's rule), so the empty
 * background of a CG element stays empty.  Non-finite values become 0 first (they must not
 * spread); alpha is copied unchanged (0 if it was not finite); the result is clamped to the
 * float range.
 *
 * It runs on 16 pixels as three planes of one channel each (R, G, B; 48 lanes where RGBA
 * took 64 with alpha's zero noise through the whole model; the same operations on every
 * colour lane, so the same bits).  grain_density16: (D / D(1))^response of the density's
 * exposure ed; MONO evaluates it once for the three channels. */
inline REAL16 grain_density16(const REAL16 ed, const REAL response)
{
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
  return (REAL16)((REAL)1);
#elif RESPONSE_MODE == 1
  return sqrt(dr);
#elif RESPONSE_MODE == 2
  return dr;
#elif REAL_IS_DOUBLE
  return pow(dr, (REAL16)(response));
#else
  return clfx_exp2_16(response * 1.44269504f * clfx_log16(dr));
#endif
}

/* One channel's output: cs its clamped value, e its relative exposure, q its density term,
 * n its grain, cov alpha clamped to [0, 1] (COVERAGE). */
inline float16 grain_tone16(const REAL16 cs, const REAL16 e, const REAL16 q, const REAL16 n,
                            const REAL amt, const REAL grey, const REAL16 cov)
{
  const REAL16 s = amt * q;
  const REAL16 ex = s * n - (REAL)0.5 * s * s;
#if REAL_IS_DOUBLE
  const REAL16 f = exp(clamp(ex, (REAL)GRAIN_EXP_MIN, (REAL)GRAIN_EXP_MAX));
#else
  const float16 f = clfx_exp16(clamp(ex, (float)GRAIN_EXP_MIN, (float)GRAIN_EXP_MAX));
#endif
  const REAL16 dev = grey * (e + (REAL)GRAIN_TOE) * (f - (REAL)1);
  const REAL16 noisy = cs + dev;
#if COVERAGE
  const REAL16 o = select(cs + cov * (noisy - cs), noisy, cov >= (REAL)1);
#else
  const REAL16 o = noisy;
#endif
  return TO_FLOAT16(clamp(o, (REAL)(-FLT_MAX), (REAL)FLT_MAX));
}

/* v clamped to [-cap, cap], in REAL */
#define GRAIN_CS16(v) TO_REAL16(clamp((v), (float16)(-GRAIN_VALUE_CAP), (float16)GRAIN_VALUE_CAP))

/* The tone model on 16 RGBA pixels *c0 .. *c3 (x .. x + 15) with their grain in planes nr,
 * ng, nb; the outputs in place (alpha copied). */
CLFX_INLINE void grain_mix16x3(
    float16 *c0, float16 *c1, float16 *c2, float16 *c3, const REAL16 nr, const REAL16 ng,
    const REAL16 nb, const REAL4 amt,
    const REAL response, const REAL grey, const REAL inv_grey)
{
  const float16 f0 = clfx_finite16_or_zero(*c0), f1 = clfx_finite16_or_zero(*c1);
  const float16 f2 = clfx_finite16_or_zero(*c2), f3 = clfx_finite16_or_zero(*c3);
  /* to planes by two-source shuffles: (r, g) pairs of 8 pixels, (b, alpha) pairs */
  const float16 rg0 = (float16)(f0.s0145, f0.s89cd, f1.s0145, f1.s89cd);
  const float16 rg1 = (float16)(f2.s0145, f2.s89cd, f3.s0145, f3.s89cd);
  const float16 ba0 = (float16)(f0.s2367, f0.sabef, f1.s2367, f1.sabef);
  const float16 ba1 = (float16)(f2.s2367, f2.sabef, f3.s2367, f3.sabef);
  const REAL16 rs = GRAIN_CS16((float16)(rg0.even, rg1.even));
  const REAL16 gs = GRAIN_CS16((float16)(rg0.odd, rg1.odd));
  const REAL16 bs = GRAIN_CS16((float16)(ba0.even, ba1.even));
  const REAL16 re = clamp(rs * inv_grey, (REAL)0, (REAL)GRAIN_VALUE_CAP);
  const REAL16 ge = clamp(gs * inv_grey, (REAL)0, (REAL)GRAIN_VALUE_CAP);
  const REAL16 be = clamp(bs * inv_grey, (REAL)0, (REAL)GRAIN_VALUE_CAP);
#if MONO
  const REAL16 lum = (REAL)(CLFX_LUMA_R) * re + (REAL)(CLFX_LUMA_G) * ge
                   + (REAL)(CLFX_LUMA_B) * be;
  const REAL16 rq = grain_density16(max(lum, (REAL)0), response), gq = rq, bq = rq;
#else
  const REAL16 rq = grain_density16(re, response), gq = grain_density16(ge, response);
  const REAL16 bq = grain_density16(be, response);
#endif
#if COVERAGE
  const REAL16 cov = TO_REAL16(clamp((float16)(ba0.odd, ba1.odd), 0.0f, 1.0f));
#else
  const REAL16 cov = (REAL16)((REAL)1);
#endif
  const float16 r = grain_tone16(rs, re, rq, nr, amt.x, grey, cov);
  const float16 g = grain_tone16(gs, ge, gq, ng, amt.y, grey, cov);
  const float16 b = grain_tone16(bs, be, bq, nb, amt.z, grey, cov);
  /* back to RGBA: (r, g) pairs, then each quad's RGB with b (one shuffle each:
   * CLFX_SHUFFLE16; vector literals of mixed parts lowered to ~7 shuffles a quad);
   * alpha as it was */
  const float16 org0 = CLFX_SHUFFLE16(r, g, 0, 16, 1, 17, 2, 18, 3, 19,
                                      4, 20, 5, 21, 6, 22, 7, 23);
  const float16 org1 = CLFX_SHUFFLE16(r, g, 8, 24, 9, 25, 10, 26, 11, 27,
                                      12, 28, 13, 29, 14, 30, 15, 31);
  const int16 is_alpha = (int16)(0, 0, 0, -1, 0, 0, 0, -1, 0, 0, 0, -1, 0, 0, 0, -1);
  *c0 = select(CLFX_SHUFFLE16(org0, b, 0, 1, 16, 16, 2, 3, 17, 17,
                              4, 5, 18, 18, 6, 7, 19, 19), f0, is_alpha);
  *c1 = select(CLFX_SHUFFLE16(org0, b, 8, 9, 20, 20, 10, 11, 21, 21,
                              12, 13, 22, 22, 14, 15, 23, 23), f1, is_alpha);
  *c2 = select(CLFX_SHUFFLE16(org1, b, 0, 1, 24, 24, 2, 3, 25, 25,
                              4, 5, 26, 26, 6, 7, 27, 27), f2, is_alpha);
  *c3 = select(CLFX_SHUFFLE16(org1, b, 8, 9, 28, 28, 10, 11, 29, 29,
                              12, 13, 30, 30, 14, 15, 31, 31), f3, is_alpha);
}

/* The three colour planes of 8 pixels' noise from grain_white32's RGBA lanes (alpha's 0s
 * dropped). */
#define GRAIN_PLANES(n0, n1, r, g, b)                                                          \
  const REAL8 r = (REAL8)((n0).s048c, (n1).s048c), g = (REAL8)((n0).s159d, (n1).s159d),      \
              b = (REAL8)((n0).s26ae, (n1).s26ae)

/* Noise, tmp: three planes (R, G, B) of rows x npitch (tpitch) values, plane c at offset
 * c * rows * npitch.  8 pixels per work-item (npitch is a multiple of 8). */
kernel void grain_noise(global REAL *noise, const int npitch, const int rows,
                        const int fx0, const int fy0, const uint seed, const int frame)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= rows || qx * 8 >= npitch) return;
  const int x = qx * 8;
  REAL16 n0, n1;
  grain_white32(seed, frame, fx0 + x, fy0 + y, &n0, &n1);
  GRAIN_PLANES(n0, n1, r, g, b);
  const size_t plane = (size_t)rows * npitch;
  global REAL *p = noise + (size_t)y * npitch + x;
  vstore8(r, 0, p);
  vstore8(g, 0, p + plane);
  vstore8(b, 0, p + 2 * plane);
}

/* sum_k w_k.c * v_k, k = 0..2R, for 16 pixels of the three planes at p (plane apart): v_k =
 * vload16 at p + k * step (step = one pixel for the horizontal pass, one row for the
 * vertical one).  Per lane the operations of the RGBA form's taps in their order; three
 * independent chains. */
CLFX_INLINE void grain_taps16x3(
    global const REAL *p, const size_t plane, const size_t step, global const REAL *weights,
    REAL16 *r, REAL16 *g, REAL16 *b)
{
  REAL16 ar = (REAL16)(0), ag = (REAL16)(0), ab = (REAL16)(0);
  for(int k = 0; k <= 2 * RADIUS; ++k)
  {
    const REAL4 w = vload4(k, weights);
    global const REAL *q = p + (size_t)k * step;
    ar += w.x * vload16(0, q);
    ag += w.y * vload16(0, q + plane);
    ab += w.z * vload16(0, q + 2 * plane);
  }
  *r = ar;
  *g = ag;
  *b = ab;
}

/* tmp(x, y) = sum_k w_k * noise(x + k, y), k = 0..2R: noise is offset by R in x; 16 pixels
 * of each plane a work-item (tpitch is a multiple of 16). */
kernel void grain_blur_h(global const REAL *noise, global REAL *tmp, global const REAL *weights,
                         const int npitch, const int tpitch, const int rows)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= rows || qx * 16 >= tpitch) return;
  const int x = qx * 16;
  REAL16 r, g, b;
  grain_taps16x3(noise + (size_t)y * npitch + x, (size_t)rows * npitch, 1, weights, &r, &g, &b);
  const size_t plane = (size_t)rows * tpitch;
  global REAL *o = tmp + (size_t)y * tpitch + x;
  vstore16(r, 0, o);
  vstore16(g, 0, o + plane);
  vstore16(b, 0, o + 2 * plane);
}

/* The 16 RGBA source pixels at i with their grain mixed in, stored back: rows are padded to
 * 4 pixels only, so the row's last 16 store only its quads < quads. */
CLFX_INLINE void grain_store16(
    global const float *src, global float *dst, const size_t i, const int quads,
    const REAL16 r, const REAL16 g, const REAL16 b, const REAL4 amt, const REAL response,
    const REAL grey, const REAL inv_grey)
{
  /* no branch in the loads: the tail loads its last quad again */
  float16 c0 = vload16(0, src + i), c1 = vload16(min(1, quads - 1), src + i);
  float16 c2 = vload16(min(2, quads - 1), src + i), c3 = vload16(quads - 1, src + i);
  grain_mix16x3(&c0, &c1, &c2, &c3, r, g, b, amt, response, grey, inv_grey);
  vstore16(c0, 0, dst + i);
  if(quads > 1)
    vstore16(c1, 1, dst + i);
  if(quads > 2)
    vstore16(c2, 2, dst + i);
  if(quads > 3)
    vstore16(c3, 3, dst + i);
}

/* Vertical taps (tmp is offset by R rows, tpitch a multiple of 16) and the mix with the
 * source; 16 pixels a work-item (grain_taps16x3). */
kernel void grain_apply(global const float *src, global float *dst, global const REAL *tmp,
                        global const REAL *weights, const int pitch, const int tpitch,
                        const int height, const float ar, const float ag, const float ab,
                        const float response, const float grey, const float inv_grey)
{
  const int ox = get_global_id(0), y = get_global_id(1);
  if(y >= height || ox * 16 >= pitch) return;
  const int x = ox * 16;
  REAL16 r, g, b;
  grain_taps16x3(tmp + (size_t)y * tpitch + x, (size_t)(height + 2 * RADIUS) * tpitch,
                 (size_t)tpitch, weights, &r, &g, &b);
  grain_store16(src, dst, (size_t)(y * pitch + x) * 4, min(4, (pitch - x) / 4), r, g, b,
                (REAL4)(ar, ag, ab, 0), response, grey, inv_grey);
}

/* Draft: white noise generated in place, one pass; 16 pixels a work-item (grain_white32
 * twice). */
kernel void grain_apply_white(global const float *src, global float *dst, const int pitch,
                              const int height, const int fx0, const int fy0, const uint seed,
                              const int frame, const float ar, const float ag, const float ab,
                              const float response, const float grey, const float inv_grey)
{
  const int ox = get_global_id(0), y = get_global_id(1);
  if(y >= height || ox * 16 >= pitch) return;
  const int x = ox * 16;
  REAL16 n0, n1, n2, n3;
  grain_white32(seed, frame, fx0 + x, fy0 + y, &n0, &n1);
  grain_white32(seed, frame, fx0 + x + 8, fy0 + y, &n2, &n3);
  const REAL16 r = (REAL16)(n0.s048c, n1.s048c, n2.s048c, n3.s048c);
  const REAL16 g = (REAL16)(n0.s159d, n1.s159d, n2.s159d, n3.s159d);
  const REAL16 b = (REAL16)(n0.s26ae, n1.s26ae, n2.s26ae, n3.s26ae);
  grain_store16(src, dst, (size_t)(y * pitch + x) * 4, min(4, (pitch - x) / 4), r, g, b,
                (REAL4)(ar, ag, ab, 0), response, grey, inv_grey);
}
