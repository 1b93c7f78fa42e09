/* sensor_noise.cl: photon shot noise, read noise and fixed-pattern PRNU in linear light
 * (clfx/plugins/sensor_noise.py has the model).
 *
 * One work-item handles 4 pixels x 4 channels as 16 lanes (rows are padded to 4 pixels);
 * the alpha lanes get zero electrons per unit and are copied bit for bit at the end (a
 * non-finite value, colour or alpha, becomes 0 first).
 * Random numbers: clfx_uniform(seed, frame, X, Y, c) of common.h for frame coordinates
 * X = fx0 + x, Y = fy0 + y, with streams c = 0..3 and 4..7 (Box-Muller pair: shot and read
 * Gaussians) and 8..11 (the uniform of the Poisson inversion).  PRNU uses its own seed and
 * frame 0, so the pattern is the same on every frame: sensor_noise_prnu writes it once per
 * parameter set and window (cached in the runtime's cache) and sensor_noise_apply reads it.
 *
 * With MOSAIC=1 sensor_noise_apply writes, per pixel, only the deviation of its Bayer (RGGB)
 * colour: the photosite's noise; sensor_noise_demosaic (end of file) demosaics that mosaic
 * (Malvar-He-Cutler) onto the clean plate and adds the optional chroma blotches.
 * Defines: SHOT, READ, PRNU (0/1) drop unused terms at compile time; INVERT=1 samples the
 * Poisson count exactly by inversion when lambda <= SWITCH electrons (a search over the
 * summed CDF, four terms per step, bounded by MAX_COUNT terms; u capped at 1 - 4e-6), else
 * the normal approximation lambda + sqrt(lambda) z.  A build with CLFX_FP64 (the reference
 * level, kernels/lib/precision.h) does all arithmetic in double.
 *
 * Speed notes (PoCL on AVX-512, where the inversion dominated): any() is reduced by vector
 * ORs (PoCL's any() branches per lane), the CDF terms of a step are independent products
 * (no latency chain), coefficients are compile-time constants, and the count is kept in
 * masked increments; the loop runs to the largest count among the 12 colour lanes.
 */
#include "lib/common.h"

#ifndef SHOT
#define SHOT 1
#endif
#ifndef READ
#define READ 1
#endif
#ifndef PRNU
#define PRNU 0
#endif
#ifndef INVERT
#define INVERT 1
#endif
#ifndef SWITCH
#define SWITCH 30.0
#endif
#ifndef MAX_COUNT
#define MAX_COUNT 200
#endif
#ifndef COVERAGE
#define COVERAGE 0          /* 1: weight the deviation by alpha (the pass that writes the output) */
#endif
#ifndef MOSAIC
#define MOSAIC 0            /* 1: write the CFA site deviations (one float per pixel) */
#endif
#define U_CAP 4e-6

#include "lib/precision.h"
#include "lib/coverage.h"
#if REAL_IS_DOUBLE
#define MASK16 long16
#define MASK8 long8
#define MASK4 long4
#define MASK2 long2
#define SN_LOG(x) log(x)
#define SN_EXP(x) exp(x)
#define SN_SINCOS2PI(u, c) sincos((REAL)SN_TWO_PI * (u), (c))
#define SN_COS2PI(u) cos((REAL)SN_TWO_PI * (u))
#else
#define MASK16 int16
#define MASK8 int8
#define MASK4 int4
#define MASK2 int2
#define SN_LOG(x) clfx_log16(x)
#define SN_EXP(x) clfx_exp16(x)
#define SN_SINCOS2PI(u, c) clfx_sincos2pi16((u), (c))
#define SN_COS2PI(u) sensor_noise_cos2pi16(u)
#endif

#define SN_TWO_PI 6.283185307179586

#include "lib/fastmath.h"

/* 1 / (j (j + 1) ... (j + m - 1)) for m = 1..4 and j = 4 b + 1: the coefficients of the
 * inversion's step b (constant-folded; up to j = 256). */
