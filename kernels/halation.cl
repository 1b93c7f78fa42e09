/* halation.cl: film halation (clfx/plugins/halation.py).
 *
 *   halation_highlights  the glare family's soft-knee highlight h of every pixel
 *                        (lib/scatter.h, scene-linear), alpha 0;
 *   (the PSF spread runs in lib/fftconv.cl: clfx/fx/fftconv.py)
 *   halation_mix         out = c + strength tint max(g, 0), minus strength tint h with
 *                        CONSERVE (each channel's total kept); alpha c's.
 * Non-finite source pixels count as 0 (clfx_finite_pixel_or_zero) and do not spread; sums beyond the
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
{  /* the glare family's mix; CONSERVE takes the tinted highlight away (mode 2) */
  scatter_mix_body(src, spitch, swidth, sheight, g, dst, pitch, height, dx, dy, strength,
                   tint, threshold, knee, 0.0f, CONSERVE ? 2 : 1);
}
