/* blur.cl: separable Gaussian blur and pyramid resampling (clfx/blur.py has the model).
 *
 * Every kernel works on rows of CH floats per pixel (CH = 1, 2 or 4) and handles 4
 * consecutive pixels per work-item as one vector of 4*CH floats (float4 / float8 / float16):
 * rows are padded to a multiple of 4 pixels, so there is no tail code and PoCL runs the
 * inner loops as vector FMAs (notes/performance.md).
 *
 * Defines
 *   CH          channels per pixel (1, 2, 4)
 *   TAPS        a rung of the tap-count ladder (clfx/fx/blur.py): the most taps the program
 *               takes, its tap loops fully unrolled with the taps past the real count (a
 *               runtime argument, `taps`) skipped, never read or weighted by 0 (0 * Inf is
 *               NaN); 0 or undefined: any count, a plain loop (unrolled loops are what
 *               costs to compile).  Direct kernels take 2 * radius + 1 taps.
 *   (border mode: a runtime argument of the direct kernels, only read near the borders:
 *    0 = zero (black outside), 1 = clamp to edge, 2 = mirror (reflect-101, periodic: any
 *    index stays in bounds); the gathers get mapped indices from the host)
 *   CLFX_FP64   accumulate (and hold weights) in REAL = double (lib/precision.h): the
 *               `reference` level, and gathers with many taps
 *
 * Kernels
 *   blur_direct_h  Gaussian along rows with shared weights; interior quads read 4*CH
 *                  contiguous floats per tap with no index arithmetic, border quads map
 *                  each lane's index through the border mode.
 *   blur_direct_v  the same along columns (the border mapping is one scalar per tap).
 *   blur_gather_h  out[y][j] = sum_t w[j][t] * in[y][idx[j][t]]  (tables from the host:
 *                  pyramid decimation, coarse blur, B-spline upsampling, window changes)
 *   blur_gather_v  out[j][x] = sum_t w[j][t] * in[idx[j][t]][x]  (4 pixels share taps)
 *   blur_sanitize  copy with non-finite values set to 0; counts bad pixels per row.
 */
#include "lib/common.h"
#include "lib/precision.h"

#ifndef CH
#define CH 4
#endif
#ifndef TAPS
#define TAPS 0
#endif
/* TAP_LOOP(t, n): for t = 0 .. n - 1, in order (the sums are the same as with n exactly
 * compiled in).  With a rung, unrolled to TAPS guarded steps; without, a runtime loop. */
#if TAPS > 0
#define TAP_LOOP(t, n) _Pragma("unroll") for(int t = 0; t < TAPS; ++t) if(t < (n))
#else
#define TAP_LOOP(t, n) for(int t = 0; t < (n); ++t)
#endif

typedef REAL wtype;

/* QUAD: the 4 pixels of a work-item; PIX: one pixel; realq_t / realp_t: their accumulators
 * (REAL vectors of the same width) and TO_REALQ / TO_REALP / TO_FLOATQ their conversions. */