#if MAX_COUNT > 256
#error "MAX_COUNT > 256: extend sn_coef"
#endif
#define SN_STEPS (((MAX_COUNT + 7) / 8) * 2)      /* steps of 4 terms, tested in pairs */
#define SN_COEF(j) {(REAL)1 / (REAL)(j), (REAL)1 / ((REAL)(j) * (REAL)((j) + 1)),              \
                    (REAL)1 / ((REAL)(j) * (REAL)((j) + 1) * (REAL)((j) + 2)),                  \
                    (REAL)1 / ((REAL)(j) * (REAL)((j) + 1) * (REAL)((j) + 2) * (REAL)((j) + 3))}
#define SN_COEF4(j) SN_COEF(j), SN_COEF((j) + 4), SN_COEF((j) + 8), SN_COEF((j) + 12)
#define SN_COEF16(j) SN_COEF4(j), SN_COEF4((j) + 16), SN_COEF4((j) + 32), SN_COEF4((j) + 48)
constant REAL sn_coef[64][4] = {SN_COEF16(1), SN_COEF16(65), SN_COEF16(129), SN_COEF16(193)};

/* any() of a 16-lane mask by halving ORs: PoCL expands any() into 16 extract-and-branch
 * steps (data-dependent branches, mispredicted), this is four vector ORs and one test. */
inline int sensor_noise_any16(const MASK16 m)
{
  const MASK8 a = m.lo | m.hi;
  const MASK4 b = a.lo | a.hi;
  const MASK2 c = b.lo | b.hi;
  return (c.x | c.y) < 0;
}
CLFX_DEFINE_FASTMATH(16)

inline float16 sensor_noise_cos2pi16(const float16 u)
{
  float16 c;
  clfx_sincos2pi16(u, &c);
  return c;
}

/* The uniform of streams c0 + c (lane 4 i + c) from clfx_hash_xy16 (fastmath.h), in REAL:
 * the per-pixel hashes are shared by the pixel's streams. */
inline REAL16 sensor_noise_stream16(const uint16 hxy, const int c0)
{
  return TO_REAL16(clfx_stream16(hxy, c0));
}

/* The fixed pattern's relative gain error prnu z per pixel and channel (alpha lanes 0):
 * a Gaussian z by Box-Muller from streams 0 and 4 of prnu_seed at frame 0, in REAL, stored
 * as float.  Computed once per parameter set and window; sensor_noise_apply multiplies
 * by 1 + pattern. */
kernel void sensor_noise_prnu(global float *pattern, const int pitch, const int height,
                              const int fx0, const int fy0, const uint prnu_seed,
                              const float prnu)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= height || qx * 4 >= pitch) return;
  const int x = qx * 4;
  const uint16 hp = clfx_hash_xy16(prnu_seed, 0, fx0 + x, fy0 + y);
  const REAL16 fa = sensor_noise_stream16(hp, 0), fb = sensor_noise_stream16(hp, 4);
  const REAL16 z = sqrt((REAL)(-2) * SN_LOG(fa)) * SN_COS2PI(fb);
  const int16 alpha = (int16)(0, 0, 0, -1, 0, 0, 0, -1, 0, 0, 0, -1, 0, 0, 0, -1);
  vstore16(select(TO_FLOAT16((REAL)prnu * z), (float16)0.0f, alpha), 0,
           pattern + (size_t)(y * pitch + x) * 4);
}

/* The model's deviation of the output at clean linear values v (g: linear units per
 * electron, vsat: the full well in linear units): shot noise below the well (none at or
 * above: a full well reads full), read noise, PRNU below the well.  sn_sigma4 below is the
 * same for one float4 pixel. */
inline REAL16 sn_sigma16(const REAL16 v, const REAL16 g, const REAL16 vsat, const REAL read_e,
                         const REAL prnu)
{
  const REAL zero = (REAL)0;
  const REAL16 below = select(max(v, zero), (REAL16)zero, v >= vsat);
  REAL16 var = (read_e * g) * (read_e * g) + (prnu * below) * (prnu * below);
#if SHOT
  var += g * below;
#endif
  return sqrt(var);
}

/* CFA colour of frame pixel (X, Y): 0 R, 1 G, 2 B (RGGB) */
inline int sn_cfa(int fx, int fy)
{
  const int ox = fx & 1, oy = fy & 1;
  return ox == oy ? (ox ? 2 : 0) : 1;
}

