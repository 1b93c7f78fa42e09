/* scatter.h: the light-spreading effects' shared per-pixel maths (clfx/kit/scatter.py).
 *
 * The glare family (glare.cl, bleed.cl, soft_focus.cl) thresholds with a soft knee, spreads
 * the highlights with a PSF (lib/fftconv.cl, or bleed's fused gather) and mixes back:
 *   display-referred input (boost > 0): inverse tone curve on luminance,
 *     e(L) = L / max(1 - L (1 - 1/B), 1/B)   (e(0) = 0, e'(0) = 1, e(1) = B), hue kept;
 *   soft knee (Unity/Kawase bloom): s = clamp(L - t + k, 0, 2k)^2 / (4k),
 *     weight = clamp(max(s, L - t) / L, 0, 1);  highlight h = max(rgb, 0) * weight.
 *   scene-linear: out = c - strength h + strength tint (PSF * h)  (energy moves, kept);
 *   display-referred: out = c + strength tint (PSF * h)            (classic additive glow).
 * Non-finite input pixels become 0 (black, alpha 0) and do not spread.
 * SCATTER_KERNELS(effect) defines the family's three kernels, <effect>_highlights,
 * <effect>_highlights_at (of a part of the source, without a reframed copy) and <effect>_mix,
 * with the same arguments for every effect.
 *
 * Corona, streaks and lens flare threshold hard (scatter_bright) and compose
 * source + light with scatter_source (non-finite channels set to 0).
 */
#ifndef CLFX_SCATTER_H
#define CLFX_SCATTER_H

#include "lib/common.h"

#define SCATTER_FLT_MAX 3.402823466e+38f

inline int scatter_pixel_finite(float4 c)
{
  return clfx_is_finite(c.x) & clfx_is_finite(c.y) & clfx_is_finite(c.z) & clfx_is_finite(c.w);
}


/* The light that scatters from 4 sanitised pixels (the model above; boost <= 0:
 * scene-linear), one pixel per lane of each channel's float4 (r, g, b in and out): vector
 * code, as PoCL runs a work-item's scalar pixel loop unvectorised. */
inline void scatter_highlight4(float4 *r, float4 *g, float4 *b, float threshold, float knee,
                               float boost)
{
  float4 x = fmax(*r, 0.0f), y = fmax(*g, 0.0f), z = fmax(*b, 0.0f);
  float4 lum = (CLFX_LUMA_R) * x + (CLFX_LUMA_G) * y + (CLFX_LUMA_B) * z;
  if(boost > 0.0f)
  {
    const int4 on = lum > 0.0f;
    const float4 e = lum / fmax(1.0f - lum * (1.0f - 1.0f / boost), 1.0f / boost);
    const float4 f = e / lum;
    x = select(x, x * f, on);
    y = select(y, y * f, on);
    z = select(z, z * f, on);
    lum = select(lum, e, on);
  }
  float4 soft = (float4)0.0f;
  if(knee > 0.0f)
  {
    const float4 k = clamp(lum - threshold + knee, 0.0f, 2.0f * knee);
    soft = k * k / (4.0f * knee);
  }
  const float4 w = select((float4)0.0f, clamp(fmax(soft, lum - threshold) / lum, 0.0f, 1.0f),
                          lum > 0.0f);
  *r = x * w;
  *g = y * w;
  *b = z * w;
}

/* Source pixel (sx, sy) (pitch spitch, swidth x sheight), 0 where any channel is not finite
 * (the glare family's rule; scatter_source zeroes channels alone) and outside the source. */
inline float4 scatter_load_px(global const float *src, int spitch, int swidth, int sheight,
                              int sx, int sy)
{
  if(sx < 0 || sx >= swidth || sy < 0 || sy >= sheight) return (float4)(0.0f);
  return clfx_finite_pixel_or_zero(vload4((size_t)sy * spitch + sx, src));
}

/* Source pixels (sx .. sx + 3, sy), sanitised, 0 outside the source: one unaligned float16
 * load inside, per-pixel loads at the borders. */
