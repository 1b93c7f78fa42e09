/* bleed.cl: sensor crosstalk (clfx/plugins/bleed.py): the glare family's soft-knee threshold
 * and energy-conserving mix (lib/scatter.h) with a small exponential PSF.  Large PSFs take
 * bleed_highlights -> lib/fftconv.cl -> bleed_mix (SCATTER_KERNELS).
 *
 * Small PSFs (radius <= 10 px) take a fused, block-skipping path:
 *   1. bleed_pad_highlights: the highlight image h on a zero-padded grid `hp` around the
 *      output window (output pixel (x, y) <-> hp pixel (x + PADX, y + RADIUS)), and one flag
 *      per 4 x ROWS block of hp telling whether any h there is non-zero;
 *   2. bleed_active: per 4 x ROWS output block, whether any non-zero h is within reach;
 *   3. bleed_direct_mix (exact PSF) or bleed_separable_mix (rank-RANK approximation):
 *      inactive blocks copy the (sanitised) source, active ones gather h and mix.
 * Every kernel works on 4 RGBA pixels as one float16 (PoCL does not vectorise across
 * work-items); the gathers also hold ROWS output rows per work-item so that each loaded input
 * row is reused by every output row within reach.  RADIUS, ROWS and RANK are compile-time
 * constants and the loops are unrolled, so taps outside the PSF's disc cost nothing.  A build
 * with RANK defined holds the separable kernel, one without it the direct kernel.
 * No atomics: identical bytes across runs and thread counts.
 */
#include "lib/scatter.h"
#include "lib/precision.h"

#ifndef RADIUS
#define RADIUS 1
#endif
#ifndef ROWS
#define ROWS 8
#endif
/* left/right padding of hp in pixels: a multiple of 4 >= RADIUS keeps quads aligned */
#define PADX (4 * ((RADIUS + 3) / 4))
#define TAPS (2 * RADIUS + 1)
#define IN_ROWS (ROWS + 2 * RADIUS)

/* Tap (dy, dx) lies inside the PSF's support disc d <= RADIUS + 0.5 (clfx.fx.psf.exponential). */
#define IN_DISC(dy, dx) (4 * ((dy) * (dy) + (dx) * (dx)) <= (2 * RADIUS + 1) * (2 * RADIUS + 1))

SCATTER_KERNELS(bleed)

/* Highlights on the padded grid: hp pixel (X, Y) holds h of source pixel (X - ox, Y - oy)
 * (0 outside the source).  One work-item: 4 pixels x ROWS rows; flags[by * (hpitch / 4) + qx]
 * = 1 if any of them is non-zero. */
kernel void bleed_pad_highlights(global const float *src, const int spitch, const int swidth,
                                 const int sheight, const int ox, const int oy,
                                 global float *hp, const int hpitch, const int hheight,
                                 global uchar *flags, const float threshold, const float knee)
{
  const int qx = get_global_id(0), by = get_global_id(1);
  if(qx * 4 >= hpitch || by * ROWS >= hheight) return;
  int16 hit = (int16)(0);
  for(int r = 0; r < ROWS; r++)
  {
    const int y = by * ROWS + r;
    if(y >= hheight) break;
    const float16 c = scatter_load4px(src, spitch, swidth, sheight, qx * 4 - ox, y - oy);
    const float16 h = scatter_highlights16(c, threshold, knee, 0.0f);
    hit |= h != (float16)(0.0f);
    vstore16(h, 0, hp + ((size_t)y * hpitch + qx * 4) * 4);
  }
  flags[(size_t)by * (hpitch / 4) + qx] = any(hit) ? 1 : 0;
}

/* active[by * (pitch / 4) + qx] = 1 if output block (qx, by) (4 x ROWS pixels) has a non-zero
 * highlight within RADIUS px, i.e. in hp columns [4 qx + PADX - R, 4 qx + 3 + PADX + R] and
 * rows [by ROWS, by ROWS + ROWS - 1 + 2R]. */
kernel void bleed_active(global const uchar *flags, const int fpitch, const int fheight,
                         global uchar *active, const int pitch, const int blocks_y)
{
  const int qx = get_global_id(0), by = get_global_id(1);
  if(qx * 4 >= pitch || by >= blocks_y) return;
  const int fx0 = (qx * 4 + PADX - RADIUS) / 4, fx1 = (qx * 4 + 3 + PADX + RADIUS) / 4;
  const int fy1 = min((by * ROWS + IN_ROWS - 1) / ROWS, fheight - 1);
  int hit = 0;
  for(int fy = by; fy <= fy1; fy++)
    for(int fx = fx0; fx <= fx1; fx++)
      hit |= flags[(size_t)fy * fpitch + fx];
  active[(size_t)by * (pitch / 4) + qx] = hit ? 1 : 0;
}

/* One output quad: out = c - strength h + strength tint max(g, 0), alpha from c (lib/scatter.h's
 * model), saturated at +-FLT_MAX (finite input, finite output).  h is the centre highlight
 * (scatter_highlights16, boost 0) and has alpha 0; the tint has alpha 0, so alpha is
 * c's exactly. */
inline void bleed_store_mixed(global const float *src, int spitch, int swidth, int sheight,
                              global float *dst, int pitch, int x, int y, int dx, int dy,
                              float16 g, float16 h, float strength, float4 tint)
{
  const float16 tint16 = (float16)(tint.xyz, 0.0f, tint.xyz, 0.0f, tint.xyz, 0.0f, tint.xyz, 0.0f);
  const float16 c = scatter_load4px(src, spitch, swidth, sheight, x + dx, y + dy);
  const float16 o = c + strength * tint16 * fmax(g, 0.0f) - strength * h;
  vstore16(clamp(o, -SCATTER_FLT_MAX, SCATTER_FLT_MAX), 0, dst + ((size_t)y * pitch + x) * 4);
}

