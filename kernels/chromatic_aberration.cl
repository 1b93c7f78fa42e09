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
 * quads whose footprints leave the source follow in chromatic_aberration_packed_fix.  The
 * bicubic levels take chromatic_aberration_packed_rb and _exact instead of _packed (below). */

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

/* A quad of the packed map: both bins on all 4 channels, mixed by the weights (kept out of
 * line: for the bicubic levels it is the rare exact path of chromatic_aberration_packed). */
CLFX_COLD void ca_packed_quad(global const float *src, global float *dst, global const int *q,
                              global const float *weights, const int pitch, const int w,
                              const int h, const int quad)
{
  float4 r0, r1, r2, r3, b0, b1, b2, b3;
  rs_fast_quad(src, pitch, w, h, q, &r0, &r1, &r2, &r3);
  rs_fast_quad(src, pitch, w, h, q + 12, &b0, &b1, &b2, &b3);
  ca_mix_store(src, dst, weights, quad, r0, r1, r2, r3, b0, b1, b2, b3);
}

/* Bicubic (preview, final): the two bins in one pass.  The red bin's read feeds only the red
 * channel and the blue bin's only blue (three-channel weights: channel_bins), so per pixel
 * each footprint row is one float16 of 4 texels whose R lanes come from the red bin's
 * row and B lanes from the blue bin's: one vertical sum, one horizontal weighting and one
 * clamp for both (rs_fast4's RS_CUBIC does each bin on all 4 channels, twice the work).
 * Every lane takes rs_fast4's operations in its order, so R and B are bit for bit its
 * results; G and A lanes carry finite values the weights zero.  The clamp's bounds take
 * min/max (the texels are finite: sanitised, or the frame has none; a result at +-0,
 * where the bounds' order of signed zeros could tell, is rendered again exactly). */
#if RS_FILTER == 1
#define CA_BLEND(r, b) CLFX_SHUFFLE16(r, b, 0, 1, 18, 3, 4, 5, 22, 7, 8, 9, 26, 11,   \
                                      12, 13, 30, 15)
/* the quad's (red, 0, blue, 0) weights, pixel k in lanes 4k..4k+3, from the bins' per-pixel
 * float4s; CA_W4 picks pixel k's */
#define CA_WQ(r, b) CLFX_SHUFFLE16((float8)(r, b), (float8)(0.0f), 0, 8, 4, 8, 1, 8, 5, \
                                   8, 2, 8, 6, 8, 3, 8, 7, 8)
#define CA_W4_0(v) (v).s0123
#define CA_W4_1(v) (v).s4567
#define CA_W4_2(v) (v).s89ab
#define CA_W4_3(v) (v).scdef
#define CA_W4(v, k) CA_W4_##k(v)
#define CA_ROW(j) rs_sanitise16(CA_BLEND(vload16(0, pr + (j) * row), vload16(0, pb + (j) * row)))
#define CA_PIXEL(k, o) {                                                                     \
    global const float *pr = src + br.s##k - row - 4, *pb = src + bb.s##k - row - 4;        \
    const float16 a0 = CA_ROW(0), a1 = CA_ROW(1), a2 = CA_ROW(2), a3 = CA_ROW(3);            \
    const float4 y0 = CA_W4(y0q, k), y1 = CA_W4(y1q, k);                                    \
    const float4 y2 = CA_W4(y2q, k), y3 = CA_W4(y3q, k);                                    \
    const float16 v = fma(a3, (float16)(y3, y3, y3, y3), fma(a2, (float16)(y2, y2, y2, y2),  \
                      fma(a1, (float16)(y1, y1, y1, y1), a0 * (float16)(y0, y0, y0, y0))));  \
    const float16 hs = v * (float16)(CA_W4(x0q, k), CA_W4(x1q, k), CA_W4(x2q, k),             \
                                     CA_W4(x3q, k));                                         \
    const float4 lo = min(min(a1.s4567, a1.s89ab), min(a2.s4567, a2.s89ab));                \
    const float4 hi = max(max(a1.s4567, a1.s89ab), max(a2.s4567, a2.s89ab));                \
    o = clamp(RS_HSUM16(hs), lo, hi); }

/* always inlined: PoCL kept it out of line, its outputs through the stack (1080p final:
 * 37 -> 35.5 ms of CPU) */
