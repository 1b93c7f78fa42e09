/* resample.h: filtered reads of an RGBA image at continuous coordinates (clfx/fx/resample.py).
 *
 * Shared by chromatic_aberration.cl, lens.cl, breathing.cl and the footprint warps
 * (lib/footprint_warp.h: distortion.cl, keystone.cl).  Compile-time choices:
 *   RS_FILTER  0 = bilinear (2x2), 1 = bicubic (Keys, a = -0.5, 4x4), 2 = Lanczos-3 (6x6)
 *   RS_BORDER  0 = black (transparent: texels outside the image are 0),
 *              1 = edge (clamp to the nearest edge texel), 2 = mirror (periodic reflect-101)
 *   REAL / REAL4  (kernels/lib/precision.h) float, or double in a CLFX_FP64 build (the
 *                 reference levels): the type of coordinates, weights and sums; double
 *                 builds also evaluate Lanczos with libm sin/cos and have no packed path
 *
 * Coordinates are continuous pixel coordinates inside the source window: the centre of texel
 * (i, j) is (i + 0.5, j + 0.5).  Non-finite texels read as 0, so a NaN/Inf pixel never
 * spreads beyond the outputs whose footprint contains it, and then only as 0
 * (hard-cases.md case 2).  The per-texel test costs ~30% of a bilinear warp, so effects
 * compile it out (RS_SANITISE=0) when the frame's shared analysis found no non-finite
 * pixel.  A non-finite coordinate (the "no source" marker) gives 0.
 *
 * Anti-ringing (hard-cases.md case 5): bicubic and Lanczos-3 have negative lobes that ring
 * far below zero beside a 1e5 highlight.  Each output is clamped to the min/max of its
 * nearest 2x2 texels (the bilinear footprint); when those are >= 0 the result is >= 0.
 */
#ifndef CLFX_RESAMPLE_H
#define CLFX_RESAMPLE_H

#include "lib/common.h"
#include "lib/precision.h"
#ifndef RS_FILTER
#define RS_FILTER 0
#endif
#ifndef RS_BORDER
#define RS_BORDER 0
#endif
#ifndef RS_SANITISE
#define RS_SANITISE 1   /* 0 only when the frame's analysis counted no non-finite pixel */
#endif

#if RS_FILTER == 0
#define RS_TAPS 2
#elif RS_FILTER == 1
#define RS_TAPS 4
#else
#define RS_TAPS 6
#endif

/* A tile of a tiled render (clfx.kit.warp.CanvasRows): its buffers hold the canvas rows
 * from `shift` on (rows of `pitch` RGBA pixels), addressed in canvas rows from the prologue on
 * (CLFX_CANVAS_ROWS, kernels/lib/common.h), so its pixels take the whole render's arithmetic.
 *
 * The prologue of a kernel that renders canvas rows row0 .. row0 + rows, 4 output pixels (a
 * quad) per work-item: declares qx (the quad), my (the row within the band) and y (its
 * canvas row), returns past the band or the pitch (the global size is rounded up), then puts
 * both buffers in canvas rows. */
#define RS_BAND_PROLOGUE(src, src_pitch, dst, dst_pitch, rows, row0, shift)                 \
  const int qx = get_global_id(0), my = get_global_id(1), y = my + (row0);                  \
  if(my >= (rows) || qx * 4 >= (dst_pitch)) return;                                         \
  CLFX_CANVAS_ROWS(src, src_pitch, 4, shift);                                               \
  CLFX_CANVAS_ROWS(dst, dst_pitch, 4, shift)

/* The prologue of a kernel over `count` records (the checked quads of a band): declares n,
 * the record, returns past count, then puts both buffers in canvas rows. */
#define RS_RECORD_PROLOGUE(src, dst, pitch, count, shift)                                   \
  const int n = get_global_id(0);                                                           \
  if(n >= (count)) return;                                                                  \
  CLFX_CANVAS_ROWS(src, pitch, 4, shift);                                                   \
  CLFX_CANVAS_ROWS(dst, pitch, 4, shift)

/* Sanitised texels: kernels/lib/common.h's helpers, or the value itself where the frame's
 * analysis counted no non-finite pixel (RS_SANITISE 0). */
#if RS_SANITISE
#define rs_sanitise(v) clfx_finite4_or_zero(v)
#define rs_sanitise8(v) clfx_finite8_or_zero(v)
#define rs_sanitise16(v) clfx_finite16_or_zero(v)
#else
#define rs_sanitise(v) (v)
#define rs_sanitise8(v) (v)
#define rs_sanitise16(v) (v)
#endif

/* One texel with the border rule; (x, y) may lie anywhere. */
inline float4 rs_texel(global const float *src, int pitch, int w, int h, int x, int y)
{
#if RS_BORDER == 0
  if(x < 0 || y < 0 || x >= w || y >= h) return (float4)0.0f;
#elif RS_BORDER == 1
  x = clfx_clampi(x, 0, w - 1);
  y = clfx_clampi(y, 0, h - 1);
#else
  x = clfx_mirror(x, w);
  y = clfx_mirror(y, h);
#endif
  return rs_sanitise(vload4(y * pitch + x, src));
}

/* Lanczos-3 weights of taps k = -2..3 (from floor(coordinate - 0.5)) at fractional offset t in
 * [0, 1): L(d) = sinc(d) sinc(d/3) at d = t - k.  sin(pi (t - k)) = (-1)^k sin(pi t) and
 * sin(pi (t - k) / 3) follows from the angle-addition formula, so only one sin/cos pair is
 * evaluated.  Weights are normalised to sum 1. */
inline void rs_lanczos3_weights(REAL t, REAL *wt)
{
  const REAL pi = (REAL)3.14159265358979323846;
#if REAL_IS_DOUBLE
  const REAL s1 = sin(pi * t);
  const REAL a = pi * t / (REAL)3;
  const REAL sa = sin(a), ca = cos(a);
#else
  /* libm sin/cos (correctly rounded, no fast-math) dominated the cost; Taylor polynomials
   * on these short ranges are accurate to < 1e-8, below float32 resolution. */
  const REAL e = pi * (t - (REAL)0.5);            /* sin(pi t) = cos(e), |e| <= pi/2 */
  const REAL e2 = e * e;
  const REAL s1 = 1 + e2 * (-1.0f / 2 + e2 * (1.0f / 24 + e2 * (-1.0f / 720 + e2 * (1.0f / 40320
                  + e2 * (-1.0f / 3628800 + e2 * (1.0f / 479001600))))));
  const REAL a = pi * t / (REAL)3;                /* 0 <= a <= pi/3 */
  const REAL a2 = a * a;
  const REAL sa = a * (1 + a2 * (-1.0f / 6 + a2 * (1.0f / 120 + a2 * (-1.0f / 5040
                  + a2 * (1.0f / 362880 + a2 * (-1.0f / 39916800))))));
  const REAL ca = 1 + a2 * (-1.0f / 2 + a2 * (1.0f / 24 + a2 * (-1.0f / 720 + a2 * (1.0f / 40320
                  + a2 * (-1.0f / 3628800)))));
#endif
  const REAL s3 = (REAL)0.86602540378443864676; /* sin(pi/3) */
  REAL sum = 0;
#pragma unroll
  for(int i = 0; i < 6; i++) {
    const int k = i - 2;
    const REAL d = t - (REAL)k;
    /* sin(a - k pi/3): k pi/3 has cos/sin from the 6-periodic table */
    const int km = (k + 6) % 6;
    const REAL ck = (km == 0) ? (REAL)1 : (km == 1 || km == 5) ? (REAL)0.5
                  : (km == 3) ? (REAL)-1 : (REAL)-0.5;
    const REAL sk = (km == 0 || km == 3) ? (REAL)0 : (km == 1 || km == 2) ? s3 : -s3;
    const REAL sin_d3 = sa * ck - ca * sk;
    const REAL sin_d = (k & 1) ? -s1 : s1;
    const REAL wv = (fabs(d) < (REAL)1e-7) ? (REAL)1
                  : (REAL)3 * sin_d * sin_d3 / (pi * pi * d * d);
    wt[i] = wv;
    sum += wv;
  }
  const REAL inv = (REAL)1 / sum;
  for(int i = 0; i < 6; i++) wt[i] *= inv;
}