kernel void sensor_noise_apply(global const float *src, global float *dst,
                               global const float *pattern, const int pitch,
                               const int height, const int fx0, const int fy0,
                               const uint seed, const int frame,
                               const float kr, const float kg, const float kb,
                               const float read_e, const float well, const float prnu)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= height || qx * 4 >= pitch) return;
  const int x = qx * 4, fx = fx0 + x, fy = fy0 + y;
  const size_t i = (size_t)(y * pitch + x) * 4;
  const float16 c = vload16(0, src + i);
  const float16 cs = clfx_finite16_or_zero(c);                /* non-finite -> 0, alpha too */
  /* |v| <= 1e38 so the PRNU gain (<= 1.6) cannot overflow float */
  REAL16 v = TO_REAL16(clamp(cs, -1e38f, 1e38f));
#if MOSAIC || COVERAGE
  const REAL16 v_clean = v;
#endif

  /* electrons per unit of linear value (k) and linear value per electron (g); alpha: 0 */
  const REAL zero = (REAL)0;
  const REAL16 k16 = (REAL16)(kr, kg, kb, zero, kr, kg, kb, zero,
                              kr, kg, kb, zero, kr, kg, kb, zero);
  const REAL16 g16 = select((REAL16)zero, (REAL)1 / k16, k16 > zero);
  /* the full well: a site holds at most `well` electrons (vsat in linear units); a full
   * well reads full, whatever more light fell on it and whatever its gain error */
  const REAL16 vsat = (REAL)well * g16;

#if PRNU
  /* photo-response non-uniformity: a fixed per-pixel, per-channel gain 1 + prnu z */
  {
    const REAL16 vc = v;
    v *= (REAL)1 + TO_REAL16(vload16(0, pattern + i));
    /* at the well: the reading changes only by what stays below it */
    v = select(v, vc + (min(v, vsat) - min(vc, vsat)), max(v, vc) >= vsat);
  }
#endif

  REAL16 out = v;
#if SHOT || READ
  const uint16 hxy = clfx_hash_xy16(seed, frame, fx, fy);
  const REAL16 ua = sensor_noise_stream16(hxy, 0), ub = sensor_noise_stream16(hxy, 4);
  const REAL16 r = sqrt((REAL)(-2) * SN_LOG(ua));
  REAL16 co;
  const REAL16 si = SN_SINCOS2PI(ub, &co);
#endif

#if SHOT
  {
    /* Poisson(lambda) electrons, lambda = max(v, 0) k; the deviation N - lambda, in linear
     * units, is added to v so that negative inputs keep their value (zero mean always). */
    const REAL16 vpos = max(v, zero);
    /* normal approximation; the cap keeps v near FLT_MAX finite */
    REAL16 dev = sqrt(min(vpos, (REAL)1e30) * g16) * r * co;
#if INVERT
    const REAL16 lam = vpos * k16;                     /* inf for huge v: normal branch */
    const MASK16 small = lam <= (REAL)SWITCH;
    if(sensor_noise_any16(small))
    {
      /* exact inversion of the Poisson CDF: the smallest n with u <= F(n), i.e. the number of
       * j >= 0 with F(j) < u (F rises with j).  u is capped at 1 - U_CAP so rounding in the
       * summed CDF (float32: |F - F_exact| <= 1.2e-6 for lambda <= 30, measured over a fine
       * lambda grid; double: ~1e-15) can never leave F below u: the top U_CAP quantile maps
       * to its lower edge. */
      const REAL16 u = min(sensor_noise_stream16(hxy, 8), (REAL)1 - (REAL)U_CAP);
      const REAL16 ls = select((REAL16)zero, lam, small), one = (REAL16)((REAL)1);
      REAL16 p = SN_EXP(-ls);                          /* pmf(j - 1) */
      REAL16 d = u - p;                                /* u - F(j - 1) */
      /* the count n in four partial sums, each a masked increment (no add chain) */
      REAL16 n0 = select((REAL16)zero, one, d > zero), n1 = (REAL16)zero;
      REAL16 n2 = (REAL16)zero, n3 = (REAL16)zero;
      /* Four terms per step, each from pmf(j - 1) by lambda^m / (j ... j + m - 1): products
       * and prefix sums are independent, so the loop-carried chain is one multiply and one
       * subtraction per four terms (the one-term recurrence is latency-bound).  A lane counts
       * term j while d = u - F(j) > 0; once d <= 0 it stays so (IEEE: d > s iff d - s > 0),
       * so finished lanes run on without masks.  The any() test comes every eight terms. */
      const REAL16 l2 = ls * ls, l3 = l2 * ls, l4 = l2 * l2;
      for(int b = 0; b < SN_STEPS && sensor_noise_any16(d > zero); )
      {
#pragma unroll
        for(int h = 0; h < 2; h++, b++)
        {
          const REAL16 p1 = p * (ls * sn_coef[b][0]), p2 = p * (l2 * sn_coef[b][1]);
          const REAL16 p3 = p * (l3 * sn_coef[b][2]), p4 = p * (l4 * sn_coef[b][3]);
          const REAL16 s2 = p1 + p2, s3 = s2 + p3, s4 = s3 + p4;
          n0 = select(n0, n0 + one, d > p1);
          n1 = select(n1, n1 + one, d > s2);
          n2 = select(n2, n2 + one, d > s3);
          n3 = select(n3, n3 + one, d > s4);
          d -= s4;
          p = p4;
        }
      }
      const REAL16 n = (n0 + n1) + (n2 + n3);
      dev = select(dev, (n - ls) * g16, small);
    }
#endif
    /* the count cannot pass the well: a site at or above it reads exactly full */
    dev = select(min(dev, vsat - vpos), (REAL16)zero, vpos >= vsat);
    out += dev;
  }
