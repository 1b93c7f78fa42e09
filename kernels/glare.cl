/* glare.cl: highlight extraction and the final mix of glare (clfx/plugins/glare.py).
 *
 * bleed.cl and soft_focus.cl include this file with GLARE_HELPERS_ONLY defined to reuse the
 * soft-knee threshold and the mix; each defines its own kernels.
 * The convolution itself runs in fftconv.cl (clfx/fftconv.py).
 *
 * Model (per pixel, RGB scene-linear, luminance L = Rec.709):
 *   display-referred input (BOOST > 0): inverse tone curve on luminance,
 *     e(L) = L / max(1 - L (1 - 1/B), 1/B)   (e(0) = 0, e'(0) = 1, e(1) = B), hue kept;
 *   soft knee (Unity/Kawase bloom): s = clamp(L - t + k, 0, 2k)^2 / (4k),
 *     weight = clamp(max(s, L - t) / L, 0, 1);  highlight h = max(rgb, 0) * weight.
 *   scene-linear: out = c - strength h + strength tint (PSF * h)  (energy moves, kept);
 *   display-referred: out = c + strength tint (PSF * h)            (classic additive glow).
 * Non-finite input pixels become 0 (black, alpha 0) and do not spread.
 */
#include "lib/common.h"

inline int glare_pixel_finite(float4 c)
{
  return clfx_is_finite(c.x) & clfx_is_finite(c.y) & clfx_is_finite(c.z) & clfx_is_finite(c.w);
}

inline float4 glare_sanitise(float4 c)
{
  return glare_pixel_finite(c) ? c : (float4)(0.0f);
}

inline float glare_knee_weight(float lum, float threshold, float knee)
{
  if(!(lum > 0.0f)) return 0.0f;
  float soft = 0.0f;
  if(knee > 0.0f)
  {
    const float x = clamp(lum - threshold + knee, 0.0f, 2.0f * knee);
    soft = x * x / (4.0f * knee);
  }
  return clamp(fmax(soft, lum - threshold) / lum, 0.0f, 1.0f);
}

/* The light that scatters from one (sanitised) pixel; alpha 0. boost <= 0: scene-linear. */
inline float4 glare_highlight(float4 c, float threshold, float knee, float boost)
{
  float4 rgb = (float4)(fmax(c.x, 0.0f), fmax(c.y, 0.0f), fmax(c.z, 0.0f), 0.0f);
  float lum = clfx_luminance(rgb);
  if(boost > 0.0f && lum > 0.0f)
  {
    const float e = lum / fmax(1.0f - lum * (1.0f - 1.0f / boost), 1.0f / boost);
    rgb *= e / lum;
    lum = e;
  }
  return rgb * glare_knee_weight(lum, threshold, knee);
}

/* src window -> highlight image of the same window, 4 pixels per work-item. */
inline void glare_highlights_body(global const float *src, global float *dst, const int pitch,
                                  const int height, const float threshold, const float knee,
                                  const float boost)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(qx * 4 >= pitch || y >= height) return;
  const size_t i = ((size_t)y * pitch + qx * 4) * 4;
  const float16 c = vload16(0, src + i);
  const float4 h0 = glare_highlight(glare_sanitise(c.s0123), threshold, knee, boost);
  const float4 h1 = glare_highlight(glare_sanitise(c.s4567), threshold, knee, boost);
  const float4 h2 = glare_highlight(glare_sanitise(c.s89ab), threshold, knee, boost);
  const float4 h3 = glare_highlight(glare_sanitise(c.scdef), threshold, knee, boost);
  vstore16((float16)(h0, h1, h2, h3), 0, dst + i);
}

/* out window (>= src window): out = c - strength h (unless additive) + strength tint g.
 * (dx, dy): out origin minus src origin; g shares the out window and pitch. */
inline void glare_mix_body(global const float *src, const int spitch, const int swidth,
                           const int sheight, global const float *g, global float *dst,
                           const int pitch, const int height, const int dx, const int dy,
                           const float strength, const float4 tint, const float threshold,
                           const float knee, const float boost, const int additive)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(qx * 4 >= pitch || y >= height) return;
  const size_t i = ((size_t)y * pitch + qx * 4) * 4;
  const float16 gl = vload16(0, g + i);
  const float4 gg[4] = {gl.s0123, gl.s4567, gl.s89ab, gl.scdef};
  float4 o[4];
  const int sy = y + dy;
  for(int l = 0; l < 4; l++)
  {
    const int sx = qx * 4 + l + dx;
    float4 c = (float4)(0.0f);
    if(sx >= 0 && sx < swidth && sy >= 0 && sy < sheight)
      c = glare_sanitise(vload4((size_t)sy * spitch + sx, src));
    /* PSF >= 0 and h >= 0: clamp the FFT's round-off (~1e-16 x energy) at 0 */
    float4 r = c + strength * tint * (float4)(fmax(gg[l].xyz, 0.0f), 0.0f);
    if(!additive) r -= strength * glare_highlight(c, threshold, knee, boost);
    r.w = c.w;
    o[l] = r;
  }
  vstore16((float16)(o[0], o[1], o[2], o[3]), 0, dst + i);
}

#ifndef GLARE_HELPERS_ONLY
kernel void glare_highlights(global const float *src, global float *dst, const int pitch,
                             const int height, const float threshold, const float knee,
                             const float boost)
{
  glare_highlights_body(src, dst, pitch, height, threshold, knee, boost);
}

kernel void glare_mix(global const float *src, const int spitch, const int swidth,
                      const int sheight, global const float *g, global float *dst,
                      const int pitch, const int height, const int dx, const int dy,
                      const float strength, const float4 tint, const float threshold,
                      const float knee, const float boost, const int additive)
{
  glare_mix_body(src, spitch, swidth, sheight, g, dst, pitch, height, dx, dy, strength, tint,
                 threshold, knee, boost, additive);
}
#endif