#if CH == 4
typedef float16 quad_t;
typedef float4 pix_t;
typedef REAL16 realq_t;
typedef REAL4 realp_t;
#define LOADQ(i, p) vload16(0, (p) + (size_t)(i) * 4)
#define STOREQ(v, i, p) vstore16((v), 0, (p) + (size_t)(i) * 4)
#define LOADP(i, p) vload4(0, (p) + (size_t)(i) * 4)
#define STOREP(v, i, p) vstore4((v), 0, (p) + (size_t)(i) * 4)
#define TO_REALQ TO_REAL16
#define TO_REALP TO_REAL4
#define TO_FLOATQ TO_FLOAT16
#elif CH == 2
typedef float8 quad_t;
typedef float2 pix_t;
typedef REAL8 realq_t;
typedef REAL2 realp_t;
#define LOADQ(i, p) vload8(0, (p) + (size_t)(i) * 2)
#define STOREQ(v, i, p) vstore8((v), 0, (p) + (size_t)(i) * 2)
#define LOADP(i, p) vload2(0, (p) + (size_t)(i) * 2)
#define STOREP(v, i, p) vstore2((v), 0, (p) + (size_t)(i) * 2)
#define TO_REALQ TO_REAL8
#define TO_REALP TO_REAL2
#define TO_FLOATQ TO_FLOAT8
#else /* CH == 1 */
typedef float4 quad_t;
typedef float pix_t;
typedef REAL4 realq_t;
typedef REAL realp_t;
#define LOADQ(i, p) vload4(0, (p) + (size_t)(i))
#define STOREQ(v, i, p) vstore4((v), 0, (p) + (size_t)(i))
#define LOADP(i, p) ((p)[(size_t)(i)])
#define STOREP(v, i, p) ((p)[(size_t)(i)] = (v))
#define TO_REALQ TO_REAL4
#define TO_REALP TO_REAL
#define TO_FLOATQ TO_FLOAT4
#endif

/* Index of the pixel that stands for index i of a line of n pixels under the border mode.
 * For the zero mode the index is clamped and blur_inside() gives the weight factor 0. */
inline int blur_map(int i, int n, int border)
{
  return border == 2 ? clfx_mirror(i, n) : clamp(i, 0, n - 1);
}

inline wtype blur_inside(int i, int n, int border)
{
  return (border != 0 || (i >= 0 && i < n)) ? (wtype)1 : (wtype)0;
}

/* Gaussian along rows.  dst column j is src column j + offset; `rows` rows of both. */
kernel void blur_direct_h(global const float *src, const int src_pitch, const int src_width,
                          global float *dst, const int dst_pitch, const int rows,
                          const int offset, global const wtype *weights, const int taps,
                          const int border)
{
  const int q = get_global_id(0), y = get_global_id(1);
  if(y >= rows || q * 4 >= dst_pitch) return;
  global const float *row = src + (size_t)y * src_pitch * CH;
  const int first = q * 4 + offset - (taps - 1) / 2;   /* input index of tap 0 of lane 0 */
  realq_t acc = (realq_t)(0);
  if(first >= 0 && first + 2 + taps < src_width)
  {
    /* interior: every tap is a contiguous load of the 4 pixels, no index arithmetic */
    TAP_LOOP(t, taps)
      acc += weights[t] * TO_REALQ(LOADQ(first + t, row));
  }
  else
  {
    realp_t a0 = (realp_t)(0), a1 = (realp_t)(0), a2 = (realp_t)(0), a3 = (realp_t)(0);
    for(int t = 0; t < taps; ++t)
    {
      const wtype w = weights[t];
      const int i = first + t;
      a0 += w * blur_inside(i, src_width, border) * TO_REALP(LOADP(blur_map(i, src_width, border), row));
      a1 += w * blur_inside(i + 1, src_width, border) * TO_REALP(LOADP(blur_map(i + 1, src_width, border), row));
      a2 += w * blur_inside(i + 2, src_width, border) * TO_REALP(LOADP(blur_map(i + 2, src_width, border), row));
      a3 += w * blur_inside(i + 3, src_width, border) * TO_REALP(LOADP(blur_map(i + 3, src_width, border), row));
    }
    acc = (realq_t)(a0, a1, a2, a3);
  }
  STOREQ(TO_FLOATQ(acc), (size_t)y * dst_pitch + q * 4, dst);
}