/* Inactive rows y0 .. y1 - 1 of a block: no light arrives and none leaves, out = sanitised
 * source. */
inline void bleed_copy_rows(global const float *src, int spitch, int swidth, int sheight,
                            global float *dst, int pitch, int x, int y0, int y1, int dx, int dy)
{
  for(int y = y0; y < y1; y++)
    vstore16(scatter_load4px(src, spitch, swidth, sheight, x + dx, y + dy), 0,
             dst + ((size_t)y * pitch + x) * 4);
}

#define HP_QUAD(row, col) vload16(0, hp + ((size_t)(row) * hpitch + (col)) * 4)

/* The arguments both fused mixes share, before their weights: the padded highlights, the
 * active-block flags, the source and the output; (dx, dy): output origin minus source
 * origin. */
#define BLEED_MIX_ARGS                                                                        \
  global const float *hp, const int hpitch, global const uchar *active,                      \
  global const float *src, const int spitch, const int swidth, const int sheight,            \
  global float *dst, const int pitch, const int height, const int dx, const int dy,          \
  const float strength, const float4 tint

#ifndef RANK
/* Exact PSF (`psf`: TAPS x TAPS, centre at (RADIUS, RADIUS)), direct gather:
 * g(y, x) = sum_{a, b} h(y + a, x - b) psf(RADIUS - a, RADIUS + b), weights and sums in REAL
 * (lib/precision.h: float64 for the reference level). */
kernel void bleed_direct_mix(BLEED_MIX_ARGS, constant REAL *psf)
{
  /* one output row per work-item: holding several rows' sums per work-item spills on PoCL */
  const int qx = get_global_id(0), y = get_global_id(1);
  const int x = qx * 4;
  if(x >= pitch || y >= height) return;
  if(!active[(size_t)(y / ROWS) * (pitch / 4) + qx])
  {
    bleed_copy_rows(src, spitch, swidth, sheight, dst, pitch, x, y, y + 1, dx, dy);
    return;
  }
  REAL16 acc = (REAL16)(0);
  /* tap (a, b): input pixel (y + a, x - b) = hp pixel (y + RADIUS + a, x + PADX - b), PSF
   * entry (RADIUS - a, RADIUS + b); taps outside the disc vanish at compile time */
#pragma unroll
  for(int a = -RADIUS; a <= RADIUS; a++)
#pragma unroll
    for(int b = -RADIUS; b <= RADIUS; b++)
      if(IN_DISC(a, b))
        acc += psf[(RADIUS - a) * TAPS + RADIUS + b] * TO_REAL16(HP_QUAD(y + RADIUS + a, x + PADX - b));
  bleed_store_mixed(src, spitch, swidth, sheight, dst, pitch, x, y, dx, dy, convert_float16(acc),
                    HP_QUAD(y + RADIUS, x + PADX), strength, tint);
}
#endif /* !RANK */

#ifdef RANK
/* Rank-RANK separable approximation psf ~ sum_k s_k u_k u_k^T: for every input row, RANK
 * horizontal TAPS-tap sums; each is added to the output rows within reach with the vertical
 * weights.  `hvec`: RANK x TAPS (u_k), `vvec`: RANK x TAPS (s_k u_k).  float32. */
kernel void bleed_separable_mix(BLEED_MIX_ARGS, constant float *hvec, constant float *vvec)
{
  const int qx = get_global_id(0), by = get_global_id(1);
  const int x = qx * 4, y0 = by * ROWS;
  if(x >= pitch || y0 >= height) return;
  if(!active[(size_t)by * (pitch / 4) + qx])
  {
    bleed_copy_rows(src, spitch, swidth, sheight, dst, pitch, x, y0, min(y0 + ROWS, height),
                    dx, dy);
    return;
  }
  float16 acc[ROWS];
#pragma unroll
  for(int o = 0; o < ROWS; o++) acc[o] = (float16)(0.0f);
#pragma unroll
  for(int ir = 0; ir < IN_ROWS; ir++)
  {
    float16 hs[RANK];
#pragma unroll
    for(int k = 0; k < RANK; k++) hs[k] = (float16)(0.0f);
#pragma unroll
    for(int b = -RADIUS; b <= RADIUS; b++)
    {
      const float16 v = HP_QUAD(y0 + ir, x + PADX - b);
#pragma unroll
      for(int k = 0; k < RANK; k++) hs[k] += hvec[k * TAPS + RADIUS + b] * v;
    }
#pragma unroll
    for(int o = 0; o < ROWS; o++)
    {
      const int a = ir - RADIUS - o;
      if(a >= -RADIUS && a <= RADIUS)
      {
#pragma unroll
        for(int k = 0; k < RANK; k++) acc[o] += vvec[k * TAPS + RADIUS - a] * hs[k];
      }
    }
  }
#pragma unroll
  for(int o = 0; o < ROWS; o++)
  {
    const int y = y0 + o;
    if(y < height)
      bleed_store_mixed(src, spitch, swidth, sheight, dst, pitch, x, y, dx, dy, acc[o],
                        HP_QUAD(y + RADIUS, x + PADX), strength, tint);
  }
}
#endif /* RANK */
