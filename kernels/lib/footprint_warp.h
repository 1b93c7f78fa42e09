/* footprint_warp.h: the kernels of a warp through an analytic map (clfx.kit.warp.FootprintWarp:
 * distortion, keystone), on the footprint filters of resample.h.
 *
 * The inverse mapping (for each output pixel, its source point) and its Jacobian are computed
 * once per parameter set on the host in float64.  The filters' footprints follow the Jacobian
 * (resample.h, "Footprint filters"), so where the map compresses the source the output is
 * area-averaged instead of aliased.  Each work-item renders 4 consecutive output pixels (rows
 * are padded to 4).  An effect's kernel file instantiates the family's two kernels under its
 * name, with the same arguments for every effect:
 *
 *   #include "lib/footprint_warp.h"
 *   #if !REAL_IS_DOUBLE
 *   FOOTPRINT_WARP_KERNELS(keystone)    // keystone_footprint
 *   #else
 *   EWA_WARP_KERNELS(keystone)          // keystone_ewa_f64
 *   #endif
 *
 * <effect>_footprint (draft / preview / final, FP_FILTER): the map is packed
 * (clfx.fx.resample.FootprintMap): per quad of 4 pixels their windows' texel indices,
 * fractions and spreads (FP_Q_INTS ints): a pure gather, the source rows of the quad
 * FP_PREFETCH_AHEAD quads on prefetched on a CPU device (distortion draft at 1080p: 3.5-4.0 ms
 * without, 2.5-2.8 with; 2.3 with the half fractions of the 12-int quadratic map, 2.2 if the
 * map were the identity, so what is left is arithmetic), outputs written with streaming
 * stores where the host asks (CLFX_STREAM_STORES, kernels/lib/common.h); quads marked -2 are
 * written as 0 (no source, black border), quads marked -1 (under 1 % at 1080p) are rendered
 * from their records (points, spreads, Jacobians) through the checked path (border rule,
 * sub-footprints), in the same launch: a second kernel for them cost 0.2 ms, and PoCL 3.1 at
 * random held it queued behind the first for ~4 ms more (draft at 1080p: 4.7 ms median, 13 of
 * 100 renders near 9 ms; one kernel: 4.2 ms, none).
 *
 * <effect>_ewa_f64 (reference, a CLFX_FP64 build: kernels/lib/precision.h): a float64 map per
 * pixel (displacement dx, dy; the footprint's extra extent J_c as two columns; the samples per
 * axis n): the mean of n x n Lanczos-3 samples at s + J_c (a_i, a_j),
 * a_i = ((i + 1/2) / n - 1/2) sqrt(n^2 / (n^2 - 1)), in float64, clamped to the min/max of the
 * samples' nearest 2x2 texels together (one sample: today's 2x2 clamp).
 *
 * Both render the canvas rows row0 .. row0 + dst_h (the map's rows: all of them in a whole
 * render) from buffers holding the canvas rows from `shift` on (CLFX_CANVAS_ROWS: a tile of a
 * tiled render, clfx.kit.warp.CanvasRows; 0 in a whole render); records count quads from the
 * canvas's first row.
 */
#ifndef CLFX_FOOTPRINT_WARP_H
#define CLFX_FOOTPRINT_WARP_H

#include "lib/resample.h"

#if !REAL_IS_DOUBLE
/* A checked quad from its record of 56 ints (clfx.fx.resample.FootprintMap): the quad index,
 * 3 unused, its packed ints (FP_Q_INTS of 16), a mode per pixel (0 fast path, 1 checked
 * path, 2 zero) and the checked path's record.  The checked pixels go through one call
 * site in a loop kept rolled (fp_sample_n; its fp_sample_grid is out of line on a CPU
 * device). */