#endif

#if READ
  out += (REAL)read_e * g16 * r * si;                  /* Gaussian read noise, electrons */
#endif

#if MOSAIC
  /* one float per pixel: the deviation (PRNU, shot, read) of the pixel's CFA colour in
   * units of the model's deviation there (sn_sigma16), the photosite's own noise as a unit
   * field (sensor_noise_demosaic interpolates it and scales each pixel's colours by their
   * own deviation) */
  const REAL16 sd = sn_sigma16(v_clean, g16, vsat, (REAL)read_e, (REAL)prnu);
  const float16 dev = TO_FLOAT16(select((REAL16)zero, (out - v_clean) / sd, sd > zero));
  const int c0 = sn_cfa(fx, fy), c1 = sn_cfa(fx + 1, fy);   /* colours alternate in a row */
  vstore4((float4)(dev[c0], dev[4 + c1], dev[8 + c0], dev[12 + c1]), 0, dst + (size_t)y * pitch + x);
#else
#if COVERAGE
  /* the deviation weighted by alpha in [0, 1]: transparent pixels stay as they were, opaque
   * ones keep the full deviation bit for bit */
  out = clfx_cover16(v_clean, out, cs);
#endif
  const int16 alpha = (int16)(0, 0, 0, -1, 0, 0, 0, -1, 0, 0, 0, -1, 0, 0, 0, -1);
  vstore16(select(TO_FLOAT16(out), cs, alpha), 0, dst + i);
#endif
}

/* ---- Bayer mosaic, demosaic and chroma blotches (sensor_noise_demosaic) -----------------
 * The camera measures one colour per photosite (RGGB at frame coordinates: R at even X and
 * even Y, B at odd X and odd Y, G elsewhere) and interpolates the others.  The site's
 * deviation is the photosite's own noise: sensor_noise_apply drew independent deviations
 * for all three channels of every pixel (noisy - v), and the site keeps its CFA colour's.
 * The deviation mosaic is then demosaiced by Malvar, He and Cutler's gradient-corrected
 * bilinear filters (2004; 5 x 5, the interpolated channel corrected by the centre site's
 * Laplacian), so noise becomes correlated across channels and neighbouring pixels as in a
 * camera's output; the clean signal v is not demosaiced (the plate keeps its detail).
 * Sites outside the data window are read mirrored about its edge (x -> -x, w-1 -> w+1... and
 * then clamped for windows under 3 px), so within 2 px of the edge a crop differs from a
 * full render.  DEMOSAIC=0 keeps each pixel's own deviation (mosaic "none").
 * CHROMA=1 adds low-frequency chroma noise: two value-noise fields (unit Gaussians at the
 * nodes of a grid of CELL px in frame coordinates, per frame, blended with smoothstep
 * weights) a, b give dR = k a, dB = k b, dG = -(wR dR + wB dB) / wG (luminance unchanged),
 * k = chroma * the green noise deviation the model gives at the pixel. */