inline float16 scatter_load4px(global const float *src, int spitch, int swidth, int sheight,
                               int sx, int sy)
{
  if(sy < 0 || sy >= sheight || sx + 3 < 0 || sx >= swidth) return (float16)(0.0f);
  if(sx >= 0 && sx + 3 < swidth)
    return clfx_finite_pixels16_or_zero(vload16(0, src + ((size_t)sy * spitch + sx) * 4));
  return (float16)(scatter_load_px(src, spitch, swidth, sheight, sx, sy),
                   scatter_load_px(src, spitch, swidth, sheight, sx + 1, sy),
                   scatter_load_px(src, spitch, swidth, sheight, sx + 2, sy),
                   scatter_load_px(src, spitch, swidth, sheight, sx + 3, sy));
}

/* The highlights (alpha 0) of 4 sanitised pixels. */
inline float16 scatter_highlights16(float16 c, float threshold, float knee, float boost)
{
  float4 r = c.s048c, g = c.s159d, b = c.s26ae;
  scatter_highlight4(&r, &g, &b, threshold, knee, boost);
  const float4 a = (float4)0.0f;
  return (float16)(r.x, g.x, b.x, a.x, r.y, g.y, b.y, a.y, r.z, g.z, b.z, a.z,
                   r.w, g.w, b.w, a.w);
}

/* src window -> highlight image of the same window, 4 pixels per work-item. */
inline void scatter_highlights_body(global const float *src, global float *dst, const int pitch,
                                    const int height, const float threshold, const float knee,
                                    const float boost)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(qx * 4 >= pitch || y >= height) return;
  const size_t i = ((size_t)y * pitch + qx * 4) * 4;
  const float16 c = clfx_finite_pixels16_or_zero(vload16(0, src + i));
  vstore16(scatter_highlights16(c, threshold, knee, boost), 0, dst + i);
}

/* The highlights of the part of src (spitch, swidth x sheight) from (dx, dy), into dst
 * (pitch, `width` x `height`): dst (x, y) takes src (x + dx, y + dy); 0 outside src and in
 * dst's padding columns.  What a reframed copy of src with its highlights taken in place
 * held, without the copy. */
inline void scatter_highlights_at_body(global const float *src, const int spitch,
                                       const int swidth, const int sheight, const int dx,
                                       const int dy, global float *dst, const int pitch,
                                       const int width, const int height,
                                       const float threshold, const float knee,
                                       const float boost)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(qx * 4 >= pitch || y >= height) return;
  const int x = qx * 4;
  /* the padding columns read nothing: as the zeros of a reframed copy */
  const int sw = min(swidth, width + dx);
  const float16 c = scatter_load4px(src, spitch, sw, sheight, x + dx, y + dy);
  vstore16(scatter_highlights16(c, threshold, knee, boost), 0, dst + ((size_t)y * pitch + x) * 4);
}

/* out window (>= src window): out = c + strength tint g, minus strength h (additive 0:
 * scene-linear glare family), nothing (1: additive) or strength tint h (2: halation's CONSERVE).
 * (dx, dy): out origin minus src origin; g shares the out window and pitch.  Sums beyond the
 * float range saturate at +-FLT_MAX: finite input gives finite output.  4 pixels per
 * work-item, one per lane (scatter_highlight4). */
inline void scatter_mix_body(global const float *src, const int spitch, const int swidth,
                             const int sheight, global const float *g, global float *dst,
                             const int pitch, const int height, const int dx, const int dy,
                             const float strength, const float4 tint, const float threshold,
                             const float knee, const float boost, const int additive)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(qx * 4 >= pitch || y >= height) return;
  const size_t i = ((size_t)y * pitch + qx * 4) * 4;
  const float16 gl = vload16(0, g + i);
  const float16 c = scatter_load4px(src, spitch, swidth, sheight, qx * 4 + dx, y + dy);
  /* PSF >= 0 and h >= 0: clamp the FFT's round-off (~1e-16 x energy) at 0 */
  const float4 st = strength * tint;
  float4 r = c.s048c + st.x * fmax(gl.s048c, 0.0f);
  float4 gg = c.s159d + st.y * fmax(gl.s159d, 0.0f);
  float4 b = c.s26ae + st.z * fmax(gl.s26ae, 0.0f);
  if(additive != 1)
  {
    float4 hr = c.s048c, hg = c.s159d, hb = c.s26ae;
    scatter_highlight4(&hr, &hg, &hb, threshold, knee, boost);
    const float4 k = additive == 0 ? (float4)strength : st;
    r -= k.x * hr;
    gg -= k.y * hg;
    b -= k.z * hb;
  }
  r = clamp(r, -SCATTER_FLT_MAX, SCATTER_FLT_MAX);
  gg = clamp(gg, -SCATTER_FLT_MAX, SCATTER_FLT_MAX);
  b = clamp(b, -SCATTER_FLT_MAX, SCATTER_FLT_MAX);
  const float4 a = c.s37bf;
  vstore16((float16)(r.x, gg.x, b.x, a.x, r.y, gg.y, b.y, a.y, r.z, gg.z, b.z, a.z,
                     r.w, gg.w, b.w, a.w), 0, dst + i);
}