/* Gaussian along columns.  dst row j is src row j + offset; both have `pitch` pixels. */
kernel void blur_direct_v(global const float *src, const int src_rows, global float *dst,
                          const int dst_rows, const int pitch, const int offset,
                          global const wtype *weights, const int taps, const int border)
{
  const int q = get_global_id(0), j = get_global_id(1);
  if(j >= dst_rows || q * 4 >= pitch) return;
  const int first = j + offset - (taps - 1) / 2;
  global const float *col = src + (size_t)q * 4 * CH;
  realq_t acc = (realq_t)(0);
  if(first >= 0 && first + taps <= src_rows)
  {
    TAP_LOOP(t, taps)
      acc += weights[t] * TO_REALQ(LOADQ((size_t)(first + t) * pitch, col));
  }
  else
  {
    for(int t = 0; t < taps; ++t)
    {
      const int i = first + t;
      const wtype w = weights[t] * blur_inside(i, src_rows, border);
      acc += w * TO_REALQ(LOADQ((size_t)blur_map(i, src_rows, border) * pitch, col));
    }
  }
  STOREQ(TO_FLOATQ(acc), (size_t)j * pitch + q * 4, dst);
}

/* Table-driven gather along rows: out[y][j] = sum_t w[j*taps+t] * in[y][idx[j*taps+t]].
 * The tables cover dst_pitch columns (padding columns point at valid pixels). */
kernel void blur_gather_h(global const float *src, const int src_pitch, global float *dst,
                          const int dst_pitch, const int rows, global const int *idx,
                          global const wtype *wtab, const int taps)
{
  const int q = get_global_id(0), y = get_global_id(1);
  if(y >= rows || q * 4 >= dst_pitch) return;
  global const float *row = src + (size_t)y * src_pitch * CH;
  const int j = q * 4;
  global const int *i0 = idx + (size_t)j * taps;
  global const wtype *w0 = wtab + (size_t)j * taps;
  realp_t a0 = (realp_t)(0), a1 = (realp_t)(0), a2 = (realp_t)(0), a3 = (realp_t)(0);
  TAP_LOOP(t, taps)
  {
    a0 += w0[t] * TO_REALP(LOADP(i0[t], row));
    a1 += w0[taps + t] * TO_REALP(LOADP(i0[taps + t], row));
    a2 += w0[2 * taps + t] * TO_REALP(LOADP(i0[2 * taps + t], row));
    a3 += w0[3 * taps + t] * TO_REALP(LOADP(i0[3 * taps + t], row));
  }
  STOREQ(TO_FLOATQ(((realq_t)(a0, a1, a2, a3))), (size_t)y * dst_pitch + j, dst);
}

/* Table-driven gather along columns: out[j][x] = sum_t w[j*taps+t] * in[idx[j*taps+t]][x]. */
kernel void blur_gather_v(global const float *src, global float *dst, const int pitch,
                          const int dst_rows, global const int *idx, global const wtype *wtab,
                          const int taps)
{
  const int q = get_global_id(0), j = get_global_id(1);
  if(j >= dst_rows || q * 4 >= pitch) return;
  global const float *col = src + (size_t)q * 4 * CH;
  global const int *i0 = idx + (size_t)j * taps;
  global const wtype *w0 = wtab + (size_t)j * taps;
  realq_t acc = (realq_t)(0);
  TAP_LOOP(t, taps)
    acc += w0[t] * TO_REALQ(LOADQ((size_t)i0[t] * pitch, col));
  STOREQ(TO_FLOATQ(acc), (size_t)j * pitch + q * 4, dst);
}

/* One work-item per row: copy with every non-finite float set to 0 (exponent-bit test, so it
 * survives any build flags); counts[y] = pixels of the row with any non-finite channel. */
kernel void blur_sanitize(global const float *src, global float *dst, const int pitch,
                          const int width, const int rows, global int *counts)
{
  const int y = get_global_id(0);
  if(y >= rows) return;
  int bad = 0;
  for(int x = 0; x < pitch; ++x)
  {
    const size_t i = ((size_t)y * pitch + x) * CH;
    int pixel_bad = 0;
    for(int c = 0; c < CH; ++c)
    {
      const float v = src[i + c];
      const int ok = clfx_is_finite(v);
      pixel_bad |= !ok;
      dst[i + c] = ok ? v : 0.0f;
    }
    bad += (x < width) & pixel_bad;
  }
  counts[y] = bad;
}