/* Separable weights for fractional offset t in [0, 1): tap k sits at integer offset
 * k - (RS_TAPS / 2 - 1) from floor(coordinate - 0.5). */
inline void rs_weights(REAL t, REAL *wt)
{
#if RS_FILTER == 0
  wt[0] = (REAL)1 - t;
  wt[1] = t;
#elif RS_FILTER == 1
  /* Keys cubic convolution, a = -0.5 (Catmull-Rom): interpolating, exact for quadratics */
  const REAL t2 = t * t, t3 = t2 * t;
  wt[0] = (REAL)-0.5 * t3 + t2 - (REAL)0.5 * t;
  wt[1] = (REAL)1.5 * t3 - (REAL)2.5 * t2 + (REAL)1;
  wt[2] = (REAL)-1.5 * t3 + (REAL)2 * t2 + (REAL)0.5 * t;
  wt[3] = (REAL)0.5 * t3 - (REAL)0.5 * t2;
#else
  rs_lanczos3_weights(t, wt);
#endif
}

#define RS_MINMAX(t) do { lo = fmin(lo, (t)); hi = fmax(hi, (t)); } while(0)

/* Filtered RGBA at (sx, sy) (source-window pixel coordinates, centres at +0.5), before the
 * anti-ringing clamp, whose bounds (the nearest 2x2 texels' min/max) go to *rlo, *rhi
 * (+-inf for bilinear, which needs none).  Footprints inside the image take a fast path:
 * each tap row is read with one or two vector loads (vload8 / vload16: 2 / 4 adjacent RGBA
 * texels) and no border rule. */
inline REAL4 rs_sample_range(global const float *src, int pitch, int w, int h, REAL sx,
                             REAL sy, float4 *rlo, float4 *rhi)
{
  *rlo = (float4)-INFINITY;
  *rhi = (float4)INFINITY;
  if(!(sx == sx) || !(sy == sy) || fabs(sx) > (REAL)1e7 || fabs(sy) > (REAL)1e7) {
    *rlo = *rhi = (float4)0.0f;
    return (REAL4)0;
  }
  const REAL fx = sx - (REAL)0.5, fy = sy - (REAL)0.5;
  const REAL flx = floor(fx), fly = floor(fy);
  const int ix = (int)flx, iy = (int)fly;
  const REAL tx = fx - flx, ty = fy - fly;
  const int off = RS_TAPS / 2 - 1;
  const int bx = ix - off, by = iy - off;
#if RS_FILTER == 0
  if(bx >= 0 && by >= 0 && bx + 2 <= w && by + 2 <= h) {
    global const float *base = src + (by * pitch + bx) * 4;
    const float8 a = rs_sanitise8(vload8(0, base));
    const float8 b = rs_sanitise8(vload8(0, base + pitch * 4));
    const REAL4 top = TO_REAL4(a.lo) + tx * (TO_REAL4(a.hi) - TO_REAL4(a.lo));
    const REAL4 bot = TO_REAL4(b.lo) + tx * (TO_REAL4(b.hi) - TO_REAL4(b.lo));
    return top + ty * (bot - top);
  }
#endif
  REAL wx[RS_TAPS], wy[RS_TAPS];
  rs_weights(tx, wx);
  rs_weights(ty, wy);
  REAL4 acc = (REAL4)0;
#if RS_FILTER > 0
  float4 lo = (float4)INFINITY, hi = (float4)-INFINITY;
  if(bx >= 0 && by >= 0 && bx + RS_TAPS <= w && by + RS_TAPS <= h) {
    global const float *base = src + (by * pitch + bx) * 4;
#pragma unroll
    for(int j = 0; j < RS_TAPS; j++) {
      const float16 r = rs_sanitise16(vload16(0, base + j * pitch * 4));
#if RS_FILTER == 1
      const REAL4 row = wx[0] * TO_REAL4(r.lo.lo) + wx[1] * TO_REAL4(r.lo.hi)
                      + wx[2] * TO_REAL4(r.hi.lo) + wx[3] * TO_REAL4(r.hi.hi);
      if(j == 1 || j == 2) { RS_MINMAX(r.lo.hi); RS_MINMAX(r.hi.lo); }
#else
      const float8 r2 = rs_sanitise8(vload8(0, base + j * pitch * 4 + 16));
      const REAL4 row = wx[0] * TO_REAL4(r.lo.lo) + wx[1] * TO_REAL4(r.lo.hi)
                      + wx[2] * TO_REAL4(r.hi.lo) + wx[3] * TO_REAL4(r.hi.hi)
                      + wx[4] * TO_REAL4(r2.lo) + wx[5] * TO_REAL4(r2.hi);
      if(j == 2 || j == 3) { RS_MINMAX(r.hi.lo); RS_MINMAX(r.hi.hi); }
#endif
      acc += wy[j] * row;
    }
    *rlo = lo;
    *rhi = hi;
    return acc;
  }
#endif
  for(int j = 0; j < RS_TAPS; j++) {
    REAL4 row = (REAL4)0;
    for(int i = 0; i < RS_TAPS; i++) {
      const float4 t = rs_texel(src, pitch, w, h, bx + i, by + j);
      row += wx[i] * TO_REAL4(t);
#if RS_FILTER > 0
      if((i == off || i == off + 1) && (j == off || j == off + 1)) RS_MINMAX(t);
#endif
    }
    acc += wy[j] * row;
  }
#if RS_FILTER > 0
  *rlo = lo;
  *rhi = hi;
#endif
  return acc;
}

/* rs_sample_range, clamped (hard-cases.md case 5). */
inline REAL4 rs_sample(global const float *src, int pitch, int w, int h, REAL sx, REAL sy)
{
  float4 lo, hi;
  const REAL4 acc = rs_sample_range(src, pitch, w, h, sx, sy, &lo, &hi);
#if RS_FILTER > 0
  return clamp(acc, TO_REAL4(lo), TO_REAL4(hi));
#else
  return acc;
#endif
}

/* The elliptical footprint of the reference levels (clfx.fx.resample.elliptical_spread): the
 * mean of n x n rs_sample_range samples at s + J_c (a_i, a_j), J_c's columns (c00, c10) and
 * (c01, c11), a_i = ((i + 1/2) / n - 1/2) sqrt(n^2 / (n^2 - 1)), clamped to the min/max of
 * all the samples' nearest 2x2 texels together; n <= 1 is one clamped sample (rs_sample). */
inline REAL4 rs_ewa_sample(global const float *src, int pitch, int w, int h, REAL sx, REAL sy,
                           REAL c00, REAL c10, REAL c01, REAL c11, int n)
{
  if(n <= 1) return rs_sample(src, pitch, w, h, sx, sy);
  const REAL scale = sqrt((REAL)(n * n) / (REAL)(n * n - 1)) / (REAL)n;
  REAL4 acc = (REAL4)0;
  float4 lo = (float4)INFINITY, hi = (float4)-INFINITY, l, u;
  for(int b = 0; b < n; b++) {
    const REAL ob = ((REAL)b + (REAL)0.5 - (REAL)0.5 * n) * scale;
    for(int a = 0; a < n; a++) {
      const REAL oa = ((REAL)a + (REAL)0.5 - (REAL)0.5 * n) * scale;
      acc += rs_sample_range(src, pitch, w, h, sx + c00 * oa + c01 * ob,
                             sy + c10 * oa + c11 * ob, &l, &u);
      lo = fmin(lo, l);
      hi = fmax(hi, u);
    }
  }
  return clamp(acc / (REAL)(n * n), TO_REAL4(lo), TO_REAL4(hi));
}

