/* chromatic_aberration.cl: lateral CA as NWAVE radially scaled reads of the source
 * (clfx/plugins/chromatic_aberration.py has the model; kernels/lib/resample.h the filters).
 *
 * For wavelength (or channel) i the source point of output pixel u is c + (u - c) S_i(rho),
 * rho = |u - c|^2 normalised so the farthest output corner is 1 (pixel aspect applied);
 * S_i is the inverse radial scale of the lens model at that wavelength, tabulated against
 * rho (LUTN + 1 entries, linear interpolation: no square root, no per-pixel inversion),
 * interleaved: entry j of wavelength i at luts[j * NWP + i].
 * The read is weighted by weights[i] = (wR, wG, wB, wA): each channel's weights sum to 1,
 * so a uniform image stays uniform and white stays white.  Three "wavelengths" with unit
 * weights per channel give the classic three-offset-copies CA (GREEN_IN_PLACE: green has
 * zero dispersion and is read in place).  Each work-item renders 4 consecutive pixels.
 *
 * Float levels launch this kernel twice (clfx/plugins/chromatic_aberration.py): with
 * CA_FAST = 1 over the interior rectangle of quads, where the host's bound on the largest
 * shift of any wavelength keeps every footprint inside the source (an unchecked vector
 * gather, kernels/lib/resample.h rs_fast4), and with CA_FAST = 0 over the border ring (border
 * rule and checks).  The launched rectangle is [qx0, qx0 + nqx) x [row0, row0 + nrows).
 *
 * Rows are the canvas's (w x h, origin (x0, y0) in the frame): a tile of a tiled render
 * (clfx.kit.warp.CanvasRows) passes buffers holding canvas rows from `shift` on, and
 * CLFX_CANVAS_ROWS addresses them in canvas rows, so its pixels take the whole render's
 * arithmetic.
 */
#include "lib/resample.h"

#ifndef NWP
#define NWP NWAVE       /* table row stride: NWAVE padded to a vector width */
#endif
#define CA_CAT2(a, b) a##b
#define CA_CAT(a, b) CA_CAT2(a, b)
#define LUTV CA_CAT(float, NWP)
#define LUT_LOAD(j, p) CA_CAT(vload, NWP)(j, p)
#define LUT_STORE(v, j, p) CA_CAT(vstore, NWP)(v, j, p)