#ifndef DEMOSAIC
#define DEMOSAIC 1
#endif
#ifndef CHROMA
#define CHROMA 0
#endif

/* 1 / the norm of each interpolating filter of Malvar-He-Cutler (its coefficients / 8):
 * R or B at a green site (5, 4, 4, -1 x 4, -1/2... : sum of squares 63.5 / 64), green at a
 * red or blue site (36 / 64), blue at red or red at blue (61 / 64) */
#define SN_NORM_HV 0.12549116102763172f     /* 1 / sqrt(63.5) */
#define SN_NORM_G 0.16666666666666666f      /* 1 / sqrt(36) */
#define SN_NORM_O 0.12803687993289598f      /* 1 / sqrt(61) */

inline float4 sn_sigma4(const float4 v, const float4 g, const float4 vsat, const float read_e,
                        const float prnu)
{
  const float4 below = select(max(v, 0.0f), (float4)0.0f, v >= vsat);
  float4 var = (read_e * g) * (read_e * g) + (prnu * below) * (prnu * below);
#if SHOT
  var += g * below;
#endif
  return sqrt(var);
}

inline int sn_mirror(int i, int n)
{
  i = i < 0 ? -i : i;
  i = i >= n ? 2 * (n - 1) - i : i;
  return clamp(i, 0, n - 1);
}

/* the site deviation at window pixel (x, y), mirrored inside the window (mirroring keeps
 * the parity, so the colour is the unmirrored site's except where a window under 3 px
 * clamps: then the site it lands on) */
inline float sn_site(global const float *mosaic, int x, int y, int pitch, int width, int height)
{
  return mosaic[(size_t)sn_mirror(y, height) * pitch + sn_mirror(x, width)];
}

inline float sn_hash_gauss(uint seed, int frame, int gx, int gy, int stream)
{
  const float u1 = clfx_uniform(seed, frame, gx, gy, stream);
  const float u2 = clfx_uniform(seed, frame, gx, gy, stream + 1);
  return sqrt(-2.0f * log(u1)) * cos(6.283185307179586f * u2);
}

inline float sn_value_noise(uint seed, int frame, float px, float py, int stream)
{
  const float gx = floor(px), gy = floor(py);
  const float tx = px - gx, ty = py - gy;
  const float sx = tx * tx * (3.0f - 2.0f * tx), sy = ty * ty * (3.0f - 2.0f * ty);
  const int ix = (int)gx, iy = (int)gy;
  const float a = sn_hash_gauss(seed, frame, ix, iy, stream);
  const float b = sn_hash_gauss(seed, frame, ix + 1, iy, stream);
  const float c = sn_hash_gauss(seed, frame, ix, iy + 1, stream);
  const float d = sn_hash_gauss(seed, frame, ix + 1, iy + 1, stream);
  return mix(mix(a, b, sx), mix(c, d, sx), sy);
}

/* noisy: DEMOSAIC=1 the site mosaic (one float per pixel, sensor_noise_apply with MOSAIC=1),
 * else the per-pixel noisy RGBA */
