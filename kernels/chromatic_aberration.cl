/* chromatic_aberration.cl: lateral CA as NWAVE radially scaled reads of the source
 * (clfx/plugins/chromatic_aberration.py has the model; kernels/resample.h the filters).
 *
 * For wavelength (or channel) i the source point of output pixel u is c + (u - c) S_i(rho),
 * rho = |u - c|^2 normalised so the farthest output corner is 1 (pixel aspect applied);
 * S_i is the inverse radial scale of the lens model at that wavelength, tabulated against
 * rho (LUTN + 1 entries, linear interpolation: no square root, no per-pixel inversion).
 * The read is weighted by weights[i] = (wR, wG, wB, wA): each channel's weights sum to 1,
 * so a uniform image stays uniform and white stays white.  Three "wavelengths" with unit
 * weights per channel give the classic three-offset-copies CA (GREEN_IN_PLACE: green has
 * zero dispersion and is read in place).  Each work-item renders 4 consecutive pixels.
 */
#include "resample.h"

#ifndef MAP_REAL
#define MAP_REAL float
#endif

kernel void chromatic_aberration_apply(global const float *src, global float *dst,
                                       global const MAP_REAL *luts,
                                       global const MAP_REAL *weights, const int pitch,
                                       const int w, const int h, const int x0, const int y0,
                                       const MAP_REAL cx, const MAP_REAL cy,
                                       const MAP_REAL ax, const MAP_REAL ay)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= h || qx * 4 >= pitch) return;
  const int idx = y * pitch + qx * 4;
#ifndef RS_EXACT_TRIG
  /* float levels: the 4 pixels' radii, table reads and coordinates as float4 vectors */
  const float4 dx4 = (float4)(x0 + qx * 4, x0 + qx * 4 + 1, x0 + qx * 4 + 2, x0 + qx * 4 + 3)
                     + 0.5f - cx;
  const float dy1 = (float)(y0 + y) + 0.5f - cy;
  const float4 ux4 = dx4 * ax;
  const float uy1 = dy1 * ay;
  const float4 t4 = clamp(ux4 * ux4 + uy1 * uy1, 0.0f, 1.0f) * (float)LUTN;
  const int4 j4 = min(convert_int4(t4), LUTN - 1);
  const float4 f4 = t4 - convert_float4(j4);
  float4 a0 = 0.0f, a1 = 0.0f, a2 = 0.0f, a3 = 0.0f;
  for(int i = 0; i < NWAVE; i++) {
#if GREEN_IN_PLACE
    /* three-channel mode: green has zero dispersion by construction, so its (and
     * alpha's) read is the pixel itself: one vload16 for the 4 pixels, no filtering */
    if(i == 1) {
      const float16 g = rs_sanitise16(vload16(0, src + idx * 4));
      const float4 wt = vload4(1, weights);
      a0 += wt * g.lo.lo; a1 += wt * g.lo.hi; a2 += wt * g.hi.lo; a3 += wt * g.hi.hi;
      continue;
    }
#endif
    global const float *lut = luts + i * (LUTN + 1);
    const float4 l0 = (float4)(lut[j4.s0], lut[j4.s1], lut[j4.s2], lut[j4.s3]);
    const float4 l1 = (float4)(lut[j4.s0 + 1], lut[j4.s1 + 1], lut[j4.s2 + 1], lut[j4.s3 + 1]);
    const float4 s4 = l0 + f4 * (l1 - l0);
    const float4 wt = vload4(i, weights);
    float4 r0, r1, r2, r3;
    rs_sample4(src, pitch, w, h, cx + dx4 * s4 - (float)x0, (float4)(cy + dy1 * s4 - (float)y0),
               &r0, &r1, &r2, &r3);
    a0 += wt * r0; a1 += wt * r1; a2 += wt * r2; a3 += wt * r3;
  }
  vstore16((float16)(a0, a1, a2, a3), 0, dst + idx * 4);
#else
  REAL4 o[4];
  const REAL dy = (REAL)(y0 + y) + (REAL)0.5 - (REAL)cy;
  for(int k = 0; k < 4; k++) {
    const REAL dx = (REAL)(x0 + qx * 4 + k) + (REAL)0.5 - (REAL)cx;
    const REAL ux = dx * (REAL)ax, uy = dy * (REAL)ay;
    const REAL t = clamp(ux * ux + uy * uy, (REAL)0, (REAL)1) * (REAL)LUTN;
    const int j = min((int)t, LUTN - 1);
    const REAL f = t - (REAL)j;
    REAL4 acc = (REAL4)0;
    for(int i = 0; i < NWAVE; i++) {
      global const MAP_REAL *lut = luts + i * (LUTN + 1);
      const REAL s = (REAL)lut[j] + f * ((REAL)lut[j + 1] - (REAL)lut[j]);
      const REAL sx = (REAL)cx + dx * s - (REAL)x0;
      const REAL sy = (REAL)cy + dy * s - (REAL)y0;
      const REAL4 wt = (REAL4)((REAL)weights[4 * i], (REAL)weights[4 * i + 1],
                               (REAL)weights[4 * i + 2], (REAL)weights[4 * i + 3]);
      acc += wt * rs_sample(src, pitch, w, h, sx, sy);
    }
    o[k] = acc;
  }
  const float16 v = (float16)(convert_float4(o[0]), convert_float4(o[1]),
                              convert_float4(o[2]), convert_float4(o[3]));
  vstore16(v, 0, dst + idx * 4);
#endif
}
