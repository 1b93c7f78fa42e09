/* image.cl: generic image plumbing used by the host (clfx/runtime.py).
 *
 * image_reframe copies an image into a different window: pixels of the destination that the
 * source covers are copied, the others are filled by the border mode (BORDER 0 = zero,
 * 1 = clamp to the nearest source pixel), the row padding is zero.  dx, dy = origin of dst
 * minus origin of src.
 * Halation's spread, the warps' and the motion family's bands reframe frame-sized windows
 * every frame, so it is vectorised: 4 pixels a work-item.
 */
#include "lib/common.h"

/* One destination pixel (x, y) of image_reframe, channel by channel. */
inline void image_reframe_pixel(global const float *src, const int src_pitch, const int src_w,
                                const int src_h, global float *dst, const int dst_pitch,
                                const int dst_w, const int x, const int y, const int dx,
                                const int dy)
{
  if(x >= dst_w)      /* the row's padding: zeros, as an upload's (kernels that read whole */
  {                   /* quads of 4 pixels see the same padding in every render) */
    for(int c = 0; c < CH; c++)
      dst[(y * dst_pitch + x) * CH + c] = 0.0f;
    return;
  }
  int sx = x + dx, sy = y + dy;
  const int inside = sx >= 0 && sy >= 0 && sx < src_w && sy < src_h;
  sx = clfx_clampi(sx, 0, max(src_w - 1, 0));
  sy = clfx_clampi(sy, 0, max(src_h - 1, 0));
  for(int c = 0; c < CH; c++)
  {
    float v = (src_w > 0 && src_h > 0) ? src[(sy * src_pitch + sx) * CH + c] : 0.0f;
    if(BORDER == 0 && !inside) v = 0.0f;
    dst[(y * dst_pitch + x) * CH + c] = v;
  }
}

#if CH == 4
#define IMAGE_QUAD float16
#define IMAGE_QUAD_LOAD vload16
#define IMAGE_QUAD_STORE vstore16
#elif CH == 2
#define IMAGE_QUAD float8
#define IMAGE_QUAD_LOAD vload8
#define IMAGE_QUAD_STORE vstore8
#elif CH == 1
#define IMAGE_QUAD float4
#define IMAGE_QUAD_LOAD vload4
#define IMAGE_QUAD_STORE vstore4
#endif

/* 4 destination pixels per work-item (dst_pitch is a multiple of 4): a quad whose pixels
 * and sources all lie inside is one vector copy, the others go pixel by pixel (a scalar
 * work-item per pixel cost a 1856 x 896 copy 12-16 ms of CPU on a 1080p frame). */
kernel void image_reframe(global const float *src, const int src_pitch, const int src_w,
                          const int src_h, global float *dst, const int dst_pitch,
                          const int dst_w, const int dst_h, const int dx, const int dy)
{
  const int x = get_global_id(0) * 4, y = get_global_id(1);
  if(x >= dst_pitch || y >= dst_h) return;
#ifdef IMAGE_QUAD
  const int sx = x + dx, sy = y + dy;
  if(x + 4 <= dst_w && sx >= 0 && sx + 4 <= src_w && sy >= 0 && sy < src_h)
  {
    IMAGE_QUAD_STORE(IMAGE_QUAD_LOAD(0, src + (sy * src_pitch + sx) * CH), 0,
                     dst + (y * dst_pitch + x) * CH);
    return;
  }
#endif
  for(int k = 0; k < 4; k++)
    image_reframe_pixel(src, src_pitch, src_w, src_h, dst, dst_pitch, dst_w, x + k, y, dx, dy);
}

/* image_sanitize: non-finite floats (NaN, +-Inf) of a 4-channel image set to 0, in place,
 * and counted (pixels with any non-finite channel) into *count.  One work-item per
 * SANITIZE_QUADS quads of 4 pixels (float16s) of a padded row: it tests them all first and
 * returns if none has one (a clean frame is read once; one quad a work-item spent more on the
 * work-item loop than on the read: 1080p 7.6 -> 4.1 ms of CPU); the atomic is touched only
 * where something was found. */
#define SANITIZE_QUADS 8
kernel void image_sanitize(global float *img, const int pitch, const int height,
                           volatile global int *count)
{
  const int q0 = get_global_id(0) * SANITIZE_QUADS, y = get_global_id(1);
  if(y >= height || q0 * 4 >= pitch) return;
  global float *row = img + (size_t)y * pitch * 4;
  const int q1 = min(q0 + SANITIZE_QUADS, pitch / 4);
  int16 any_bad = (int16)0;
  for(int q = q0; q < q1; q++)
    any_bad |= (as_int16(vload16(q, row)) & 0x7f800000) == 0x7f800000;
  if(!any(any_bad)) return;
  int n = 0;
  for(int q = q0; q < q1; q++)
  {
    const float16 v = vload16(q, row);
    const int16 bad = (as_int16(v) & 0x7f800000) == 0x7f800000;
    if(!any(bad)) continue;
    vstore16(clfx_finite16_or_zero(v), q, row);
    n += (any(bad.s0123) ? 1 : 0) + (any(bad.s4567) ? 1 : 0) +
         (any(bad.s89ab) ? 1 : 0) + (any(bad.scdef) ? 1 : 0);
  }
  atomic_add(count, n);
}

/* image_rgb_matrix: dst.rgb = M src.rgb, dst.a = src.a for a 4-channel image (M's rows r0,
 * r1, r2 in .xyz): the working space's pixels into the spectral effects' reference basis and
 * back (clfx.kit.spectral.in_reference_basis).  Linear: negative components stay negative.
 * One work-item per pixel of the padded rows. */
kernel void image_rgb_matrix(global const float *src, global float *dst, const int pitch,
                             const int height, const float4 r0, const float4 r1,
                             const float4 r2)
{
  const int x = get_global_id(0), y = get_global_id(1);
  if(y >= height || x >= pitch) return;
  const size_t i = (size_t)y * pitch + x;
  const float4 c = vload4(i, src);
  const float4 rgb = (float4)(c.x, c.y, c.z, 0.0f);
  vstore4((float4)(dot(r0, rgb), dot(r1, rgb), dot(r2, rgb), c.w), i, dst);
}