kernel void sensor_noise_demosaic(global const float *src, global const float *noisy,
                                  global float *dst, const int pitch, const int width,
                                  const int height, const int fx0, const int fy0,
                                  const uint seed, const int frame, const float kr,
                                  const float kg, const float kb, const float read_e,
                                  const float prnu, const float well, const float chroma,
                                  const float inv_cell)
{
  const int x = get_global_id(0), y = get_global_id(1);
  if(x >= pitch || y >= height) return;
  const size_t i = ((size_t)y * pitch + x) * 4;
  if(x >= width)                                       /* row padding */
  {
    vstore4((float4)0.0f, 0, dst + i);
    return;
  }
  const float4 raw = vload4(0, src + i);
  const float4 v = clamp(clfx_finite4_or_zero(raw), -1e38f, 1e38f);
  const float alpha = clfx_finite_or(raw.w, 0.0f);      /* bit for bit where finite */
  /* linear units per electron, the full well and the model's deviation per channel */
  const float4 g = (float4)(1.0f / kr, 1.0f / kg, 1.0f / kb, 0.0f);
  const float4 vsat = well * g;
  const float4 sd = sn_sigma4(v, g, vsat, read_e, prnu);
  float4 d;
#if DEMOSAIC
  const int fx = fx0 + x, fy = fy0 + y, c = sn_cfa(fx, fy);
  float s0, ax, ay, bx, by, dg;
  if(x >= 2 && y >= 2 && x < width - 2 && y < height - 2)
  {
    /* interior: the 5 x 5 neighbourhood read directly */
    global const float *m = noisy + (size_t)y * pitch + x;
    const size_t r = (size_t)pitch;
    s0 = m[0];
    ax = m[-1] + m[1];
    ay = m[-(long)r] + m[r];
    bx = m[-2] + m[2];
    by = m[-2 * (long)r] + m[2 * r];
    dg = m[-(long)r - 1] + m[-(long)r + 1] + m[r - 1] + m[r + 1];
  }
  else
  {
#define S(dx, dy) sn_site(noisy, x + (dx), y + (dy), pitch, width, height)
    s0 = S(0, 0);
    ax = S(-1, 0) + S(1, 0); ay = S(0, -1) + S(0, 1);                /* axis neighbours */
    bx = S(-2, 0) + S(2, 0); by = S(0, -2) + S(0, 2);                /* two away */
    dg = S(-1, -1) + S(1, -1) + S(-1, 1) + S(1, 1);                  /* diagonals */
#undef S
  }
  /* Malvar-He-Cutler on the unit field of site deviations, each interpolated colour
   * divided by its filter's norm (the deviation it gives unit white noise: sqrt(63.5) / 8,
   * 6 / 8, sqrt(61) / 8), so every colour of every pixel has unit variance (no period-2
   * lattice of noise amplitude), then scaled by the pixel's own deviation for that colour:
   * a dark pixel beside a light, or the green of a saturated red, gets its own noise, not
   * its neighbours' (MHC's Laplacian term would carry a red site's noise into its green) */
  if(c == 1)
  {
    /* green site: the horizontal neighbours are R in an R row (even Y), B in a B row */
    const float hor = (5.0f * s0 + 4.0f * ax - bx - dg + 0.5f * by) * SN_NORM_HV;
    const float ver = (5.0f * s0 + 4.0f * ay - by - dg + 0.5f * bx) * SN_NORM_HV;
    const int rrow = (fy & 1) == 0;
    d = (float4)(rrow ? hor : ver, s0, rrow ? ver : hor, 0.0f);
  }
  else
  {
    const float gi = (4.0f * s0 + 2.0f * (ax + ay) - (bx + by)) * SN_NORM_G;
    const float o = (6.0f * s0 + 2.0f * dg - 1.5f * (bx + by)) * SN_NORM_O;  /* the other colour */
    d = c == 0 ? (float4)(s0, gi, o, 0.0f) : (float4)(o, gi, s0, 0.0f);
  }
  d *= sd;
#else
  d = vload4(0, noisy + i) - v;                        /* each pixel's own deviations */
#endif
  float4 out = v + (float4)(d.x, d.y, d.z, 0.0f);
#if CHROMA
  {
    const float px = (float)(fx0 + x) * inv_cell, py = (float)(fy0 + y) * inv_cell;
    const float a = sn_value_noise(seed, frame, px, py, 12);
    const float b = sn_value_noise(seed, frame, px, py, 14);
    const float dr = chroma * sd.y * a, db = chroma * sd.y * b;
    out += (float4)(dr, -((CLFX_LUMA_R) * dr + (CLFX_LUMA_B) * db) / (CLFX_LUMA_G), db, 0.0f);
  }
#endif
#if COVERAGE
  out = clfx_cover4(v, out, alpha);                    /* transparent pixels stay empty */
#endif
  out = clamp(out, -FLT_MAX, FLT_MAX);
  out.w = alpha;
  vstore4(out, 0, dst + i);
}
