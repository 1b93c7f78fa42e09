/* lens.cl: a real lens's distortion, transverse CA and vignetting (clfx/plugins/lens.py).
 *
 * Green (and alpha) read the source at the distortion map's point u_g; with HAS_TCA, red and
 * blue read at C + (u_g - C) T_c(rho), rho = |u_g - C|^2 scaled to [0, 1] (C = lensfun's
 * optical centre, lensfun assumes square pixels): the inverse of the lens's TCA model.  With
 * HAS_VIG the result is multiplied by lensfun's pa polynomial 1 + k1 r^2 + k2 r^4 + k3 r^6
 * at the output pixel (r = 1 at the calibration frame's corner), clamped to >= 0.  4 output
 * pixels per work-item.
 *
 * lens_packed (draft / preview / final): the source points of every channel are computed
 * once per parameter set on the host in float64 and packed (clfx.fx.resample.PackedMap,
 * LENS_MAPS maps = green, then red and blue with TCA: 12 ints per map and quad): a pure
 * gather, no table reads, floor or border rule per pixel; lens_packed_fix then re-renders
 * the quads whose footprints leave the source through the checked path.  LENS_MAPS = 0
 * (vignetting only) reads the source pixels in place.
 *
 * lens_apply (reference, a CLFX_FP64 build: kernels/lib/precision.h): a float64
 * displacement map for green (HAS_MAP = 0: u_g = u) and float64 TCA tables, float64
 * coordinates, weights and sums.
 *
 * Each renders the canvas rows row0 .. row0 + rows (the map's rows: all in a whole render)
 * from buffers holding the canvas rows from `shift` on (CLFX_CANVAS_ROWS: a tile of a tiled
 * render, clfx.kit.warp.CanvasRows; 0 in a whole render); records count quads from the
 * canvas's first row.
 */
#include "lib/resample.h"

#if !REAL_IS_DOUBLE
/* multiply RGB of the 4 pixels of quad (qx, y) by the vignetting (no-op without HAS_VIG) */
inline void lens_vignette(int qx, int y, float ccx, float ccy, float vig_scale, float vk1,
                          float vk2, float vk3, float4 *c0, float4 *c1, float4 *c2, float4 *c3)
{
#if HAS_VIG
  const float4 ux = (float4)(qx * 4, qx * 4 + 1, qx * 4 + 2, qx * 4 + 3) + 0.5f;
  const float uy = (float)y + 0.5f;
  const float4 vx = (ux - ccx) * vig_scale;
  const float vy = (uy - ccy) * vig_scale;
  const float4 r2 = vx * vx + vy * vy;
  const float4 v = fmax(1.0f + r2 * (vk1 + r2 * (vk2 + r2 * vk3)), 0.0f);
  (*c0).xyz *= v.s0; (*c1).xyz *= v.s1; (*c2).xyz *= v.s2; (*c3).xyz *= v.s3;
#endif
}

/* LENS_MAPS == 3: red from the quad's second map and blue from its third (q_red, q_blue),
 * read by `read` (rs_fast_quad or rs_fix_quad) over c0..c3's red and blue. */
#define LENS_RED_BLUE(read, q_red, q_blue) {                                                 \
    float4 r0, r1, r2, r3;                                                                   \
    read(src, pitch, w, h, q_red, &r0, &r1, &r2, &r3);                                       \
    c0.x = r0.x; c1.x = r1.x; c2.x = r2.x; c3.x = r3.x;                                      \
    read(src, pitch, w, h, q_blue, &r0, &r1, &r2, &r3);                                      \
    c0.z = r0.z; c1.z = r1.z; c2.z = r2.z; c3.z = r3.z; }

kernel void lens_packed(global const float *src, global float *dst, global const int *map,
                        const int pitch, const int w, const int h, const int row0,
                        const int rows, const int shift, const float ccx,
                        const float ccy, const float vig_scale, const float vk1,
                        const float vk2, const float vk3)
{
  RS_BAND_PROLOGUE(src, pitch, dst, pitch, rows, row0, shift);
  const int entry = my * (pitch / 4) + qx, quad = y * (pitch / 4) + qx;
  float4 c0, c1, c2, c3;
#if LENS_MAPS == 0
  const float16 s = rs_sanitise16(vload16(0, src + quad * 16));
  c0 = s.lo.lo; c1 = s.lo.hi; c2 = s.hi.lo; c3 = s.hi.hi;
#else
  global const int *q = map + 12 * LENS_MAPS * entry;
  rs_fast_quad(src, pitch, w, h, q, &c0, &c1, &c2, &c3);
#if LENS_MAPS == 3
  LENS_RED_BLUE(rs_fast_quad, q + 12, q + 24)
#endif
#endif
  lens_vignette(qx, y, ccx, ccy, vig_scale, vk1, vk2, vk3, &c0, &c1, &c2, &c3);
  vstore16((float16)(c0, c1, c2, c3), 0, dst + quad * 16);
}

