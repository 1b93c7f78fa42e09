/* soft_focus.cl: diffusion filter (clfx/plugins/soft_focus.py): glare.cl's soft knee with a
 * low threshold (every moderately bright pixel scatters), blended energy-conservingly:
 * out = c - amount h + amount tint (PSF * h).  Works on display-referred input unchanged
 * (no boost: its threshold is below 1). */
#define GLARE_HELPERS_ONLY 1
#include "glare.cl"

kernel void soft_focus_highlights(global const float *src, global float *dst, const int pitch,
                                  const int height, const float threshold, const float knee)
{
  glare_highlights_body(src, dst, pitch, height, threshold, knee, 0.0f);
}

kernel void soft_focus_mix(global const float *src, const int spitch, const int swidth,
                           const int sheight, global const float *g, global float *dst,
                           const int pitch, const int height, const int dx, const int dy,
                           const float amount, const float4 tint, const float threshold,
                           const float knee)
{
  glare_mix_body(src, spitch, swidth, sheight, g, dst, pitch, height, dx, dy, amount, tint,
                 threshold, knee, 0.0f, 0);
}
