/* halation.cl: film halation (clfx/plugins/halation.py).
 *
 *   halation_highlights  the glare family's soft-knee highlight h of every pixel
 *                        (lib/scatter.h, scene-linear), alpha 0;
 *   (the PSF spread runs in lib/fftconv.cl: clfx/fx/fftconv.py)
 *   halation_mix         out = c + strength tint max(g, 0), minus strength tint h with
 *                        CONSERVE (each channel's total kept); alpha c's.
 * Non-finite source pixels count as 0 (scatter_sanitise) and do not spread; sums beyond the
 * float range saturate at +-FLT_MAX (finite input, finite output).
 */
#include "lib/scatter.h"

#ifndef CONSERVE
#define CONSERVE 0
#endif

kernel void halation_highlights(global const float *src, global float *dst, const int pitch,
                                const int height, const float threshold, const float knee)
{
  scatter_highlights_body(src, dst, pitch, height, threshold, knee, 0.0f);
}

/* 4 output pixels per work-item; (dx, dy): output origin minus source origin; g shares the
 * output's window and pitch. */
kernel void halation_mix(global const float *src, const int spitch, const int swidth,
                         const int sheight, global const float *g, global float *dst,
                         const int pitch, const int height, const int dx, const int dy,
                         const float strength, const float4 tint, const float threshold,
                         const float knee)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(qx * 4 >= pitch || y >= height) return;
  const size_t i = ((size_t)y * pitch + qx * 4) * 4;
  const float16 gl = vload16(0, g + i);
  const float4 gg[4] = {gl.s0123, gl.s4567, gl.s89ab, gl.scdef};
  const float4 st = strength * (float4)(tint.xyz, 0.0f);
  float4 o[4];
  const int sy = y + dy;
  for(int l = 0; l < 4; l++)
  {
    const int sx = qx * 4 + l + dx;
    float4 c = (float4)(0.0f);
    if(sx >= 0 && sx < swidth && sy >= 0 && sy < sheight)
      c = scatter_sanitise(vload4((size_t)sy * spitch + sx, src));
    /* PSF >= 0 and h >= 0: the FFT's round-off below 0 is clamped */
    float4 light = st * fmax(gg[l], 0.0f);
#if CONSERVE
    light -= st * scatter_highlight(c, threshold, knee, 0.0f);
#endif
    o[l] = scatter_add(c, light);
  }
  vstore16((float16)(o[0], o[1], o[2], o[3]), 0, dst + i);
}
