/* breathing.cl: lens breathing, the frame scaled by m about the optical centre
 * (clfx/plugins/breathing.py has the model; kernels/lib/resample.h the filters).
 *
 * The map is affine and the same for every pixel: output pixel x (source-window
 * coordinates, centre at x + 0.5) reads the source at x * inv_m + a, with
 * a = c + (0.5 - c) * inv_m from the host (c the optical centre, inv_m = 1 / m), so no map
 * is built or cached per frame while the focus moves.  Its Jacobian is inv_m I everywhere:
 * the host turns it into one footprint spread (hx, hy) and sub-footprint count n
 * (clfx.fx.resample.footprint_spread; elliptical_spread for the reference).  Quads inside
 * the source take resample.h's fast path, the rest its checked path (edge clamp).
 * Each work-item renders 4 consecutive output pixels (rows are padded to 4).
 */
#define FP_Q_SPACE private   /* each work-item packs its quad itself (fp_fast_quad) */
#include "lib/resample.h"

#if !REAL_IS_DOUBLE
/* draft / preview / final (FP_FILTER): the footprint filter at the scaled points.  A quad
 * whose four windows lie inside the source (and needs no sub-footprints) is packed in
 * private memory as the packed maps are (resample.h, "Fast path": fp_pack_quad) and takes
 * fp_fast_quad;
 * the others (near the border, strong minification) the checked path, pixel by pixel. */
kernel void breathing_footprint(global const float *src, global float *dst,
                                const int src_pitch, const int src_w, const int src_h,
                                const int dst_pitch, const int dst_h, const float ax,
                                const float ay, const float inv_m, const float hx,
                                const float hy, const int n)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= dst_h || qx * 4 >= dst_pitch) return;
  const float sy = fma((float)y, inv_m, ay);
  float fy;
  const int iy = fp_window(sy, hy, &fy);
  int fast = n <= 1 && iy >= 0 && iy + FP_TAPS <= src_h;
  int q[FP_Q_INTS];
  float4 sx;
  for(int k = 0; k < 4; k++) {
    const float p = fma((float)(qx * 4 + k), inv_m, ax);
    float fx;
    const int ix = fp_window(p, hx, &fx);
    fast &= ix >= 0 && ix + FP_TAPS <= src_w;
#if FP_FILTER == 0
    fast &= ix + 4 <= src_pitch || iy + FP_TAPS < src_h;   /* rows read as 4 texels */
#endif
    fp_pack_quad(q, k, (iy * src_pitch + ix) * 4, fx, fy, hx, hy);
    sx[k] = p;
  }
  float4 o0, o1, o2, o3;
  if(fast) {
    fp_fast_quad(src, src_pitch, q, &o0, &o1, &o2, &o3);
  } else {
    o0 = fp_sample_grid(src, src_pitch, src_w, src_h, sx.s0, sy, hx, hy, n, inv_m, 0.0f,
                          0.0f, inv_m);
    o1 = fp_sample_grid(src, src_pitch, src_w, src_h, sx.s1, sy, hx, hy, n, inv_m, 0.0f,
                          0.0f, inv_m);
    o2 = fp_sample_grid(src, src_pitch, src_w, src_h, sx.s2, sy, hx, hy, n, inv_m, 0.0f,
                          0.0f, inv_m);
    o3 = fp_sample_grid(src, src_pitch, src_w, src_h, sx.s3, sy, hx, hy, n, inv_m, 0.0f,
                          0.0f, inv_m);
  }
  vstore16((float16)(o0, o1, o2, o3), 0, dst + (y * dst_pitch + qx * 4) * 4);
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