kernel void chromatic_aberration_apply(global const float *src, global float *dst,
                                       global const REAL *luts,
                                       global const REAL *weights, const int pitch,
                                       const int w, const int h, const int x0, const int y0,
                                       const REAL cx, const REAL cy,
                                       const REAL ax, const REAL ay,
                                       const int qx0, const int row0, const int nqx,
                                       const int nrows, const int shift)
{
  CLFX_CANVAS_ROWS(src, pitch, 4, shift);
  CLFX_CANVAS_ROWS(dst, pitch, 4, shift);
  /* the launch covers quads [qx0, qx0 + nqx) x rows [row0, row0 + nrows) */
  if(get_global_id(0) >= nqx || get_global_id(1) >= nrows) return;
  const int qx = get_global_id(0) + qx0, y = get_global_id(1) + row0;
  const int idx = y * pitch + qx * 4;
#if !REAL_IS_DOUBLE
  /* float levels: the 4 pixels' radii, table reads and coordinates as float4 vectors */
  const float4 dx4 = (float4)(x0 + qx * 4, x0 + qx * 4 + 1, x0 + qx * 4 + 2, x0 + qx * 4 + 3)
                     + 0.5f - cx;
  const float dy1 = (float)(y0 + y) + 0.5f - cy;
  const float4 ux4 = dx4 * ax;
  const float uy1 = dy1 * ay;
  const float4 t4 = clamp(ux4 * ux4 + uy1 * uy1, 0.0f, 1.0f) * (float)LUTN;
  const int4 j4 = min(convert_int4(t4), (int4)(LUTN - 1));
  const float4 f4 = t4 - convert_float4(j4);
  /* the tables are interleaved (entry j holds all NWP wavelengths): per pixel two vector
   * loads and one mix give every wavelength's scale (scalar reads per wavelength cost 40%) */
  float sc0[NWP], sc1[NWP], sc2[NWP], sc3[NWP];
#if NWP == 4 || NWP == 8 || NWP == 16
#define CA_SCALES(k, arr) {                                                                  \
    const LUTV lo = LUT_LOAD(j4.s##k, luts), hi = LUT_LOAD(j4.s##k + 1, luts);                \
    LUT_STORE(lo + f4.s##k * (hi - lo), 0, arr); }
#else
#define CA_SCALES(k, arr)                                                                    \
    for(int i = 0; i < NWP; i++) {                                                           \
      const float lo = luts[j4.s##k * NWP + i], hi = luts[(j4.s##k + 1) * NWP + i];          \
      arr[i] = lo + f4.s##k * (hi - lo); }
#endif
  CA_SCALES(0, sc0) CA_SCALES(1, sc1) CA_SCALES(2, sc2) CA_SCALES(3, sc3)
#undef CA_SCALES
  float4 a0 = 0.0f, a1 = 0.0f, a2 = 0.0f, a3 = 0.0f;
#pragma unroll
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
    const float4 s4 = (float4)(sc0[i], sc1[i], sc2[i], sc3[i]);
    const float4 wt = vload4(i, weights);
    const float4 sx = cx + dx4 * s4 - (float)x0, sy = (float4)(cy + dy1 * s4 - (float)y0);
    float4 r0, r1, r2, r3;
#if CA_FAST
    /* an interior quad (the host's margin bounds every wavelength's shift): texel index
     * and fractions here, then the unchecked vector gather */
    const float4 fx = sx - 0.5f, fy = sy - 0.5f;
    const float4 flx = floor(fx), fly = floor(fy);
    const int4 base = (convert_int4(fly) * pitch + convert_int4(flx)) * 4;
    rs_fast4(src, pitch, base, fx - flx, fy - fly, &r0, &r1, &r2, &r3);
#else
    rs_sample4(src, pitch, w, h, sx, sy, &r0, &r1, &r2, &r3);
#endif
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
      const REAL l0 = (REAL)luts[j * NWP + i], l1 = (REAL)luts[(j + 1) * NWP + i];
      const REAL s = l0 + f * (l1 - l0);
      const REAL sx = (REAL)cx + dx * s - (REAL)x0;
      const REAL sy = (REAL)cy + dy * s - (REAL)y0;
      const REAL4 wt = (REAL4)((REAL)weights[4 * i], (REAL)weights[4 * i + 1],
                               (REAL)weights[4 * i + 2], (REAL)weights[4 * i + 3]);
      acc += wt * rs_sample(src, pitch, w, h, sx, sy);
    }
    o[k] = acc;
  }
  rs_store_quad(dst, idx, o);
#endif
}

#if !REAL_IS_DOUBLE
/* Three-bin mode (NWAVE = 3, GREEN_IN_PLACE) at float levels: the two moving bins' source
 * points precomputed per parameter set as a packed map (clfx.fx.resample.PackedMap, 2 maps =
 * 24 ints per quad): a pure gather with no table reads, floor or checks per pixel; the
 * quads whose footprints leave the source follow in chromatic_aberration_packed_fix. */

/* out = wr * red read + wg * green in place + wb * blue read, for the quad's 4 pixels */
inline void ca_mix_store(global const float *src, global float *dst, global const float *weights,
                         const int quad, float4 r0, float4 r1, float4 r2, float4 r3, float4 b0,
                         float4 b1, float4 b2, float4 b3)
{
  const float16 g = rs_sanitise16(vload16(0, src + quad * 16));
  const float4 wr = vload4(0, weights), wg = vload4(1, weights), wb = vload4(2, weights);
  vstore16((float16)(wr * r0 + wg * g.lo.lo + wb * b0, wr * r1 + wg * g.lo.hi + wb * b1,
                     wr * r2 + wg * g.hi.lo + wb * b2, wr * r3 + wg * g.hi.hi + wb * b3),
           0, dst + quad * 16);
}

/* the map holds canvas rows row0 .. row0 + rows (all in a whole render) */
kernel void chromatic_aberration_packed(global const float *src, global float *dst,
                                        global const int *map, global const float *weights,
                                        const int pitch, const int w, const int h,
                                        const int row0, const int rows, const int shift)
{
  RS_BAND_PROLOGUE(src, pitch, dst, pitch, rows, row0, shift);
  const int entry = my * (pitch / 4) + qx, quad = y * (pitch / 4) + qx;
  float4 r0, r1, r2, r3, b0, b1, b2, b3;
  rs_fast_quad(src, pitch, w, h, map + 24 * entry, &r0, &r1, &r2, &r3);
  rs_fast_quad(src, pitch, w, h, map + 24 * entry + 12, &b0, &b1, &b2, &b3);
  ca_mix_store(src, dst, weights, quad, r0, r1, r2, r3, b0, b1, b2, b3);
}

/* records of 20 ints: quad index (in canvas rows), 3 unused, then each map's 4 x and 4 y */
kernel void chromatic_aberration_packed_fix(global const float *src, global float *dst,
                                            global const int *records, const int count,
                                            global const float *weights, const int pitch,
                                            const int w, const int h, const int row0,
                                            const int rows, const int shift)
{
  RS_RECORD_PROLOGUE(src, dst, pitch, count, shift);
  global const int *rec = records + 20 * n;
  float4 r0, r1, r2, r3, b0, b1, b2, b3;
  rs_fix_quad(src, pitch, w, h, rec + 4, &r0, &r1, &r2, &r3);
  rs_fix_quad(src, pitch, w, h, rec + 12, &b0, &b1, &b2, &b3);
  ca_mix_store(src, dst, weights, rec[0], r0, r1, r2, r3, b0, b1, b2, b3);
}
#endif