inline void fw_checked_quad(global const float *src, global float *dst,
                            global const int *rec, const int src_pitch,
                            const int src_w, const int src_h)
{
  const int4 mode = vload4(5, rec);
  float4 o0 = (float4)0.0f, o1 = (float4)0.0f, o2 = (float4)0.0f, o3 = (float4)0.0f;
  if(any(mode == 0)) fp_fast_quad(src, src_pitch, rec + 4, &o0, &o1, &o2, &o3);
  float4 s[4];
#pragma unroll 1
  for(int k = 0; k < 4; k++)
    s[k] = mode[k] == 1 ? fp_sample_n(src, src_pitch, src_w, src_h, rec + 24, k)
                        : (float4)0.0f;
  clfx_store16_streaming(((float16)(mode.s0 == 0 ? o0 : s[0], mode.s1 == 0 ? o1 : s[1],
                                     mode.s2 == 0 ? o2 : s[2], mode.s3 == 0 ? o3 : s[3])),
                         dst + rec[0] * 16);
}

/* launched over exactly (dst_pitch / 4, dst_h): a bounds test in it made PoCL keep each
 * work-item's values in stack arrays (15% slower); every path fences (the group's last
 * item) */
#define FOOTPRINT_WARP_KERNELS(effect)                                                        \
kernel void effect##_footprint(global const float *src, global float *dst,                    \
                               global const int *map, global const int *records,              \
                               const int src_pitch, const int src_w, const int src_h,         \
                               const int dst_pitch, const int dst_h, const int row0,          \
                               const int shift)                                               \
{                                                                                             \
  CLFX_CANVAS_ROWS(src, src_pitch, 4, shift);                                                 \
  CLFX_CANVAS_ROWS(dst, dst_pitch, 4, shift);                                                 \
  const int quads = dst_pitch / 4, entry = get_global_id(1) * quads + get_global_id(0);      \
  const int quad = entry + row0 * quads;                                                      \
  fp_prefetch_quad(src, src_pitch, map + FP_Q_INTS * min(entry + FP_PREFETCH_AHEAD,           \
                                                         quads * dst_h - 1));                 \
  global const int *q = map + FP_Q_INTS * entry;                                              \
  const int mark = q[0];                                                                      \
  if(mark >= 0) {                                                                             \
    float4 o0, o1, o2, o3;                                                                    \
    fp_fast_quad(src, src_pitch, q, &o0, &o1, &o2, &o3);                                      \
    clfx_store16_streaming(((float16)(o0, o1, o2, o3)), dst + quad * 16);                     \
  } else if(mark == -2) {                                                                     \
    clfx_store16_streaming((float16)0.0f, dst + quad * 16);                                   \
  } else {                                                                                    \
    fw_checked_quad(src, dst, records + 56 * q[1], src_pitch, src_w, src_h);                  \
  }                                                                                           \
  clfx_streaming_fence();                                                                     \
}
#else
#define EWA_WARP_KERNELS(effect)                                                              \
kernel void effect##_ewa_f64(global const float *src, global float *dst,                      \
                             global const REAL *map, const int src_pitch, const int src_w,    \
                             const int src_h, const int dst_pitch, const int dst_h,           \
                             const int row0, const int shift)                                 \
{                                                                                             \
  RS_BAND_PROLOGUE(src, src_pitch, dst, dst_pitch, dst_h, row0, shift);                       \
  REAL4 o[4];                                                                                 \
  for(int k = 0; k < 4; k++) {                                                                \
    const int x = qx * 4 + k;                                                                 \
    global const REAL *m = map + 8 * (my * dst_pitch + x);                                    \
    o[k] = rs_ewa_sample(src, src_pitch, src_w, src_h, (REAL)x + (REAL)0.5 + m[0],            \
                         (REAL)y + (REAL)0.5 + m[1], m[2], m[3], m[4], m[5], (int)m[6]);      \
  }                                                                                           \
  rs_store_quad(dst, y * dst_pitch + qx * 4, o);                                              \
}
#endif

#endif
