/* corona.cl: highlights in, corona composed out (clfx/plugins/corona.py).
 *
 * corona_bright   RGB * max(lum - t, 0) / lum of the sanitised source (non-finite -> 0,
 *                 negatives -> 0), alpha 0; 4 pixels per work-item (one float16).
 * corona_compose  out = sanitised source (zero outside its window) + intensity * glow, where
 *                 glow (the highlights convolved with the spectral PSF, clfx.fx.fftconv)
 *                 covers the output window; alpha is the source's.
 */
#include "lib/scatter.h"

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

kernel void corona_compose(global const float *src, const int src_pitch, const int src_w,
                           const int src_h, const int ox, const int oy,
                           global const float *glow, global float *dst, const int pitch,
                           const int width, const int height, const float intensity)
{
  const int x = get_global_id(0), y = get_global_id(1);
  if(x >= pitch || y >= height) return;
  if(x >= width) { clfx_store4(dst, pitch, x, y, (float4)0.0f); return; }
  const float4 c = scatter_source(src, src_pitch, src_w, src_h, x - ox, y - oy);
  const float4 g = fmax(clfx_finite4_or_zero(clfx_load4(glow, pitch, x, y)), (float4)0.0f);
  clfx_store4(dst, pitch, x, y, scatter_add(c, intensity * g));
}
