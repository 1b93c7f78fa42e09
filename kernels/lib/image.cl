/* image.cl: generic image plumbing used by the host (clfx/runtime.py).
 *
 * image_reframe copies an image into a different window: pixels of the destination that the
 * source covers are copied, the others are filled by the border mode (BORDER 0 = zero,
 * 1 = clamp to the nearest source pixel), the row padding is zero.  dx, dy = origin of dst
 * minus origin of src.
 * One work-item per destination pixel: this runs rarely (window changes), not per effect.
 */
#include "lib/common.h"

kernel void image_reframe(global const float *src, const int src_pitch, const int src_w,
                          const int src_h, global float *dst, const int dst_pitch,
                          const int dst_w, const int dst_h, const int dx, const int dy)
{
  const int x = get_global_id(0), y = get_global_id(1);
  if(x >= dst_pitch || y >= dst_h) return;
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

/* image_sanitize: non-finite floats (NaN, +-Inf) of a 4-channel image set to 0, in place,
 * and counted (pixels with any non-finite channel) into *count.  One work-item per 4 pixels
 * (a float16 of the padded row); the atomic is touched only where something was found. */
kernel void image_sanitize(global float *img, const int pitch, const int height,
                           volatile global int *count)
{
  const int q = get_global_id(0), y = get_global_id(1);
  if(y >= height || q * 4 >= pitch) return;
  global float *p = img + ((size_t)y * pitch + q * 4) * 4;
  const float16 v = vload16(0, p);
  const int16 bad = (as_int16(v) & 0x7f800000) == 0x7f800000;
  if(!any(bad)) return;
  vstore16(clfx_finite16_or_zero(v), 0, p);
  const int n = (any(bad.s0123) ? 1 : 0) + (any(bad.s4567) ? 1 : 0) +
                (any(bad.s89ab) ? 1 : 0) + (any(bad.scdef) ? 1 : 0);
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