#if LENS_MAPS > 0
/* the border quads, after lens_packed: records of 4 + 8 LENS_MAPS ints (quad index,
 * 3 unused, then per map the 4 x and 4 y of the source points) */
kernel void lens_packed_fix(global const float *src, global float *dst,
                            global const int *records, const int count, const int pitch,
                            const int w, const int h, const int row0, const int rows,
                            const int shift, const float ccx, const float ccy,
                            const float vig_scale, const float vk1, const float vk2,
                            const float vk3)
{
  RS_RECORD_PROLOGUE(src, dst, pitch, count, shift);
  global const int *rec = records + (4 + 8 * LENS_MAPS) * n;
  const int quad = rec[0];
  float4 c0, c1, c2, c3;
  rs_fix_quad(src, pitch, w, h, rec + 4, &c0, &c1, &c2, &c3);
#if LENS_MAPS == 3
  LENS_RED_BLUE(rs_fix_quad, rec + 12, rec + 20)
#endif
  lens_vignette(quad % (pitch / 4), quad / (pitch / 4), ccx, ccy, vig_scale, vk1, vk2, vk3,
                &c0, &c1, &c2, &c3);
  vstore16((float16)(c0, c1, c2, c3), 0, dst + quad * 16);
}
#endif
#else
kernel void lens_apply(global const float *src, global float *dst, global const REAL *map,
                       global const REAL *luts, const int pitch, const int w, const int h,
                       const int row0, const int rows, const int shift,
                       const REAL ccx, const REAL ccy,
                       const REAL lut_scale, const REAL vig_scale, const REAL vk1,
                       const REAL vk2, const REAL vk3)
{
  RS_BAND_PROLOGUE(src, pitch, dst, pitch, rows, row0, shift);
  map -= (size_t)row0 * pitch * 2;    /* the map holds rows row0 .. row0 + rows */
  REAL4 o[4];
  for(int k = 0; k < 4; k++) {
#if HAS_MAP
    const REAL2 gp = rs_map_point(map, pitch, qx * 4 + k, y);
    const REAL gx = gp.x, gy = gp.y;
#else
    const REAL gx = (REAL)(qx * 4 + k) + (REAL)0.5, gy = (REAL)y + (REAL)0.5;
#endif
    REAL4 c = rs_sample(src, pitch, w, h, gx, gy);
#if HAS_TCA
    /* ccx, ccy: optical centre in source-window coordinates */
    const REAL dx = gx - ccx, dy = gy - ccy;
    const REAL t = clamp((dx * dx + dy * dy) * lut_scale, (REAL)0, (REAL)1) * (REAL)LUTN;
    const int j = min((int)t, LUTN - 1);
    const REAL f = t - (REAL)j;
    const REAL sr = luts[j] + f * (luts[j + 1] - luts[j]);
    const REAL sb = luts[LUTN + 1 + j] + f * (luts[LUTN + 2 + j] - luts[LUTN + 1 + j]);
    c.x = rs_sample(src, pitch, w, h, ccx + dx * sr, ccy + dy * sr).x;
    c.z = rs_sample(src, pitch, w, h, ccx + dx * sb, ccy + dy * sb).z;
#endif
#if HAS_VIG
    /* vignetting at the output pixel's centre */
    const REAL vx = ((REAL)(qx * 4 + k) + (REAL)0.5 - ccx) * vig_scale;
    const REAL vy = ((REAL)y + (REAL)0.5 - ccy) * vig_scale;
    const REAL r2 = vx * vx + vy * vy;
    const REAL v = fmax((REAL)1 + r2 * (vk1 + r2 * (vk2 + r2 * vk3)), (REAL)0);
    c.x *= v; c.y *= v; c.z *= v;
#endif
    o[k] = c;
  }
  rs_store_quad(dst, y * pitch + qx * 4, o);
}
#endif
