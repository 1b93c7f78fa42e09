/* motion_gather.h: sampling helpers shared by lib/motion.cl and camera_blur.cl.
 *
 * BILINEAR (define, default 1) selects bilinear or nearest fetches; JITTER (default 1)
 * selects interleaved-gradient jitter or the midpoint rule.
 */
#ifndef CLFX_MOTION_GATHER_H
#define CLFX_MOTION_GATHER_H
#include "lib/common.h"

#ifndef BILINEAR
#define BILINEAR 1
#endif
#ifndef JITTER
#define JITTER 1
#endif

/* A band of a tiled render (the rows `clfx.kit.motion.band_margin` grows it by): its buffers
 * hold the canvas rows from `row0` on, addressed in canvas rows (CLFX_CANVAS_ROWS,
 * kernels/lib/common.h).  Reads clamp to the rows the buffer holds (row0 <= y < row1): the
 * canvas's edges where the buffer reaches them, elsewhere never hit (the band's margin covers
 * every read). */

/* Colour at continuous position (px, py) (pixel centres at +0.5), clamp-to-edge (rows
 * row0 <= y < row1), times `scale`.  The float index is clamped before the int conversion
 * so far-off positions cannot overflow; the corners are scaled before they are
 * interpolated, so with scale <= 1/2 no difference of finite colours can overflow either. */
inline float4 mg_fetch_scaled(global const float *col, const int pitch, const int w,
                              const int row0, const int row1, const float px, const float py,
                              const float scale)
{
#if BILINEAR
  const float u = px - 0.5f, v = py - 0.5f;
  const float fu = floor(u), fv = floor(v);
  const float ax = u - fu, ay = v - fv;
  const int iu = (int)clamp(fu, -1.0f, (float)w);
  const int iv = (int)clamp(fv, (float)(row0 - 1), (float)row1);
  const int xa = clfx_clampi(iu, 0, w - 1), xb = clfx_clampi(iu + 1, 0, w - 1);
  const int ya = clfx_clampi(iv, row0, row1 - 1), yb = clfx_clampi(iv + 1, row0, row1 - 1);
  const float4 c00 = vload4(ya * pitch + xa, col) * scale;
  const float4 c10 = vload4(ya * pitch + xb, col) * scale;
  const float4 c01 = vload4(yb * pitch + xa, col) * scale;
  const float4 c11 = vload4(yb * pitch + xb, col) * scale;
  const float4 top = c00 + (c10 - c00) * ax, bot = c01 + (c11 - c01) * ax;
  return top + (bot - top) * ay;
#else
  const int x = (int)clamp(floor(px), 0.0f, (float)(w - 1));
  const int y = (int)clamp(floor(py), (float)row0, (float)(row1 - 1));
  return vload4(y * pitch + x, col) * scale;
#endif
}

/* A float4 of 4 lanes' values as a float16, each lane's value over its pixel's 4 channels */
#define SPLAT16(w) (float16)((w).xxxx, (w).yyyy, (w).zzzz, (w).wwww)

/* The pixels at flat indices i of the 4 lanes, times `scale`, lane-major */
#define MG_GATHER4(buf, i, scale) \
  ((float16)(vload4((i).x, buf), vload4((i).y, buf), vload4((i).z, buf), vload4((i).w, buf)) \
   * (scale))

/* mg_fetch_scaled at the 4 lanes' own positions (px, py) at once: per element the same
 * operations, the lanes' arithmetic in one float16 */
CLFX_INLINE float16 mg_fetch4_scaled(global const float *col, const int pitch, const int w,
                                     const int row0, const int row1, const float4 px,
                                     const float4 py, const float scale)
{
#if BILINEAR
  const float4 u = px - 0.5f, v = py - 0.5f;
  const float4 fu = floor(u), fv = floor(v);
  const float4 ax = u - fu, ay = v - fv;
  const int4 iu = convert_int4(clamp(fu, -1.0f, (float)w));
  const int4 iv = convert_int4(clamp(fv, (float)(row0 - 1), (float)row1));
  const int4 xa = clamp(iu, (int4)(0), (int4)(w - 1));
  const int4 xb = clamp(iu + 1, (int4)(0), (int4)(w - 1));
  const int4 ya = clamp(iv, (int4)(row0), (int4)(row1 - 1)) * pitch;
  const int4 yb = clamp(iv + 1, (int4)(row0), (int4)(row1 - 1)) * pitch;
  const float16 c00 = MG_GATHER4(col, ya + xa, scale), c10 = MG_GATHER4(col, ya + xb, scale);
  const float16 c01 = MG_GATHER4(col, yb + xa, scale), c11 = MG_GATHER4(col, yb + xb, scale);
  const float16 top = c00 + (c10 - c00) * SPLAT16(ax), bot = c01 + (c11 - c01) * SPLAT16(ax);
  return top + (bot - top) * SPLAT16(ay);
#else
  const int4 x = convert_int4(clamp(floor(px), 0.0f, (float)(w - 1)));
  const int4 y = convert_int4(clamp(floor(py), (float)row0, (float)(row1 - 1)));
  return MG_GATHER4(col, y * pitch + x, scale);
#endif
}

/* Colour at continuous position (px, py): mg_fetch_scaled unscaled. */
inline float4 mg_fetch(global const float *col, const int pitch, const int w, const int row0,
                       const int row1, const float px, const float py)
{
  return mg_fetch_scaled(col, pitch, w, row0, row1, px, py, 1.0f);
}

/* Interleaved gradient noise (Jimenez 2014): a jitter in [0, 1) whose pattern has no low
 * frequencies, so banding between samples turns into fine, even grain; shifted per frame.
 * Without JITTER: 0.5, the midpoint rule (deterministic, O(spacing^2) error). */
inline float4 mg_jitter(const float4 x, const float y, const int frame)
{
#if !JITTER
  return (float4)(0.5f);
#endif
  const float o = 5.588238f * (float)(frame & 63);
  const float4 a = 0.06711056f * (x + o) + 0.00583715f * (y + o);
  const float4 b = 52.9829189f * (a - floor(a));
  return b - floor(b);
}

#endif
