/* mask.cl: limiting an effect to a mask (clfx/fx/mask.py, per-object effects).
 *
 * All images share one window and so one pitch (DeviceImage: pitch depends on the width
 * only); the mask has one channel, the others four (RGBA, premultiplied).  One work-item per
 * pixel of the padded row: these run once per masked step, on a frame already on the device.
 *
 *   mask_mix:      dst = src + m * (eff - src)   (the effect where the mask is, the source
 *                                                 elsewhere, blended by coverage)
 *   mask_multiply: dst = src * m                 (the masked region's light only)
 *   mask_spread:   dst = src + (eff - masked)    (what an effect did to the masked light,
 *                                                 added to the untouched source)
 */
#include "lib/common.h"

kernel void mask_mix(global const float4 *src, global const float4 *eff,
                     global const float *mask, global float4 *dst, const int pitch,
                     const int height)
{
  const int x = get_global_id(0), y = get_global_id(1);
  if(x >= pitch || y >= height) return;
  const int i = y * pitch + x;
  const float4 s = src[i];
  dst[i] = s + mask[i] * (eff[i] - s);
}

kernel void mask_multiply(global const float4 *src, global const float *mask,
                          global float4 *dst, const int pitch, const int height)
{
  const int x = get_global_id(0), y = get_global_id(1);
  if(x >= pitch || y >= height) return;
  const int i = y * pitch + x;
  dst[i] = src[i] * mask[i];
}

kernel void mask_spread(global const float4 *src, global const float4 *masked,
                        global const float4 *eff, global float4 *dst, const int pitch,
                        const int height)
{
  const int x = get_global_id(0), y = get_global_id(1);
  if(x >= pitch || y >= height) return;
  const int i = y * pitch + x;
  dst[i] = src[i] + (eff[i] - masked[i]);
}
