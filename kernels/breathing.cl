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
 *
 * Rows are the whole render's: output row y of dst is row y + row0 of the whole output,
 * and src holds the whole render's source rows from `shift` on (CLFX_CANVAS_ROWS: a tile of
 * a tiled render, clfx.kit.warp.CanvasRows; both 0 in a whole render), so a band's pixels
 * take the whole render's arithmetic.
 */
#include "lib/resample.h"

#if !REAL_IS_DOUBLE
/* draft / preview / final (FP_FILTER): the footprint filter at the scaled points.  A quad
 * whose four windows lie inside the source (and needs no sub-footprints) takes
 * fp_fast_quad_at with its windows, fractions and spreads (the spreads rounded to half
 * floats, as a packed quad holds them); the others (near the border, strong minification)
 * the checked path, pixel by pixel, through one call site.  Launched over exactly
 * (dst_pitch / 4, dst_h): no bounds test.  Before (the quad packed in a private array, the
 * checked path inlined four times, a bounds test) the draft took 12.5 ms at 1080p on the
 * bench's narrow case, now 9.3 (cv2.warpAffine bilinear 2.7: the distortion kernel on the
 * same affine map, read from a packed map, takes 4.9, so the windows computed here per
 * quad still cost ~4 ms; not found why). */
kernel void breathing_footprint(global const float *src, global float *dst,
                                const int src_pitch, const int src_w, const int src_h,
                                const int dst_pitch, const int dst_h, const float ax,
                                const float ay, const float inv_m, const float hx,
                                const float hy, const int n, const int row0, const int shift)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  CLFX_CANVAS_ROWS(src, src_pitch, 4, shift);
  const float sy = fma((float)(y + row0), inv_m, ay);
  float fy;
  const int iy = fp_window(sy, hy, &fy);
  const float4 sx = fma(convert_float4((int4)(qx * 4) + (int4)(0, 1, 2, 3)), inv_m, ax);
  float4 fx;
  const int4 ix = fp_window4(sx, hx, &fx);
  int fast = n <= 1 && iy >= 0 && iy + FP_TAPS <= src_h && all(ix >= 0) &&
             all(ix + FP_TAPS <= src_w);
#if FP_FILTER == 0
  fast &= all(ix + 4 <= src_pitch) || iy + FP_TAPS < src_h;   /* rows read as 4 texels */
#endif
  const int4 base = (iy * src_pitch + ix) * 4;
  float4 o[4];
  if(fast) {
    ushort h16[2];                             /* the spreads as half floats */
    vstore_half(hx, 0, (private half *)h16);
    vstore_half(hy, 1, (private half *)h16);
    const float2 hr = vload_half2(0, (private const half *)h16);
    fp_fast_quad_at(src, src_pitch, base, (float8)(fx, (float4)fy),
                    (float8)(hr, hr, hr, hr), &o[0], &o[1], &o[2], &o[3]);
  } else {
#pragma unroll 1
    for(int k = 0; k < 4; k++)
      o[k] = fp_sample_grid(src, src_pitch, src_w, src_h, sx[k], sy, hx, hy, n, inv_m, 0.0f,
                            0.0f, inv_m);
  }
  clfx_store16_streaming(((float16)(o[0], o[1], o[2], o[3])),
                         dst + (y * dst_pitch + qx * 4) * 4);
  clfx_streaming_fence();
}
#else
/* reference (a CLFX_FP64 build): the elliptical footprint, J_c = e I, in float64 */
kernel void breathing_ewa_f64(global const float *src, global float *dst,
                              const int src_pitch, const int src_w, const int src_h,
                              const int dst_pitch, const int dst_h, const REAL ax,
                              const REAL ay, const REAL inv_m, const REAL e, const int n,
                              const int row0, const int shift)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= dst_h || qx * 4 >= dst_pitch) return;
  CLFX_CANVAS_ROWS(src, src_pitch, 4, shift);
  const REAL sy = (REAL)(y + row0) * inv_m + ay;
  REAL4 o[4];
  for(int k = 0; k < 4; k++) {
    const REAL sx = (REAL)(qx * 4 + k) * inv_m + ax;
    o[k] = rs_ewa_sample(src, src_pitch, src_w, src_h, sx, sy, e, (REAL)0, (REAL)0, e, n);
  }
  rs_store_quad(dst, y * dst_pitch + qx * 4, o);
}
#endif
