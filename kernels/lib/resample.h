/* resample.h: filtered reads of an RGBA image at continuous coordinates (clfx/fx/resample.py).
 *
 * Shared by distortion.cl, chromatic_aberration.cl and lens.cl.  Compile-time choices:
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

/* Non-finite lanes (exponent bits all ones) become 0; a vector select, no branches. */
inline float4 rs_sanitise(float4 v)
{
#if !RS_SANITISE
  return v;
#endif
  const int4 bad = (as_int4(v) & (int4)0x7f800000) == (int4)0x7f800000;
  return select(v, (float4)0.0f, bad);
}

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
  /* Lanczos-3: L(d) = sinc(d) sinc(d/3) at d = t - k, k = -2..3.  sin(pi (t - k)) =
   * (-1)^k sin(pi t) and sin(pi (t - k) / 3) follows from the angle-addition formula, so
   * only one sin/cos pair per axis is evaluated.  Weights are normalised to sum 1. */
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
#endif
}

/* Sanitised vector loads: non-finite lanes read as 0. */
inline float8 rs_sanitise8(float8 v)
{
#if !RS_SANITISE
  return v;
#endif
  return select(v, (float8)0.0f, (as_int8(v) & (int8)0x7f800000) == (int8)0x7f800000);
}

inline float16 rs_sanitise16(float16 v)
{
#if !RS_SANITISE
  return v;
#endif
  return clfx_finite16_or_zero(v);
}

#define RS_MINMAX(t) do { lo = fmin(lo, (t)); hi = fmax(hi, (t)); } while(0)

/* Filtered RGBA at (sx, sy) (source-window pixel coordinates, centres at +0.5).
 * Footprints inside the image take a fast path: each tap row is read with one or two
 * vector loads (vload8 / vload16: 2 / 4 adjacent RGBA texels) and no border rule. */
inline REAL4 rs_sample(global const float *src, int pitch, int w, int h, REAL sx, REAL sy)
{
  if(!(sx == sx) || !(sy == sy) || fabs(sx) > (REAL)1e7 || fabs(sy) > (REAL)1e7)
    return (REAL4)0;
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
    return clamp(acc, TO_REAL4(lo), TO_REAL4(hi));
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
  acc = clamp(acc, TO_REAL4(lo), TO_REAL4(hi));
#endif
  return acc;
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

/* Keys cubic (a = -0.5) weights of 4 pixels at once */
inline void rs_cubic_w4(float4 t, float4 *w0, float4 *w1, float4 *w2, float4 *w3)
{
  const float4 t2 = t * t;
  *w0 = ((-0.5f * t + 1.0f) * t - 0.5f) * t;
  *w1 = (1.5f * t - 2.5f) * t2 + 1.0f;
  *w2 = ((-1.5f * t + 2.0f) * t + 0.5f) * t;
  *w3 = (0.5f * t - 0.5f) * t2;
}

/* Lanczos-3 weights of 4 pixels at once: the same formula as rs_weights (one sin/cos pair
 * by Taylor polynomials, angle addition for the 6 taps, normalised to sum 1). */
inline void rs_lanczos_w4(float4 t, float4 *w0, float4 *w1, float4 *w2, float4 *w3,
                          float4 *w4, float4 *w5)
{
  const float pi = 3.14159265358979323846f;
  const float4 e = pi * (t - 0.5f);
  const float4 e2 = e * e;
  const float4 s1 = 1.0f + e2 * (-1.0f / 2 + e2 * (1.0f / 24 + e2 * (-1.0f / 720 + e2 * (1.0f / 40320
                    + e2 * (-1.0f / 3628800 + e2 * (1.0f / 479001600))))));
  const float4 a = pi * t / 3.0f;
  const float4 a2 = a * a;
  const float4 sa = a * (1.0f + a2 * (-1.0f / 6 + a2 * (1.0f / 120 + a2 * (-1.0f / 5040
                    + a2 * (1.0f / 362880 + a2 * (-1.0f / 39916800))))));
  const float4 ca = 1.0f + a2 * (-1.0f / 2 + a2 * (1.0f / 24 + a2 * (-1.0f / 720 + a2 * (1.0f / 40320
                    + a2 * (-1.0f / 3628800)))));
  const float s3 = 0.86602540378443864676f;
  const float4 hs = 0.5f * sa, cs = s3 * ca;
  const float pp = pi * pi;
  /* tap k = i - 2 at distance d = t - k: 3 sin(pi d) sin(pi d / 3) / (pi d)^2 */
#define RS_LZ(d, sin_d, sin_d3) \
  select(3.0f * (sin_d) * (sin_d3) / (pp * (d) * (d)), (float4)1.0f, fabs(d) < 1e-7f)
  const float4 v0 = RS_LZ(t + 2.0f, s1, cs - hs);
  const float4 v1 = RS_LZ(t + 1.0f, -s1, cs + hs);
  const float4 v2 = RS_LZ(t, s1, sa);
  const float4 v3 = RS_LZ(t - 1.0f, -s1, hs - cs);
  const float4 v4 = RS_LZ(t - 2.0f, s1, -hs - cs);
  const float4 v5 = RS_LZ(t - 3.0f, -s1, -sa);
#undef RS_LZ
  const float4 inv = 1.0f / (((v0 + v1) + (v2 + v3)) + (v4 + v5));
  *w0 = v0 * inv; *w1 = v1 * inv; *w2 = v2 * inv; *w3 = v3 * inv; *w4 = v4 * inv; *w5 = v5 * inv;
}

/* Broadcast lane k of four float4 weight vectors into a float16 (4 texels x RGBA) */
#define RS_W16(a, b, c, d, k) \
  (float16)((float4)((a).s##k), (float4)((b).s##k), (float4)((c).s##k), (float4)((d).s##k))
#define RS_HSUM16(v) (((v).lo.lo + (v).lo.hi) + ((v).hi.lo + (v).hi.hi))

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
    const float16 r0 = rs_sanitise16(vload16(0, p)), r1 = rs_sanitise16(vload16(0, p + row)); \
    const float16 r2 = rs_sanitise16(vload16(0, p + 2 * row));                               \
    const float16 r3 = rs_sanitise16(vload16(0, p + 3 * row));                               \
    const float16 v = fma(r3, (float16)y3.s##k, fma(r2, (float16)y2.s##k,                    \
                      fma(r1, (float16)y1.s##k, r0 * y0.s##k)));                             \
    const float16 hsum = v * RS_W16(x0, x1, x2, x3, k);                                      \
    const float4 lo = fmin(fmin(r1.s4567, r1.s89ab), fmin(r2.s4567, r2.s89ab));             \
    const float4 hi = fmax(fmax(r1.s4567, r1.s89ab), fmax(r2.s4567, r2.s89ab));             \
    *o = clamp(RS_HSUM16(hsum), lo, hi); }
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

#endif