CLFX_INLINE void ca_cubic_bins(global const float *src, int pitch,
                               int w, int h, global const int *q,
                               float4 *o0, float4 *o1, float4 *o2,
                               float4 *o3)
{
  const int row = pitch * 4, off = RS_TAPS / 2 - 1;
  /* rs_fast_quad's clamp: border quads (re-rendered later) read inside the image */
  const int4 lo = (int4)(off * (pitch + 1) * 4);
  const int4 hi = (int4)(((h - RS_TAPS + off) * pitch + (w - RS_TAPS + off)) * 4);
  const int4 br = clamp(vload4(0, q), lo, hi), bb = clamp(vload4(3, q), lo, hi);
  float8 r0, r1, r2, r3, b0, b1, b2, b3;    /* lanes 0-3 x, 4-7 y (rs_cubic_w4's formula) */
  rs_cubic_w8(as_float8(vload8(0, q + 4)), &r0, &r1, &r2, &r3);
  rs_cubic_w8(as_float8(vload8(0, q + 16)), &b0, &b1, &b2, &b3);
  const float16 x0q = CA_WQ(r0.lo, b0.lo), x1q = CA_WQ(r1.lo, b1.lo);
  const float16 x2q = CA_WQ(r2.lo, b2.lo), x3q = CA_WQ(r3.lo, b3.lo);
  const float16 y0q = CA_WQ(r0.hi, b0.hi), y1q = CA_WQ(r1.hi, b1.hi);
  const float16 y2q = CA_WQ(r2.hi, b2.hi), y3q = CA_WQ(r3.hi, b3.hi);
  CA_PIXEL(0, *o0) CA_PIXEL(1, *o1) CA_PIXEL(2, *o2) CA_PIXEL(3, *o3)
}
#undef CA_PIXEL
#undef CA_ROW
#undef CA_W4
#undef CA_W4_0
#undef CA_W4_1
#undef CA_W4_2
#undef CA_W4_3
#undef CA_WQ
#undef CA_BLEND
#endif

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

#if RS_FILTER == 1
/* Bicubic: the blended pass (ca_cubic_bins) over every quad.  ca_mix_store's sum
 * wr * red + wg * green + wb * blue with the three-bin weights (0/1, channel_bins) is each
 * channel's own value plus zeros, which this sum over the blended results is too, bit for
 * bit, unless that value is +-0: its sign then follows the zeros' (the bins' other channels,
 * not computed here).  Such quads (black or transparent pixels) are flagged (flags[entry] = 1;
 * a store, not a branch: a branch in this kernel, even to an atomic, cost 15 %) and
 * chromatic_aberration_packed_exact renders them again with both bins whole.  1080p final,
 * CPU ms: 60-64 for chromatic_aberration_packed, 44-46 for this and 1 for the exact pass. */
kernel void chromatic_aberration_packed_rb(global const float *src, global float *dst,
                                           global const int *map, global uchar *flags,
                                           global const float *weights, const int pitch,
                                           const int w, const int h, const int row0,
                                           const int rows, const int shift)
{
  RS_BAND_PROLOGUE(src, pitch, dst, pitch, rows, row0, shift);
  const int entry = my * (pitch / 4) + qx, quad = y * (pitch / 4) + qx;
  float4 o0, o1, o2, o3;  /* (red bin's R, -, blue bin's B, -) */
  ca_cubic_bins(src, pitch, w, h, map + 24 * entry, &o0, &o1, &o2, &o3);
  const float16 g = rs_sanitise16(vload16(0, src + quad * 16));
  const float4 wr = vload4(0, weights), wg = vload4(1, weights), wb = vload4(2, weights);
  const float16 t = (float16)(wr * o0 + wg * g.lo.lo + wb * o0, wr * o1 + wg * g.lo.hi + wb * o1,
                              wr * o2 + wg * g.hi.lo + wb * o2, wr * o3 + wg * g.hi.hi + wb * o3);
  vstore16(t, 0, dst + quad * 16);
  /* a lane at +-0, tested lane by lane on the bits (PoCL's any() of a float16 compare, or
   * of its halves OR-ed, cost 5-7 ms of CPU more at 1080p) */
  const int16 z = as_int16(t) & 0x7fffffff;
  flags[entry] = (uchar)((z.s0 == 0) | (z.s1 == 0) | (z.s2 == 0) | (z.s3 == 0) | (z.s4 == 0)
                         | (z.s5 == 0) | (z.s6 == 0) | (z.s7 == 0) | (z.s8 == 0) | (z.s9 == 0)
                         | (z.sa == 0) | (z.sb == 0) | (z.sc == 0) | (z.sd == 0) | (z.se == 0)
                         | (z.sf == 0));
}

/* The flagged quads of chromatic_aberration_packed_rb through both bins (its arguments, one
 * work-item per CA_EXACT_QUADS entries of the map). */
#define CA_EXACT_QUADS 64
kernel void chromatic_aberration_packed_exact(global const float *src, global float *dst,
                                              global const int *map, global uchar *flags,
                                              global const float *weights, const int pitch,
                                              const int w, const int h, const int row0,
                                              const int rows, const int shift)
{
  const int quads = pitch / 4, e0 = get_global_id(0) * CA_EXACT_QUADS;
  const int e1 = min(e0 + CA_EXACT_QUADS, rows * quads);
  if(e0 >= e1) return;
  CLFX_CANVAS_ROWS(src, pitch, 4, shift);
  CLFX_CANVAS_ROWS(dst, pitch, 4, shift);
  for(int e = e0; e < e1; e++)
    if(flags[e])
      ca_packed_quad(src, dst, map + 24 * e, weights, pitch, w, h,
                     (e / quads + row0) * quads + e % quads);
}
#endif

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
