/* breathing.cl: lens breathing, the frame scaled by m about the optical centre
 * (clfx/plugins/breathing.py has the model; kernels/lib/resample.h the filters).
 *
 * The map is affine and the same for every pixel: output pixel x (source-window
 * coordinates, centre at x + 0.5) reads the source at x * inv_m + a, with
 * a = c + (0.5 - c) * inv_m from the host (c the optical centre, inv_m = 1 / m), so no map
 * is built or cached per frame while the focus moves.  Its Jacobian is inv_m I everywhere:
 * the host turns it into one footprint spread (hx, hy) and sub-footprint count n
 * (clfx.fx.resample.footprint_spread; elliptical_spread for the reference), and every pixel
 * takes the checked footprint path of resample.h (border rule per texel: edge clamp).
 * Each work-item renders 4 consecutive output pixels (rows are padded to 4).
 */
#include "lib/resample.h"

#if !REAL_IS_DOUBLE
/* draft / preview / final (FP_FILTER): the footprint filter at the scaled point */
kernel void breathing_footprint(global const float *src, global float *dst,
                                const int src_pitch, const int src_w, const int src_h,
                                const int dst_pitch, const int dst_h, const float ax,
                                const float ay, const float inv_m, const float hx,
                                const float hy, const int n)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= dst_h || qx * 4 >= dst_pitch) return;
  const float sy = fma((float)y, inv_m, ay);
  float4 o[4];
  for(int k = 0; k < 4; k++) {
    const float sx = fma((float)(qx * 4 + k), inv_m, ax);
    o[k] = fp_sample_grid(src, src_pitch, src_w, src_h, sx, sy, hx, hy, n, inv_m, 0.0f, 0.0f,
                          inv_m);
  }
  vstore16((float16)(o[0], o[1], o[2], o[3]), 0, dst + (y * dst_pitch + qx * 4) * 4);
}
#else
/* reference (a CLFX_FP64 build): the elliptical footprint, J_c = e I, in float64 */
kernel void breathing_ewa_f64(global const float *src, global float *dst,
                              const int src_pitch, const int src_w, const int src_h,
                              const int dst_pitch, const int dst_h, const REAL ax,
                              const REAL ay, const REAL inv_m, const REAL e, const int n)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= dst_h || qx * 4 >= dst_pitch) return;
  const REAL sy = (REAL)y * inv_m + ay;
  REAL4 o[4];
  for(int k = 0; k < 4; k++) {
    const REAL sx = (REAL)(qx * 4 + k) * inv_m + ax;
    o[k] = rs_ewa_sample(src, src_pitch, src_w, src_h, sx, sy, e, (REAL)0, (REAL)0, e, n);
  }
  rs_store_quad(dst, y * dst_pitch + qx * 4, o);
}
#endif
