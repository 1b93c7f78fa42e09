/* bleed.cl: sensor crosstalk (clfx/plugins/bleed.py): glare's soft-knee threshold and
 * energy-conserving mix (glare.cl) with a small exponential PSF, convolved directly. */
#define GLARE_HELPERS_ONLY 1
#include "glare.cl"

kernel void bleed_highlights(global const float *src, global float *dst, const int pitch,
                             const int height, const float threshold, const float knee)
{
  glare_highlights_body(src, dst, pitch, height, threshold, knee, 0.0f);
}

kernel void bleed_mix(global const float *src, const int spitch, const int swidth,
                      const int sheight, global const float *g, global float *dst,
                      const int pitch, const int height, const int dx, const int dy,
                      const float strength, const float4 tint, const float threshold,
                      const float knee)
{
  glare_mix_body(src, spitch, swidth, sheight, g, dst, pitch, height, dx, dy, strength, tint,
                 threshold, knee, 0.0f, 0);
}