#define SCATTER_KERNELS(effect)                                                               \
kernel void effect##_highlights(global const float *src, global float *dst, const int pitch,  \
                                const int height, const float threshold, const float knee,    \
                                const float boost)                                            \
{                                                                                             \
  scatter_highlights_body(src, dst, pitch, height, threshold, knee, boost);                   \
}                                                                                             \
kernel void effect##_mix(global const float *src, const int spitch, const int swidth,         \
                         const int sheight, global const float *g, global float *dst,         \
                         const int pitch, const int height, const int dx, const int dy,       \
                         const float strength, const float4 tint, const float threshold,      \
                         const float knee, const float boost, const int additive)             \
{                                                                                             \
  scatter_mix_body(src, spitch, swidth, sheight, g, dst, pitch, height, dx, dy, strength,     \
                   tint, threshold, knee, boost, additive);                                   \
}                                                                                             \
kernel void effect##_highlights_at(global const float *src, const int spitch,                 \
                                   const int swidth, const int sheight, const int dx,         \
                                   const int dy, global float *dst, const int pitch,          \
                                   const int width, const int height, const float threshold,  \
                                   const float knee, const float boost)                       \
{                                                                                             \
  scatter_highlights_at_body(src, spitch, swidth, sheight, dx, dy, dst, pitch, width, height, \
                             threshold, knee, boost);                                         \
}

/* Hard-threshold bright-pass of one source pixel: RGB * max(lum - t, 0) / lum, non-finite
 * channels and negatives -> 0, alpha 0. */
inline float4 scatter_bright(float4 c, float threshold)
{
  c = fmax(clfx_finite4_or_zero(c), (float4)0.0f);
  const float l = clfx_luminance(c);
  /* k <= 1; fmin only turns the NaN of a luminance rounded up to inf into 1 */
  const float k = l > threshold ? fmin((l - threshold) / l, 1.0f) : 0.0f;
  return (float4)(c.x * k, c.y * k, c.z * k, 0.0f);
}

/* Source pixel (sx, sy) with non-finite channels set to 0; 0 outside the source. */
inline float4 scatter_source(global const float *src, int pitch, int width, int height,
                             int sx, int sy)
{
  if(sx < 0 || sx >= width || sy < 0 || sy >= height) return (float4)0.0f;
  return clfx_finite4_or_zero(clfx_load4(src, pitch, sx, sy));
}

/* source + added light, saturated at +-FLT_MAX (finite input, finite output); alpha c's. */
inline float4 scatter_add(float4 c, float4 light)
{
  const float4 r = clamp(c + light, -SCATTER_FLT_MAX, SCATTER_FLT_MAX);
  return (float4)(r.xyz, c.w);
}

/* img (pitch, w x h pixels) at the continuous pixel position (u, v) (pixel centres at
 * integers): bilinear, clamped at the edges.  The upsampling of a reduced-resolution glow. */
inline float4 scatter_bilinear(global const float *img, int pitch, int w, int h, float u,
                               float v)
{
  const float u0 = floor(u), v0 = floor(v);
  const float fu = u - u0, fv = v - v0;
  const int i0 = (int)u0, j0 = (int)v0;
  const float4 a = clfx_load4_clamped(img, pitch, w, h, i0, j0);
  const float4 b = clfx_load4_clamped(img, pitch, w, h, i0 + 1, j0);
  const float4 d = clfx_load4_clamped(img, pitch, w, h, i0, j0 + 1);
  const float4 e = clfx_load4_clamped(img, pitch, w, h, i0 + 1, j0 + 1);
  return (a * (1.0f - fu) + b * fu) * (1.0f - fv) + (d * (1.0f - fu) + e * fu) * fv;
}

#endif /* CLFX_SCATTER_H */
