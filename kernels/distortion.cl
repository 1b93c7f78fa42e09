/* distortion.cl: Brown-Conrady lens distortion as a gather through a precomputed map
 * (clfx/plugins/distortion.py has the model; kernels/resample.h the filters).
 *
 * The inverse mapping (for each output pixel, the undistorted source point) is computed once
 * per parameter set on the host in float64 and stored as a displacement map: source point =
 * output pixel centre + (dx, dy), both in source-window pixel coordinates.  MAP_REAL is float
 * (final and below) or double (reference).  Each work-item renders 4 consecutive output
 * pixels (rows are padded to 4): one vload8 of the map, four filtered reads, one vstore16.
 */
#include "resample.h"

#ifndef MAP_REAL
#define MAP_REAL float
#endif

kernel void distortion_warp(global const float *src, global float *dst,
                            global const MAP_REAL *map, const int src_pitch,
                            const int src_w, const int src_h, const int dst_pitch,
                            const int dst_h, const int off_x, const int off_y)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= dst_h || qx * 4 >= dst_pitch) return;
  const int i = y * dst_pitch + qx * 4;
#ifndef RS_EXACT_TRIG
  {
    /* float levels: 4 pixels' coordinates as float4 (one vload8 of the map) */
    const float8 m = vload8(0, map + 2 * i);
    const float4 sx = (float4)(qx * 4 + off_x, qx * 4 + 1 + off_x, qx * 4 + 2 + off_x,
                               qx * 4 + 3 + off_x) + 0.5f + m.even;
    const float4 sy = (float4)(y + off_y) + 0.5f + m.odd;
    float4 o0, o1, o2, o3;
    rs_sample4(src, src_pitch, src_w, src_h, sx, sy, &o0, &o1, &o2, &o3);
    vstore16((float16)(o0, o1, o2, o3), 0, dst + i * 4);
    return;
  }
#endif
  REAL4 o[4];
  for(int k = 0; k < 4; k++) {
    const REAL sx = (REAL)(qx * 4 + k + off_x) + (REAL)0.5 + (REAL)map[2 * (i + k)];
    const REAL sy = (REAL)(y + off_y) + (REAL)0.5 + (REAL)map[2 * (i + k) + 1];
    o[k] = rs_sample(src, src_pitch, src_w, src_h, sx, sy);
  }
  const float16 v = (float16)(convert_float4(o[0]), convert_float4(o[1]),
                              convert_float4(o[2]), convert_float4(o[3]));
  vstore16(v, 0, dst + i * 4);
}
