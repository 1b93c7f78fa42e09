/* lens.cl: a real lens's distortion, transverse CA and vignetting (clfx/plugins/lens.py).
 *
 * Green (and alpha) read the source at the distortion map's point u_g (output pixel centre +
 * displacement, source-window coordinates; HAS_MAP = 0 means no distortion: u_g = u).  With
 * HAS_TCA, red and blue read at C + (u_g - C) T_c(rho), rho = |u_g - C|^2 scaled so the LUT
 * covers [0, 1] (C = lensfun's optical centre, lensfun assumes square pixels): the inverse of
 * the lens's TCA model, tabulated per parameter set.  With HAS_VIG the result is multiplied
 * by lensfun's pa polynomial 1 + k1 r^2 + k2 r^4 + k3 r^6 at the output pixel (r = 1 at the
 * calibration frame's corner), clamped to >= 0.  4 output pixels per work-item.
 */
#include "resample.h"

#ifndef MAP_REAL
#define MAP_REAL float
#endif

kernel void lens_apply(global const float *src, global float *dst, global const MAP_REAL *map,
                       global const MAP_REAL *luts, const int pitch, const int w, const int h,
                       const int x0, const int y0,
                       const MAP_REAL ccx, const MAP_REAL ccy, const MAP_REAL lut_scale,
                       const MAP_REAL vig_scale, const MAP_REAL vk1, const MAP_REAL vk2,
                       const MAP_REAL vk3)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= h || qx * 4 >= pitch) return;
  const int idx = y * pitch + qx * 4;
#ifndef RS_EXACT_TRIG
  /* float levels: 4 pixels at once, coordinates as float4 vectors */
  const float4 ux = (float4)(qx * 4, qx * 4 + 1, qx * 4 + 2, qx * 4 + 3) + 0.5f;
  const float uy = (float)y + 0.5f;
#if HAS_MAP
  const float8 m = vload8(0, map + 2 * idx);
  const float4 gx = ux + m.even, gy = uy + m.odd;
#else
  const float4 gx = ux, gy = (float4)uy;
#endif
  float4 c0, c1, c2, c3;
  rs_sample4(src, pitch, w, h, gx, gy, &c0, &c1, &c2, &c3);
#if HAS_TCA
  {
    const float4 dx = gx - ccx, dy = gy - ccy;
    const float4 t = clamp((dx * dx + dy * dy) * lut_scale, 0.0f, 1.0f) * (float)LUTN;
    const int4 j = min(convert_int4(t), LUTN - 1);
    const float4 f = t - convert_float4(j);
    float4 r0, r1, r2, r3;
#define LENS_LUT(off) (float4)(luts[(off) + j.s0], luts[(off) + j.s1], luts[(off) + j.s2], luts[(off) + j.s3])
    const float4 sr = LENS_LUT(0) + f * (LENS_LUT(1) - LENS_LUT(0));
    rs_sample4(src, pitch, w, h, ccx + dx * sr, ccy + dy * sr, &r0, &r1, &r2, &r3);
    c0.x = r0.x; c1.x = r1.x; c2.x = r2.x; c3.x = r3.x;
    const float4 sb = LENS_LUT(LUTN + 1) + f * (LENS_LUT(LUTN + 2) - LENS_LUT(LUTN + 1));
#undef LENS_LUT
    rs_sample4(src, pitch, w, h, ccx + dx * sb, ccy + dy * sb, &r0, &r1, &r2, &r3);
    c0.z = r0.z; c1.z = r1.z; c2.z = r2.z; c3.z = r3.z;
  }
#endif
#if HAS_VIG
  {
    const float4 vx = (ux - ccx) * vig_scale;
    const float vy = (uy - ccy) * vig_scale;
    const float4 r2 = vx * vx + vy * vy;
    const float4 v = fmax(1.0f + r2 * (vk1 + r2 * (vk2 + r2 * vk3)), 0.0f);
    c0.xyz *= v.s0; c1.xyz *= v.s1; c2.xyz *= v.s2; c3.xyz *= v.s3;
  }
#endif
  vstore16((float16)(c0, c1, c2, c3), 0, dst + idx * 4);
#else
  float4 o[4];
  for(int k = 0; k < 4; k++) {
    /* output pixel centre in source-window coordinates */
    const REAL ux = (REAL)(qx * 4 + k) + (REAL)0.5;
    const REAL uy = (REAL)y + (REAL)0.5;
#if HAS_MAP
    const REAL gx = ux + (REAL)map[2 * (idx + k)];
    const REAL gy = uy + (REAL)map[2 * (idx + k) + 1];
#else
    const REAL gx = ux, gy = uy;
#endif
    const REAL4 g = rs_sample(src, pitch, w, h, gx, gy);
    REAL4 c = g;
#if HAS_TCA
    /* ccx, ccy: optical centre in source-window coordinates */
    const REAL dx = gx - (REAL)ccx, dy = gy - (REAL)ccy;
    const REAL t = clamp((dx * dx + dy * dy) * (REAL)lut_scale, (REAL)0, (REAL)1) * (REAL)LUTN;
    const int j = min((int)t, LUTN - 1);
    const REAL f = t - (REAL)j;
    const REAL sr = (REAL)luts[j] + f * ((REAL)luts[j + 1] - (REAL)luts[j]);
    const REAL sb = (REAL)luts[LUTN + 1 + j] + f * ((REAL)luts[LUTN + 2 + j] - (REAL)luts[LUTN + 1 + j]);
    c.x = rs_sample(src, pitch, w, h, (REAL)ccx + dx * sr, (REAL)ccy + dy * sr).x;
    c.z = rs_sample(src, pitch, w, h, (REAL)ccx + dx * sb, (REAL)ccy + dy * sb).z;
#endif
#if HAS_VIG
    const REAL vx = (ux - (REAL)ccx) * (REAL)vig_scale, vy = (uy - (REAL)ccy) * (REAL)vig_scale;
    const REAL r2 = vx * vx + vy * vy;
    const REAL v = fmax((REAL)1 + r2 * ((REAL)vk1 + r2 * ((REAL)vk2 + r2 * (REAL)vk3)), (REAL)0);
    c.x *= v; c.y *= v; c.z *= v;
#endif
    o[k] = convert_float4(c);
  }
  vstore16((float16)(o[0], o[1], o[2], o[3]), 0, dst + idx * 4);
#endif
}