/* Four reads at once (the 4 pixels of a work-item): coordinates as float4 vectors so the
 * arithmetic is vectorised; for bilinear in float, when all four footprints are inside the
 * image each takes two vload8.  Results go to o[0..3]; written with macros, not loops over
 * private arrays, which PoCL spilled to memory. */
inline void rs_sample4(global const float *src, int pitch, int w, int h, float4 sx, float4 sy,
                       REAL4 *o0, REAL4 *o1, REAL4 *o2, REAL4 *o3)
{
#if RS_FILTER == 0 && !REAL_IS_DOUBLE
  const float4 fx = sx - 0.5f, fy = sy - 0.5f;
  const float4 flx = floor(fx), fly = floor(fy);
  const float4 tx = fx - flx, ty = fy - fly;
  const int4 ix = convert_int4_sat(flx), iy = convert_int4_sat(fly);   /* NaN -> 0 */
  const int4 ok = (ix >= 0) & (ix < w - 1) & (iy >= 0) & (iy < h - 1) & (sx == sx) & (sy == sy);
  if(all(ok)) {
    const int4 base = (iy * pitch + ix) * 4;
    const int row = pitch * 4;
#define RS_BILERP(k, o) {                                                  \
      const float8 a = rs_sanitise8(vload8(0, src + base.s##k));          \
      const float8 b = rs_sanitise8(vload8(0, src + base.s##k + row));    \
      *o = mix(mix(a.lo, a.hi, tx.s##k), mix(b.lo, b.hi, tx.s##k), ty.s##k); }
    RS_BILERP(0, o0) RS_BILERP(1, o1) RS_BILERP(2, o2) RS_BILERP(3, o3)
#undef RS_BILERP
    return;
  }
#endif
  *o0 = rs_sample(src, pitch, w, h, sx.s0, sy.s0);
  *o1 = rs_sample(src, pitch, w, h, sx.s1, sy.s1);
  *o2 = rs_sample(src, pitch, w, h, sx.s2, sy.s2);
  *o3 = rs_sample(src, pitch, w, h, sx.s3, sy.s3);
}

/* ---- Packed maps: a pure gather from a map precomputed once per parameter set ----------
 *
 * clfx.fx.resample.PackedMap turns a float64 map of source points into 12 ints per quad of 4
 * output pixels (a work-item): the float indices (iy * pitch + ix) * 4 of the texels
 * (ix, iy) = floor(source point - 0.5), the 4 x fractions and the 4 y fractions (float).
 * The fast kernel (rs_fast_quad) reads them for every quad: no floor, no conversion, no
 * border rule, no branch, one vector load per footprint row and float16 / float8
 * arithmetic.  Quads with a footprint leaving the source (or no source) are listed per
 * filter and re-rendered afterwards by a small kernel through rs_sample (rs_fix_quad);
 * the fast kernel clamps their texel indices so it never reads outside the buffer.
 * (A branch between the two paths inside one kernel cost 25%: PoCL's work-item loops.)
 */

/* Keys cubic (a = -0.5) weights of 4 (rs_cubic_w4) or 8 (rs_cubic_w8: both axes of a quad)
 * fractions at once */
#define RS_CUBIC_WN(name, T)                                                                  \
inline void name(T t, T *w0, T *w1, T *w2, T *w3)                                             \
{                                                                                             \
  const T t2 = t * t;                                                                         \
  *w0 = ((-0.5f * t + 1.0f) * t - 0.5f) * t;                                                  \
  *w1 = (1.5f * t - 2.5f) * t2 + 1.0f;                                                        \
  *w2 = ((-1.5f * t + 2.0f) * t + 0.5f) * t;                                                  \
  *w3 = (0.5f * t - 0.5f) * t2;                                                               \
}
RS_CUBIC_WN(rs_cubic_w4, float4)
RS_CUBIC_WN(rs_cubic_w8, float8)
#undef RS_CUBIC_WN

/* Lanczos-3 weights of 4 (rs_lanczos_w4) or 16 (rs_lanczos_w16: several axes and sample sets
 * of a quad in one zmm-wide evaluation) fractions at once: the same formula as rs_weights
 * (one sin/cos pair by Taylor polynomials, angle addition for the 6 taps, normalised to
 * sum 1). */
#define RS_LANCZOS_WN(name, T)                                                                \
inline void name(T t, T *w0, T *w1, T *w2, T *w3, T *w4, T *w5)                               \
{                                                                                             \
  const float pi = 3.14159265358979323846f;                                                   \
  const T e = pi * (t - 0.5f);                                                                \
  const T e2 = e * e;                                                                         \
  const T s1 = 1.0f + e2 * (-1.0f / 2 + e2 * (1.0f / 24 + e2 * (-1.0f / 720 + e2 * (1.0f / 40320 \
               + e2 * (-1.0f / 3628800 + e2 * (1.0f / 479001600))))));                        \
  const T a = pi * t / 3.0f;                                                                  \
  const T a2 = a * a;                                                                         \
  const T sa = a * (1.0f + a2 * (-1.0f / 6 + a2 * (1.0f / 120 + a2 * (-1.0f / 5040            \
               + a2 * (1.0f / 362880 + a2 * (-1.0f / 39916800))))));                          \
  const T ca = 1.0f + a2 * (-1.0f / 2 + a2 * (1.0f / 24 + a2 * (-1.0f / 720 + a2 * (1.0f / 40320 \
               + a2 * (-1.0f / 3628800)))));                                                  \
  const float s3 = 0.86602540378443864676f;                                                   \
  const T hs = 0.5f * sa, cs = s3 * ca;                                                       \
  const float pp = pi * pi;                                                                   \
  /* tap k = i - 2 at distance d = t - k: 3 sin(pi d) sin(pi d / 3) / (pi d)^2 */             \
  const T d0 = t + 2.0f, d1 = t + 1.0f, d3 = t - 1.0f, d4 = t - 2.0f, d5 = t - 3.0f;          \
  const T v0 = select(3.0f * s1 * (cs - hs) / (pp * d0 * d0), (T)1.0f, fabs(d0) < 1e-7f);     \
  const T v1 = select(3.0f * -s1 * (cs + hs) / (pp * d1 * d1), (T)1.0f, fabs(d1) < 1e-7f);    \
  const T v2 = select(3.0f * s1 * sa / (pp * t * t), (T)1.0f, fabs(t) < 1e-7f);               \
  const T v3 = select(3.0f * -s1 * (hs - cs) / (pp * d3 * d3), (T)1.0f, fabs(d3) < 1e-7f);    \
  const T v4 = select(3.0f * s1 * (-hs - cs) / (pp * d4 * d4), (T)1.0f, fabs(d4) < 1e-7f);    \
  const T v5 = select(3.0f * -s1 * -sa / (pp * d5 * d5), (T)1.0f, fabs(d5) < 1e-7f);          \
  const T inv = 1.0f / (((v0 + v1) + (v2 + v3)) + (v4 + v5));                                 \
  *w0 = v0 * inv; *w1 = v1 * inv; *w2 = v2 * inv; *w3 = v3 * inv; *w4 = v4 * inv; *w5 = v5 * inv; \
}
RS_LANCZOS_WN(rs_lanczos_w4, float4)
RS_LANCZOS_WN(rs_lanczos_w8, float8)
RS_LANCZOS_WN(rs_lanczos_w16, float16)
#undef RS_LANCZOS_WN

/* Broadcast lane k of four float4 weight vectors into a float16 (4 texels x RGBA) */
#define RS_W16(a, b, c, d, k) \
  (float16)((float4)((a).s##k), (float4)((b).s##k), (float4)((c).s##k), (float4)((d).s##k))
#define RS_HSUM16(v) (((v).lo.lo + (v).lo.hi) + ((v).hi.lo + (v).hi.hi))
/* A 4x4 window from p (rows of `row` floats): the rows r0..r3 (4 texels each), summed
 * vertically with y0..y3 on 16 lanes, then weighted horizontally with x0..x3: hs. */
#define RS_ROWS4(k)                                                                           \
    const float16 r0 = rs_sanitise16(vload16(0, p)), r1 = rs_sanitise16(vload16(0, p + row)); \
    const float16 r2 = rs_sanitise16(vload16(0, p + 2 * row));                               \
    const float16 r3 = rs_sanitise16(vload16(0, p + 3 * row));                               \
    const float16 v = fma(r3, (float16)y3.s##k, fma(r2, (float16)y2.s##k,                    \
                      fma(r1, (float16)y1.s##k, r0 * y0.s##k)));                             \
    const float16 hs = v * RS_W16(x0, x1, x2, x3, k);

/* The fast path: 4 outputs from texel bases (float indices of the footprint's (ix, iy)
 * texel) and fractions, every footprint inside the source. */
inline void rs_fast4(global const float *src, int pitch, int4 base, float4 tx, float4 ty,
                     float4 *o0, float4 *o1, float4 *o2, float4 *o3)
{
  const int row = pitch * 4;
#if RS_FILTER == 0
  /* 2x2, pixel by pixel: two vload8 (the top and bottom texel pairs) and three mixes
   * (gathering the 4 pixels into float16s first was 15% slower: the shuffles) */
#define RS_BILERP(k, o) {                                                                    \
    const float8 a = rs_sanitise8(vload8(0, src + base.s##k));                               \
    const float8 b = rs_sanitise8(vload8(0, src + base.s##k + row));                         \
    *o = mix(mix(a.lo, a.hi, tx.s##k), mix(b.lo, b.hi, tx.s##k), ty.s##k); }
  RS_BILERP(0, o0) RS_BILERP(1, o1) RS_BILERP(2, o2) RS_BILERP(3, o3)
#undef RS_BILERP
#elif RS_FILTER == 1
  float4 x0, x1, x2, x3, y0, y1, y2, y3;
  rs_cubic_w4(tx, &x0, &x1, &x2, &x3);
  rs_cubic_w4(ty, &y0, &y1, &y2, &y3);
  /* per pixel: the 4 rows (vload16 = 4 texels each) summed vertically with wy on 16 lanes,
   * then weighted horizontally; clamped to the central 2x2 texels (anti-ringing) */
#define RS_CUBIC(k, o) {                                                                     \
    global const float *p = src + base.s##k - row - 4;                                      \
    RS_ROWS4(k)                                                                              \
    const float4 lo = fmin(fmin(r1.s4567, r1.s89ab), fmin(r2.s4567, r2.s89ab));             \
    const float4 hi = fmax(fmax(r1.s4567, r1.s89ab), fmax(r2.s4567, r2.s89ab));             \
    *o = clamp(RS_HSUM16(hs), lo, hi); }
  RS_CUBIC(0, o0) RS_CUBIC(1, o1) RS_CUBIC(2, o2) RS_CUBIC(3, o3)
#undef RS_CUBIC
#else
  float4 x0, x1, x2, x3, x4, x5, y0, y1, y2, y3, y4, y5;
  rs_lanczos_w4(tx, &x0, &x1, &x2, &x3, &x4, &x5);
  rs_lanczos_w4(ty, &y0, &y1, &y2, &y3, &y4, &y5);
#define RS_LROW(j, wy)                                                                        \
    { const float16 a = rs_sanitise16(vload16(0, p + j * row));                              \
      const float8 b = rs_sanitise8(vload8(0, p + j * row + 16));                            \
      va = fma(a, (float16)(wy), va); vb = fma(b, (float8)(wy), vb);                         \
      if(j == 2 || j == 3) { lo = fmin(lo, fmin(a.s89ab, a.scdef));                           \
                             hi = fmax(hi, fmax(a.s89ab, a.scdef)); } }
#define RS_LANCZOS(k, o) {                                                                   \
    global const float *p = src + base.s##k - 2 * row - 8;                                  \
    float16 va = (float16)0.0f; float8 vb = (float8)0.0f;                                    \
    float4 lo = (float4)INFINITY, hi = (float4)-INFINITY;                                    \
    RS_LROW(0, y0.s##k) RS_LROW(1, y1.s##k) RS_LROW(2, y2.s##k)                              \
    RS_LROW(3, y3.s##k) RS_LROW(4, y4.s##k) RS_LROW(5, y5.s##k)                              \
    const float16 ha = va * RS_W16(x0, x1, x2, x3, k);                                       \
    const float8 hb = vb * (float8)((float4)x4.s##k, (float4)x5.s##k);                       \
    *o = clamp(RS_HSUM16(ha) + (hb.lo + hb.hi), lo, hi); }
  RS_LANCZOS(0, o0) RS_LANCZOS(1, o1) RS_LANCZOS(2, o2) RS_LANCZOS(3, o3)
#undef RS_LANCZOS
#undef RS_LROW
#endif
}

#if !REAL_IS_DOUBLE
/* 4 outputs of a quad from its 12 packed entries q (fast path, no border rule). */
inline void rs_fast_quad(global const float *src, int pitch, int w, int h, global const int *q,
                         float4 *o0, float4 *o1, float4 *o2, float4 *o3)
{
  const int off = RS_TAPS / 2 - 1;
  /* the footprints of border quads (re-rendered later) are pulled inside the image */
  const int4 base = clamp(vload4(0, q), (int4)(off * (pitch + 1) * 4),
                          (int4)(((h - RS_TAPS + off) * pitch + (w - RS_TAPS + off)) * 4));
  rs_fast4(src, pitch, base, as_float4(vload4(1, q)), as_float4(vload4(2, q)), o0, o1, o2, o3);
}

/* 4 outputs of a border quad from its points (4 x then 4 y, float) with the border rule. */
inline void rs_fix_quad(global const float *src, int pitch, int w, int h, global const int *c,
                        float4 *o0, float4 *o1, float4 *o2, float4 *o3)
{
  const float4 sx = as_float4(vload4(0, c)), sy = as_float4(vload4(1, c));
  *o0 = rs_sample(src, pitch, w, h, sx.s0, sy.s0);
  *o1 = rs_sample(src, pitch, w, h, sx.s1, sy.s1);
  *o2 = rs_sample(src, pitch, w, h, sx.s2, sy.s2);
  *o3 = rs_sample(src, pitch, w, h, sx.s3, sy.s3);
}
#else
/* Reference (double) builds read a float64 displacement map (clfx.fx.resample.upload_map:
 * rows of `pitch` pixels, (dx, dy) each): the source point of output pixel (x, y) is its
 * centre plus the displacement. */
inline REAL2 rs_map_point(global const REAL *map, int pitch, int x, int y)
{
  const int i = y * pitch + x;
  return (REAL2)((REAL)x + (REAL)0.5 + map[2 * i], (REAL)y + (REAL)0.5 + map[2 * i + 1]);
}
#endif

/* The 4 results of a quad, as float, to pixels i .. i + 3 of dst. */
inline void rs_store_quad(global float *dst, int i, const REAL4 *o)
{
  vstore16((float16)(TO_FLOAT4(o[0]), TO_FLOAT4(o[1]), TO_FLOAT4(o[2]), TO_FLOAT4(o[3])), 0,
           dst + i * 4);
}


#if !REAL_IS_DOUBLE
/* Cubic B-spline weights of 8 fractions at once (both axes of a quad; taps -1..2 of
 * floor(u), fraction t) */
inline void fp_bspline_w8(float8 t, float8 *w0, float8 *w1, float8 *w2, float8 *w3)
{
  const float8 t2 = t * t, t3 = t2 * t, u = 1.0f - t;
  *w0 = u * u * u * (1.0f / 6.0f);
  *w1 = (3.0f * t3 - 6.0f * t2 + 4.0f) * (1.0f / 6.0f);
  *w2 = (-3.0f * t3 + 3.0f * t2 + 3.0f * t + 1.0f) * (1.0f / 6.0f);
  *w3 = t3 * (1.0f / 6.0f);
}
#endif

/* 8 taps: the mean of l0..l5 (taps 0..5) and r0..r5 shifted by o = off (0, 1 or 2) */
#define FP_MERGE8(off, w) {                                                                   \
    const int4 o1 = (off) == 1.0f, o2 = (off) == 2.0f;                                      \
    const float4 z = (float4)0.0f;                                                           \
    w##0 = 0.5f * (l0 + select(select(r0, z, o1), z, o2));                                  \
    w##1 = 0.5f * (l1 + select(select(r1, r0, o1), z, o2));                                 \
    w##2 = 0.5f * (l2 + select(select(r2, r1, o1), r0, o2));                                \
    w##3 = 0.5f * (l3 + select(select(r3, r2, o1), r1, o2));                                \
    w##4 = 0.5f * (l4 + select(select(r4, r3, o1), r2, o2));                                \
    w##5 = 0.5f * (l5 + select(select(r5, r4, o1), r3, o2));                                \
    w##6 = 0.5f * select(select(z, r5, o1), r4, o2);                                        \
    w##7 = 0.5f * select(z, r5, o2); }

/* ---- Footprint filters: resampling that follows the map's local Jacobian ----------------
 *
 * Where a warp compresses the source (the map minifies), a fixed kernel read at one point
 * aliases: the output pixel's preimage covers several texels.  The footprint filters
 * (clfx.fx.resample.FootprintMap, FOOTPRINTS) widen the kernel per output pixel.  From the
 * map's Jacobian J = d(source) / d(output), the host takes the marginal widths of the
 * preimage, W_x^2 = J11^2 + J12^2 and W_y^2 = J21^2 + J22^2 (texels), and the extra variance
 * a box of that width has beyond the texel's own box, v = kappa max(W^2 - 1, 0) / 12; it
 * stores h = sqrt(v) (half float) per axis.  Magnified pixels (W <= 1) get h = 0: exactly
 * the plain filter.  FP_FILTER selects the filter (h sets the extra spread along each axis):
 *
 *   0  quadratic (draft, 3x3): the 3-point Lagrange interpolant about the nearest texel plus
 *      a variance term, weights ((q - d) / 2, 1 - q, (q + d) / 2), q = h^2 + d^2, d = the
 *      offset from the nearest texel's centre: the centroid is exact, the spread is h^2;
 *   1  bicubic (preview, 4x4): Keys (a = -0.5) blended with the cubic B-spline (variance
 *      1/3), alpha = 3 h^2, so the added variance is h^2;
 *   2  lanczos3 (final, 8x8): the mean of two normalised Lanczos-3 samples at u - h and
 *      u + h: exactly box_2 / box_1 = cos(pi f) at a 2x minification, variance h^2.
 *
 * Each output is clamped to the min/max of the texels within 1 + h of the point along both
 * axes (the union of the 2x2 footprints at u +- h): today's 2x2 anti-ringing clamp where
 * h = 0, and never tighter than the area the footprint averages.  The quadratic clamps to
 * its whole 3x3 window: its negative lobes sit on the outer taps only, so that bounds its
 * overshoot as tightly, for fewer instructions.
 *
 * Fast path (fp_fast_quad): per quad of 4 output pixels the packed map holds FP_Q_INTS ints:
 * the float indices of the windows' top-left texels (-1: the quad is rendered by the checked
 * path; -2: every output of the quad is 0, e.g. outside a black border), the fractions
 * f_x (4), f_y (4) and (h_x, h_y) as half2 (4).  f is d in [-0.5, 0.5) (quadratic),
 * t = frac(u) (bicubic), or frac(u - h) (lanczos3), u = the point in texel units (texel k at
 * u = k); the window starts at round(u) - 1, floor(u) - 1 or floor(u - h) - 2.  The
 * quadratic stores f as half (12 ints a quad, steps of at most 2^-12 texel: the map is read
 * once per output pixel, as many bytes as the source, and the draft is bound by memory);
 * the others as float32 (16 ints: positions to ~1e-7 texel); clfx.fx.resample.FootprintMap
 * writes the layout (a kernel with an affine map computes the same values per work-item and
 * calls fp_fast_quad_at: breathing.cl).  Checked path (fp_sample): any point, the border
 * rule per texel; footprints too wide for one window are split by the host into n x n
 * sub-footprints (J / n each) and averaged (fp_sample_n).
 */
#ifndef FP_FILTER
#define FP_FILTER 2
#endif
#if FP_FILTER == 0
#define FP_TAPS 3
#elif FP_FILTER == 1
#define FP_TAPS 4
#else
#define FP_TAPS 8
#endif
#ifndef FP_Q_INTS
#define FP_Q_INTS 16    /* clfx.fx.resample.Footprint.entry_ints: 12, fractions as half */
#endif
/* How many quads ahead fp_prefetch_quad asks for: the memory's latency in quads of work, so
 * it depends on the machine.  Draft at 1080p on two machines of this project: the first ran
 * best at 32 (8: 3.35 ms, 16: 2.9, 32: 2.5, 64: 3.0); the second, where the draft and
 * cv2.remap both ran about half as fast, at 16-24 (12: 4.4, 16: 4.4-4.8, 20: 4.6-4.7,
 * 24: 4.4-4.6, 32: 4.9-5.4, 64: 5.2-5.9).  24 sits between the two (not measured on the
 * first).  A build may set it (-D FP_PREFETCH_AHEAD=n) to tune. */
#ifndef FP_PREFETCH_AHEAD
#define FP_PREFETCH_AHEAD 24
#endif
/* 1: the lanczos3 fast path takes its shortcuts (one weight set where both coincide, the
 * 2x2 clamp), 0: every quad through the general forms: the same pixels, bit for bit (a
 * test builds both) */
#ifndef FP_SHORTCUTS
#define FP_SHORTCUTS 1
#endif

#if !REAL_IS_DOUBLE
/* One axis: the weights of the window's FP_TAPS taps from the fraction f and spread h. */
inline void fp_weights(float f, float h, float *w)
{
#if FP_FILTER == 0
  const float q = h * h + f * f;
  w[0] = 0.5f * (q - f);
  w[1] = 1.0f - q;
  w[2] = 0.5f * (q + f);
#elif FP_FILTER == 1
  const float t = f, t2 = t * t, t3 = t2 * t, u = 1.0f - t;
  const float a = fmin(3.0f * h * h, 1.0f);
  const float k0 = -0.5f * t3 + t2 - 0.5f * t, k1 = 1.5f * t3 - 2.5f * t2 + 1.0f;
  const float k2 = -1.5f * t3 + 2.0f * t2 + 0.5f * t, k3 = 0.5f * t3 - 0.5f * t2;
  const float b0 = u * u * u / 6.0f, b1 = (3.0f * t3 - 6.0f * t2 + 4.0f) / 6.0f;
  const float b2 = (-3.0f * t3 + 3.0f * t2 + 3.0f * t + 1.0f) / 6.0f, b3 = t3 / 6.0f;
  w[0] = k0 + a * (b0 - k0);
  w[1] = k1 + a * (b1 - k1);
  w[2] = k2 + a * (b2 - k2);
  w[3] = k3 + a * (b3 - k3);
#else
  float l[6], r[6];
  rs_lanczos3_weights(f, l);
  const float p = f + 2.0f * h, fl = floor(p);
  const int o = (int)fl;                        /* 0, 1 or 2: h < 1 */
  rs_lanczos3_weights(p - fl, r);
  for(int k = 0; k < 8; k++) {
    const int j = k - o;
    w[k] = 0.5f * ((k < 6 ? l[k] : 0.0f) + ((j >= 0 && j < 6) ? r[j] : 0.0f));
  }
#endif
}

/* The clamp's taps [c0, c1] of the window: the texels within 1 + h of u (written from the
 * fraction exactly as the fast path does); the quadratic's whole window. */
inline void fp_clamp_range(float f, float h, int *c0, int *c1)
{
#if FP_FILTER == 0
  *c0 = 0;                                      /* the whole 3x3 window */
  *c1 = 2;
#elif FP_FILTER == 2
  *c0 = 2;                                      /* u - h = f + 2 */
  *c1 = (int)ceil((f + 2.0f * h) + 2.0f);
#else
  *c0 = (int)floor(f + 1.0f - h);
  *c1 = (int)ceil(f + 1.0f + h);
#endif
}

/* The window's first texel and its fraction along one axis at continuous coordinate p
 * (texel centres at +0.5) with spread h: fp_window for one point, fp_window4 for 4 (the same
 * operations lane by lane). */
#if FP_FILTER == 0
#define FP_WINDOW_N(name, T, IT)                                                              \
inline IT name(T p, float h, T *f)                                                            \
{ const T m = floor(p); *f = p - m - 0.5f; return convert_##IT(m) - 1; }
#elif FP_FILTER == 1
#define FP_WINDOW_N(name, T, IT)                                                              \
inline IT name(T p, float h, T *f)                                                            \
{ const T u = p - 0.5f, i = floor(u); *f = u - i; return convert_##IT(i) - 1; }
#else
#define FP_WINDOW_N(name, T, IT)                                                              \
inline IT name(T p, float h, T *f)                                                            \
{ const T m = p - h - 0.5f, i = floor(m); *f = m - i; return convert_##IT(i) - 2; }
#endif
FP_WINDOW_N(fp_window, float, int)
FP_WINDOW_N(fp_window4, float4, int4)
#undef FP_WINDOW_N

/* The footprint filter at (sx, sy) with spreads (hx, hy), texels through the border rule. */
inline float4 fp_sample(global const float *src, int pitch, int w, int h, float sx, float sy,
                        float hx, float hy)
{
  if(!(sx == sx) || !(sy == sy) || fabs(sx) > 1e7f || fabs(sy) > 1e7f) return (float4)0.0f;
  float fx, fy, wx[FP_TAPS], wy[FP_TAPS];
  int cx0, cx1, cy0, cy1;
  const int x0 = fp_window(sx, hx, &fx), y0 = fp_window(sy, hy, &fy);
  fp_weights(fx, hx, wx);
  fp_weights(fy, hy, wy);
  fp_clamp_range(fx, hx, &cx0, &cx1);
  fp_clamp_range(fy, hy, &cy0, &cy1);
  float4 acc = (float4)0.0f, lo = (float4)INFINITY, hi = (float4)-INFINITY;
  const int cols_inside = x0 >= 0 && x0 + FP_TAPS <= w;
  for(int j = 0; j < FP_TAPS; j++) {
    const int yy = y0 + j, rin = j >= cy0 && j <= cy1;
#if RS_BORDER == 0
    if(yy < 0 || yy >= h) {                   /* a black row: adds 0, may bound the clamp */
      if(rin) { lo = fmin(lo, (float4)0.0f); hi = fmax(hi, (float4)0.0f); }
      continue;
    }
#endif
    float4 row = (float4)0.0f;
    if(cols_inside && yy >= 0 && yy < h) {     /* no border rule needed along this row */
      global const float *p = src + (yy * pitch + x0) * 4;
      for(int i = 0; i < FP_TAPS; i++) {
        const float4 t = rs_sanitise(vload4(i, p));
        row += wx[i] * t;
        if(rin && i >= cx0 && i <= cx1) { lo = fmin(lo, t); hi = fmax(hi, t); }
      }
    } else {
      for(int i = 0; i < FP_TAPS; i++) {
        const float4 t = rs_texel(src, pitch, w, h, x0 + i, yy);
        row += wx[i] * t;
        if(rin && i >= cx0 && i <= cx1) { lo = fmin(lo, t); hi = fmax(hi, t); }
      }
    }
    acc += wy[j] * row;
  }
  return clamp(acc, lo, hi);
}

/* The footprint filter at (sx, sy) split into n x n sub-footprints centred at
 * s + J ((a + 1/2) / n - 1/2, (b + 1/2) / n - 1/2), each with spreads (hx, hy), averaged;
 * n <= 1 is one footprint (fp_sample).  The checked path: out of line on a CPU device
 * (CLFX_COLD), so a kernel calling it for a quad's pixels stays small. */
CLFX_COLD float4 fp_sample_grid(global const float *src, int pitch, int w, int h, float sx,
                             float sy, float hx, float hy, int n, float j11, float j12,
                             float j21, float j22)
{
  if(n <= 1) return fp_sample(src, pitch, w, h, sx, sy, hx, hy);
  const float inv = 1.0f / (float)(n * n);    /* scaled before the sum: no overflow */
  float4 acc = (float4)0.0f;
  for(int b = 0; b < n; b++) {
    const float ob = ((float)b + 0.5f) / (float)n - 0.5f;
    for(int a = 0; a < n; a++) {
      const float oa = ((float)a + 0.5f) / (float)n - 0.5f;
      acc += inv * fp_sample(src, pitch, w, h, sx + j11 * oa + j12 * ob,
                             sy + j21 * oa + j22 * ob, hx, hy);
    }
  }
  return acc;
}

/* Output k of a checked quad: record c = 4 x, 4 y (float), 4 (hx, hy) half2, 4 sub-footprint
 * counts n, then J11, J12, J21, J22 (4 floats each): fp_sample_grid. */
inline float4 fp_sample_n(global const float *src, int pitch, int w, int h,
                          global const int *c, int k)
{
  const float2 hh = vload_half2(k, (global const half *)(c + 8));
  return fp_sample_grid(src, pitch, w, h, as_float(c[k]), as_float(c[4 + k]), hh.x, hh.y,
                        c[12 + k], as_float(c[16 + k]), as_float(c[20 + k]),
                        as_float(c[24 + k]), as_float(c[28 + k]));
}

/* The fast path: 4 outputs of a quad from its FP_Q_INTS packed ints q (every window inside the
 * source; the clamp reads the texels already loaded for the weighted sum).  Sums run
 * vertically first on whole rows (float16 = 4 texels); min/max instead of fmin/fmax (the
 * texels are finite: sanitised, or the frame has no NaN/Inf), the final clamp keeps
 * fmin/fmax semantics so an overflowing sum of huge finite texels stays finite. */

/* Ask a CPU device to fetch the source rows of the fast quad q (its first and last windows'
 * ends, every row of the window) into cache: the map decides the addresses, so the
 * hardware prefetchers, which follow strides, miss them where the map curves across rows
 * (the draft at 1920x1080 spent ~40% of its time waiting for them). */
inline void fp_prefetch_quad(global const float *src, int pitch, global const int *q)
{
#if CLFX_CAN_PREFETCH
  if(q[0] < 0) return;
  global const float *a = src + q[0], *b = src + q[3] + 4 * (FP_TAPS - 1);
  for(int j = 0; j < FP_TAPS; j++) {
    clfx_prefetch(a + (size_t)j * pitch * 4);
    clfx_prefetch(b + (size_t)j * pitch * 4);
  }
#endif
}

/* The fast path from the quad's values: the windows' float indices base, fractions
 * f8 = (f_x of the 4 pixels, f_y of the 4) and spreads hh = (h_x, h_y) of each pixel
 * interleaved, as a packed quad holds them (a kernel with an affine map passes its own:
 * breathing.cl). */
CLFX_INLINE void fp_fast_quad_at(global const float *src, int pitch,
                                 int4 base, float8 f8, float8 hh,
                                 float4 *o0, float4 *o1,
                                 float4 *o2, float4 *o3)
{
  const int row = pitch * 4;
  const float4 fx = f8.lo, fy = f8.hi;
  const float4 hx = hh.even, hy = hh.odd;
#if FP_FILTER == 0
  /* 3x3, the quad's 4 pixels side by side (lanes 4k..4k+3 = pixel k): each of the 9 taps
   * is one float16 of 4 texels (aligned float4 loads: a texel is 16 bytes), weighted by
   * per-pixel weights spread with one permute, so every operation is 16 lanes wide with no
   * horizontal reduction; clamped to the whole window (the Lagrange lobes sit on the outer
   * taps, so this bounds the overshoot as a 2x2 would).  The rows-per-pixel form it replaced
   * (float16 rows, vertical then horizontal sums) took 1.6x the CPU time (15.5 vs 9.8 ms on
   * the 1920x1080 bench map; cv2.remap bilinear 7.9 ms). */
  const float8 h8 = shuffle(hh, (uint8)(0, 2, 4, 6, 1, 3, 5, 7)); /* (h_x, h_y) */
  const float8 q8 = fma(h8, h8, f8 * f8);
  const float8 w0 = 0.5f * (q8 - f8), w1 = 1.0f - q8, w2 = 0.5f * (q8 + f8);
  const uint16 mx = (uint16)(0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3), my = mx + 4u;
  const float16 x0 = shuffle(w0, mx), x1 = shuffle(w1, mx), x2 = shuffle(w2, mx);
  global const float4 *t = (global const float4 *)src;
  global const float4 *p0 = t + (base.s0 >> 2), *p1 = t + (base.s1 >> 2);
  global const float4 *p2 = t + (base.s2 >> 2), *p3 = t + (base.s3 >> 2);
  const size_t rt = (size_t)pitch;
#define FP_TAP(o) rs_sanitise16((float16)(p0[o], p1[o], p2[o], p3[o]))
#define FP_ROW(j) const float16 a##j = FP_TAP(j * rt), b##j = FP_TAP(j * rt + 1),           \
                                c##j = FP_TAP(j * rt + 2);                                   \
                  const float16 r##j = fma(c##j, x2, fma(b##j, x1, a##j * x0));
  FP_ROW(0) FP_ROW(1) FP_ROW(2)
  const float16 acc = fma(r2, shuffle(w2, my), fma(r1, shuffle(w1, my), r0 * shuffle(w0, my)));
  const float16 lo = min(min(min(a0, b0), c0), min(min(min(a1, b1), c1), min(min(a2, b2), c2)));
  const float16 hi = max(max(max(a0, b0), c0), max(max(max(a1, b1), c1), max(max(a2, b2), c2)));
#undef FP_ROW
#undef FP_TAP
  /* clamp, NaN (inf - inf of an overflowing sum) and +-inf to the bounds: finite out */
  const float16 c = select(lo, acc, acc > lo), r = select(hi, c, c < hi);
  *o0 = r.s0123;
  *o1 = r.s4567;
  *o2 = r.s89ab;
  *o3 = r.scdef;
#elif FP_FILTER == 1
  /* both axes at once: lanes 0-3 x, 4-7 y */
  float8 k0, k1, k2, k3, b0, b1, b2, b3;
  const float8 t8 = (float8)(fx, fy), h8 = (float8)(hx, hy);
  const float8 a8 = fmin(3.0f * h8 * h8, 1.0f);
  rs_cubic_w8(t8, &k0, &k1, &k2, &k3);
  fp_bspline_w8(t8, &b0, &b1, &b2, &b3);
  const float8 m0 = k0 + a8 * (b0 - k0), m1 = k1 + a8 * (b1 - k1);
  const float8 m2 = k2 + a8 * (b2 - k2), m3 = k3 + a8 * (b3 - k3);
  const float4 x0 = m0.lo, x1 = m1.lo, x2 = m2.lo, x3 = m3.lo;
  const float4 y0 = m0.hi, y1 = m1.hi, y2 = m2.hi, y3 = m3.hi;
  /* clamp taps [floor(u - h), ceil(u + h)] with u = f + 1: columns as lane masks (a texel
   * outside reads as its row's texel 1, always inside), rows 0 and 3 when included */
  const int4 cx0 = convert_int4(floor(fx + 1.0f - hx)), cx1 = convert_int4(ceil(fx + 1.0f + hx));
  const int4 cy0 = convert_int4(floor(fy + 1.0f - hy)), cy1 = convert_int4(ceil(fy + 1.0f + hy));
  const int16 lane = (int16)(0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3);
#define FP_CLAMPROW(r) { const float16 m = select((float16)(r.s4567, r.s4567, r.s4567, r.s4567), \
                                                  r, cm); lo = min(lo, m); hi = max(hi, m); }
#define FP_PIXEL(k, o) {                                                                     \
    global const float *p = src + base.s##k;                                                 \
    RS_ROWS4(k)                                                                              \
    const int16 cm = (lane >= (int16)cx0.s##k) & (lane <= (int16)cx1.s##k);                  \
    float16 lo = (float16)(r1.s4567, r1.s4567, r1.s4567, r1.s4567), hi = lo;                 \
    FP_CLAMPROW(r1)                                                                          \
    if(cy1.s##k >= 2) FP_CLAMPROW(r2)                                                        \
    if(cy0.s##k <= 0) FP_CLAMPROW(r0)                                                        \
    if(cy1.s##k >= 3) FP_CLAMPROW(r3)                                                        \
    *o = clamp(RS_HSUM16(hs), min(min(lo.lo.lo, lo.lo.hi), min(lo.hi.lo, lo.hi.hi)),         \
               max(max(hi.lo.lo, hi.lo.hi), max(hi.hi.lo, hi.hi.hi))); }
  FP_PIXEL(0, o0) FP_PIXEL(1, o1) FP_PIXEL(2, o2) FP_PIXEL(3, o3)
#undef FP_PIXEL
#undef FP_CLAMPROW
#else
  /* two Lanczos-3 weight sets per axis: at f (taps 0..5) and at f + 2h (taps o..o+5) */
  float4 l0, l1, l2, l3, l4, l5, r0, r1, r2, r3, r4, r5;
  float4 x0, x1, x2, x3, x4, x5, x6, x7, y0, y1, y2, y3, y4, y5, y6, y7;
  const float4 px = fx + 2.0f * hx, py = fy + 2.0f * hy;
  const float4 flx = floor(px), fly = floor(py);
  /* the four weight sets in one 16-wide evaluation: x at f, x at f + 2h, y, y; where the
   * second set of each axis is the first (h = 0: the map magnifies, 63 % of the quads of
   * distortion at 1080p), one 8-wide evaluation copied (the same lane-wise operations, so
   * the same weights, for half the divisions and polynomials) */
  float16 g0, g1, g2, g3, g4, g5;
  const float8 f8s = (float8)(fx, fy), p8s = (float8)(px - flx, py - fly);
  if(FP_SHORTCUTS && all(p8s == f8s)) {
    float8 k0, k1, k2, k3, k4, k5;
    rs_lanczos_w8(f8s, &k0, &k1, &k2, &k3, &k4, &k5);
    g0 = (float16)(k0.lo, k0.lo, k0.hi, k0.hi); g1 = (float16)(k1.lo, k1.lo, k1.hi, k1.hi);
    g2 = (float16)(k2.lo, k2.lo, k2.hi, k2.hi); g3 = (float16)(k3.lo, k3.lo, k3.hi, k3.hi);
    g4 = (float16)(k4.lo, k4.lo, k4.hi, k4.hi); g5 = (float16)(k5.lo, k5.lo, k5.hi, k5.hi);
  } else {
    rs_lanczos_w16((float16)(f8s.lo, p8s.lo, f8s.hi, p8s.hi), &g0, &g1, &g2, &g3, &g4, &g5);
  }
  l0 = g0.s0123; l1 = g1.s0123; l2 = g2.s0123; l3 = g3.s0123; l4 = g4.s0123; l5 = g5.s0123;
  r0 = g0.s4567; r1 = g1.s4567; r2 = g2.s4567; r3 = g3.s4567; r4 = g4.s4567; r5 = g5.s4567;
  FP_MERGE8(flx, x)
  l0 = g0.s89ab; l1 = g1.s89ab; l2 = g2.s89ab; l3 = g3.s89ab; l4 = g4.s89ab; l5 = g5.s89ab;
  r0 = g0.scdef; r1 = g1.scdef; r2 = g2.scdef; r3 = g3.scdef; r4 = g4.scdef; r5 = g5.scdef;
  FP_MERGE8(fly, y)
  /* the clamp: taps 2 .. ceil(u + h) = ceil(f + 2 + 2h) along each axis (u - h = f + 2).
   * Mostly the 2x2 texels 2..3 of rows 2..3 (f + 2h <= 1: 98 % of the fast pixels of
   * distortion at 1080p), two float8 rows of 2 texels, the same minima and maxima in the
   * same order as the general form: texels 2..5 of each row as one float16, those beyond
   * the range read as texel 2 (its row reductions cost as much as the row's taps) */
  const int4 cx1 = convert_int4(ceil(px + 2.0f)), cy1 = convert_int4(ceil(py + 2.0f));
  const int4 oy = convert_int4(fly);
  const int16 lane = (int16)(2, 2, 2, 2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5);
  /* the x weights, lane 4 i + k = tap i of pixel k: a pixel's (RS_W16) in one permute */
  const float16 xlo = (float16)(x0, x1, x2, x3), xhi = (float16)(x4, x5, x6, x7);
#define FP_ROW(j, wy) { const float16 a = rs_sanitise16(vload16(0, p + j * row));            \
    const float16 b = rs_sanitise16(vload16(0, p + j * row + 16));                           \
    va = fma(a, (float16)(wy), va); vb = fma(b, (float16)(wy), vb);                          \
    if(j >= 2 && j <= 5 && wide && j <= yb) {                                                \
      const float16 c = (float16)(a.hi, b.lo);                                                \
      const float16 m = select((float16)(a.s89ab, a.s89ab, a.s89ab, a.s89ab), c, cm);       \
      lo = min(lo, m); hi = max(hi, m); } }
#define FP_PIXEL(k, o) {                                                                     \
    global const float *p = src + base.s##k;                                                 \
    const int yb = cy1.s##k, xb = cx1.s##k, wide = !FP_SHORTCUTS || xb > 3 || yb > 3;        \
    const int16 cm = lane <= (int16)xb;                                                      \
    float16 va = (float16)0.0f, vb = (float16)0.0f;                                          \
    float16 lo = (float16)INFINITY, hi = (float16)-INFINITY;                                 \
    FP_ROW(0, y0.s##k) FP_ROW(1, y1.s##k) FP_ROW(2, y2.s##k) FP_ROW(3, y3.s##k)              \
    FP_ROW(4, y4.s##k) FP_ROW(5, y5.s##k)                                                    \
    if(oy.s##k >= 1) FP_ROW(6, y6.s##k)                                                      \
    if(oy.s##k >= 2) FP_ROW(7, y7.s##k)                                                      \
    const uint16 wk = (uint16)(k, k, k, k, 4 + k, 4 + k, 4 + k, 4 + k,                       \
                               8 + k, 8 + k, 8 + k, 8 + k, 12 + k, 12 + k, 12 + k, 12 + k);  \
    const float16 ha = va * shuffle(xlo, wk), hb = vb * shuffle(xhi, wk);                    \
    /* RS_HSUM16(ha) + RS_HSUM16(hb), the same sums: both vectors' pairs in one add */      \
    const float16 pq = shuffle2(ha, hb, (uint16)(0, 1, 2, 3, 16, 17, 18, 19,                 \
                                                 8, 9, 10, 11, 24, 25, 26, 27))              \
                     + shuffle2(ha, hb, (uint16)(4, 5, 6, 7, 20, 21, 22, 23,                 \
                                                 12, 13, 14, 15, 28, 29, 30, 31));           \
    const float8 hs = pq.lo + pq.hi;                                                         \
    float4 l4, h4;                                                                           \
    if(wide) {                                                                               \
      l4 = min(min(lo.lo.lo, lo.lo.hi), min(lo.hi.lo, lo.hi.hi));                            \
      h4 = max(max(hi.lo.lo, hi.lo.hi), max(hi.hi.lo, hi.hi.hi));                            \
    } else {                                                                                 \
      const float8 c2 = rs_sanitise8(vload8(0, p + 2 * row + 8));                            \
      const float8 c3 = rs_sanitise8(vload8(0, p + (yb >= 3 ? 3 : 2) * row + 8));            \
      const float8 mn = min(c2, c3), mx = max(c2, c3);                                       \
      l4 = min(mn.lo, xb >= 3 ? mn.hi : mn.lo);                                              \
      h4 = max(mx.lo, xb >= 3 ? mx.hi : mx.lo);                                              \
    }                                                                                        \
    *o = clamp(hs.lo + hs.hi, l4, h4); }
  FP_PIXEL(0, o0) FP_PIXEL(1, o1) FP_PIXEL(2, o2) FP_PIXEL(3, o3)
#undef FP_PIXEL
#undef FP_ROW
#endif
}

/* The fast path of a packed quad q (FP_Q_INTS ints of a packed map). */
CLFX_INLINE void fp_fast_quad(global const float *src, int pitch,
                              global const int *q, float4 *o0,
                              float4 *o1, float4 *o2, float4 *o3)
{
#if FP_Q_INTS == 12
  const float8 f8 = vload_half8(0, (global const half *)(q + 4));  /* (f_x, f_y) */
#else
  const float8 f8 = as_float8(vload8(0, q + 4));
#endif
  fp_fast_quad_at(src, pitch, vload4(0, q), f8,
                  vload_half8(0, (global const half *)(q + FP_Q_INTS - 4)), o0, o1, o2, o3);
}
#endif

#endif
