/* corona.cl: highlights in, corona composed out (clfx/plugins/corona.py).
 *
 * corona_bright   RGB * max(lum - t, 0) / lum of the sanitised source (non-finite -> 0,
 *                 negatives -> 0), alpha 0; 4 pixels per work-item (one float16).
 * corona_down     the highlights splatted onto a grid FACTOR times coarser (tent weights,
 *                 centroid kept), with one pixel of border around the output window
 * corona_compose  out = sanitised source (zero outside its window) - intensity * highlights
 *                 + intensity * glow, where glow (the highlights convolved with the spectral
 *                 PSF, clfx.fx.fftconv) covers the output window: the diffracted part of the
 *                 light leaves the pixel and lands in the pattern (energy kept); alpha is the
 *                 source's.
 */
#include "lib/scatter.h"

#ifndef FACTOR
#define FACTOR 1
#endif

kernel void corona_bright(global const float *src, global float *dst, const int pitch,
                          const int height, const float threshold)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(qx * 4 >= pitch || y >= height) return;
  const int i = (y * pitch + qx * 4) * 4;
  const float16 c = vload16(0, src + i);
  vstore16((float16)(scatter_bright(c.s0123, threshold), scatter_bright(c.s4567, threshold),
                     scatter_bright(c.s89ab, threshold), scatter_bright(c.scdef, threshold)),
           0, dst + i);
}

kernel void corona_down(global const float *src, const int src_pitch, const int src_w,
                        const int src_h, const int ox, const int oy, global float *dst,
                        const int pitch, const int width, const int height,
                        const float threshold)
{
  /* reduced pixel i is centred on output x = FACTOR (i - 1/2) (one pixel of border on each
   * side); every output pixel splats its highlight onto the reduced centres within FACTOR
   * with tent weights, which sum to 1 and keep its centroid: the pattern is not moved */
  const int x = get_global_id(0), y = get_global_id(1);
  if(x >= pitch || y >= height) return;
  float4 acc = (float4)0.0f;
  if(x < width)
  {
    const float cx = FACTOR * ((float)x - 0.5f), cy = FACTOR * ((float)y - 0.5f);
    const int x0 = (int)floor(cx - FACTOR), y0 = (int)floor(cy - FACTOR);
    for(int j = y0; j <= y0 + 2 * FACTOR; j++)
    {
      const int sy = j - oy;
      const float wy = 1.0f - fabs(((float)j + 0.5f - cy) * (1.0f / FACTOR));
      if(sy < 0 || sy >= src_h || wy <= 0.0f) continue;
      for(int i = x0; i <= x0 + 2 * FACTOR; i++)
      {
        const int sx = i - ox;
        const float wx = 1.0f - fabs(((float)i + 0.5f - cx) * (1.0f / FACTOR));
        if(sx < 0 || sx >= src_w || wx <= 0.0f) continue;
        acc += (wx * wy) * scatter_bright(clfx_load4(src, src_pitch, sx, sy), threshold);
      }
    }
  }
  clfx_store4(dst, pitch, x, y, fmin(acc, SCATTER_FLT_MAX));
}

kernel void corona_compose(global const float *src, const int src_pitch, const int src_w,
                           const int src_h, const int ox, const int oy,
                           global const float *glow, const int g_pitch, const int g_w,
                           const int g_h, global float *dst, const int pitch,
                           const int width, const int height, const float intensity,
                           const float threshold)
{
  const int x = get_global_id(0), y = get_global_id(1);
  if(x >= pitch || y >= height) return;
  if(x >= width) { clfx_store4(dst, pitch, x, y, (float4)0.0f); return; }
  const float4 c = scatter_source(src, src_pitch, src_w, src_h, x - ox, y - oy);
#if FACTOR == 1
  const float4 gl = clfx_load4(glow, g_pitch, x, y);
#else
  /* the reduced-resolution glow (centre of reduced pixel i at FACTOR (i - 1/2)), bilinear,
   * per full pixel */
  const float4 gl = scatter_bilinear(glow, g_pitch, g_w, g_h, ((float)x + 0.5f) / FACTOR + 0.5f,
                                     ((float)y + 0.5f) / FACTOR + 0.5f)
                    * (1.0f / (FACTOR * FACTOR));
#endif
  const float4 g = fmax(clfx_finite4_or_zero(gl), (float4)0.0f);
  const float4 h = scatter_bright(c, threshold);
  clfx_store4(dst, pitch, x, y, scatter_add(c - intensity * h, intensity * g));
}
