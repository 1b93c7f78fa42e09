/* distortion.cl: Brown-Conrady lens distortion as a gather through a precomputed map
 * (clfx/plugins/distortion.py has the model; kernels/lib/resample.h the filters).
 *
 * The inverse mapping (for each output pixel, the undistorted source point) is computed once
 * per parameter set on the host in float64.  Each work-item renders 4 consecutive output
 * pixels (rows are padded to 4).
 *
 * distortion_warp (draft / preview / final): the map is packed (clfx.fx.resample.PackedMap):
 * per quad of 4 pixels their texel indices and float fractions (12 ints): a pure gather
 * (three vload4 of the map, one vector load per footprint row, no border rule, no branch);
 * then distortion_fix re-renders the quads whose footprints leave the source (listed per
 * filter on the host) through the checked path.
 *
 * distortion_warp_f64 (reference, a CLFX_FP64 build: kernels/lib/precision.h): a float64
 * displacement map (source point = output pixel centre + (dx, dy)), float64 coordinates,
 * weights and sums.
 */
#include "lib/resample.h"

#if !REAL_IS_DOUBLE
kernel void distortion_warp(global const float *src, global float *dst,
                            global const int *map, const int src_pitch, const int src_w,
                            const int src_h, const int dst_pitch, const int dst_h)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= dst_h || qx * 4 >= dst_pitch) return;
  const int quad = y * (dst_pitch / 4) + qx;
  float4 o0, o1, o2, o3;
  rs_fast_quad(src, src_pitch, src_w, src_h, map + 12 * quad, &o0, &o1, &o2, &o3);
  vstore16((float16)(o0, o1, o2, o3), 0, dst + quad * 16);
}

/* the border quads, after distortion_warp: records of 12 ints (quad index, 3 unused,
 * 4 x and 4 y of the source points) */
kernel void distortion_fix(global const float *src, global float *dst,
                           global const int *records, const int count, const int src_pitch,
                           const int src_w, const int src_h, const int dst_pitch,
                           const int dst_h)
{
  const int n = get_global_id(0);
  if(n >= count) return;
  global const int *rec = records + 12 * n;
  float4 o0, o1, o2, o3;
  rs_fix_quad(src, src_pitch, src_w, src_h, rec + 4, &o0, &o1, &o2, &o3);
  vstore16((float16)(o0, o1, o2, o3), 0, dst + rec[0] * 16);
}
#else
kernel void distortion_warp_f64(global const float *src, global float *dst,
                                global const REAL *map, const int src_pitch,
                                const int src_w, const int src_h, const int dst_pitch,
                                const int dst_h)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= dst_h || qx * 4 >= dst_pitch) return;
  REAL4 o[4];
  for(int k = 0; k < 4; k++) {
    const REAL2 s = rs_map_point(map, dst_pitch, qx * 4 + k, y);
    o[k] = rs_sample(src, src_pitch, src_w, src_h, s.x, s.y);
  }
  rs_store_quad(dst, y * dst_pitch + qx * 4, o);
}
#endif
