/* sensor_noise.cl: photon shot noise, read noise and fixed-pattern PRNU in linear light
 * (clfx/plugins/sensor_noise.py has the model).
 *
 * One work-item handles 4 pixels x 4 channels as 16 lanes (rows are padded to 4 pixels);
 * the alpha lanes get zero electrons per unit and are copied bit for bit at the end.
 * Random numbers: clfx_uniform(seed, frame, X, Y, c) of common.h for frame coordinates
 * X = fx0 + x, Y = fy0 + y, with streams c = 0..3 and 4..7 (Box-Muller pair: shot and read
 * Gaussians) and 8..11 (the uniform of the Poisson inversion).  PRNU uses its own seed and
 * frame 0, so the pattern is the same on every frame.
 *
 * Defines: SHOT, READ, PRNU (0/1) drop unused terms at compile time; INVERT=1 samples the
 * Poisson count exactly by inversion when lambda <= SWITCH electrons (bounded loop of
 * MAX_COUNT steps; u capped at 1 - 4e-6), else the normal approximation
 * lambda + sqrt(lambda) z.  USE_DOUBLE=1 (reference) does all arithmetic in double.
 */
#include "common.h"

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
#ifndef USE_DOUBLE
#define USE_DOUBLE 0
#endif
#define U_CAP 4e-6

#if USE_DOUBLE
#define REAL double
#define REAL16 double16
#define MASK16 long16
#define TO_REAL16 convert_double16
#define SN_LOG(x) log(x)
#define SN_EXP(x) exp(x)
#define SN_SINCOS2PI(u, c) sincos((REAL)SN_TWO_PI * (u), (c))
#define SN_COS2PI(u) cos((REAL)SN_TWO_PI * (u))
#else
#define REAL float
#define REAL16 float16
#define MASK16 int16
#define TO_REAL16 convert_float16
#define SN_LOG(x) clfx_log16(x)
#define SN_EXP(x) clfx_exp2_16((x) * 1.44269504f)
#define SN_SINCOS2PI(u, c) clfx_sincos2pi16((u), (c))
#define SN_COS2PI(u) sensor_noise_cos2pi16(u)
#endif

#define SN_TWO_PI 6.283185307179586

#include "fastmath.h"
CLFX_DEFINE_FASTMATH(16)
inline float16 sensor_noise_cos2pi16(const float16 u)
{
  float16 c;
  clfx_sincos2pi16(u, &c);
  return c;
}

/* clfx_uniform(seed, frame, x + i, y, c0 + c), lane 4 i + c, in REAL precision. */
inline REAL16 sensor_noise_uniform16(uint seed, int frame, int x, int y, int c0)
{
  return TO_REAL16(clfx_uniform16(seed, frame, x, y, c0));
}

kernel void sensor_noise_apply(global const float *src, global float *dst, const int pitch,
                               const int height, const int fx0, const int fy0,
                               const uint seed, const uint prnu_seed, const int frame,
                               const float kr, const float kg, const float kb,
                               const float read_e, const float prnu)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= height || qx * 4 >= pitch) return;
  const int x = qx * 4, fx = fx0 + x, fy = fy0 + y;
  const size_t i = (size_t)(y * pitch + x) * 4;
  const float16 c = vload16(0, src + i);
  const int16 finite = (as_uint16(c) & 0x7f800000u) != (uint16)0x7f800000u;
  /* non-finite -> 0; |v| <= 1e38 so the PRNU gain (<= 1.6) cannot overflow float */
  REAL16 v = TO_REAL16(clamp(select((float16)0.0f, c, finite), -1e38f, 1e38f));

  /* electrons per unit of linear value (k) and linear value per electron (g); alpha: 0 */
  const REAL zero = (REAL)0;
  const REAL16 k16 = (REAL16)(kr, kg, kb, zero, kr, kg, kb, zero,
                              kr, kg, kb, zero, kr, kg, kb, zero);
  const REAL16 g16 = select((REAL16)zero, (REAL)1 / k16, k16 > zero);

#if PRNU
  {
    /* photo-response non-uniformity: a fixed per-pixel, per-channel gain 1 + prnu z */
    const REAL16 fa = sensor_noise_uniform16(prnu_seed, 0, fx, fy, 0);
    const REAL16 fb = sensor_noise_uniform16(prnu_seed, 0, fx, fy, 4);
    v *= (REAL)1 + (REAL)prnu * sqrt((REAL)(-2) * SN_LOG(fa)) * SN_COS2PI(fb);
  }
#endif

  REAL16 out = v;
#if SHOT || READ
  const REAL16 ua = sensor_noise_uniform16(seed, frame, fx, fy, 0);
  const REAL16 ub = sensor_noise_uniform16(seed, frame, fx, fy, 4);
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
    if(any(small))
    {
      /* exact inversion of the Poisson CDF: the smallest n with u <= F(n).  u is capped at
       * 1 - U_CAP so rounding in the summed CDF (measured <= 2e-7 for lambda <= 30) can never
       * leave F below u: the top U_CAP quantile maps to its lower edge. */
      const REAL16 u = min(sensor_noise_uniform16(seed, frame, fx, fy, 8), (REAL)1 - (REAL)U_CAP);
      const REAL16 ls = select((REAL16)zero, lam, small);
      REAL16 p = SN_EXP(-ls), cdf = p, n = (REAL16)zero;
      MASK16 active = small & (u > cdf);
      /* Lanes stay active from the first step on, so every active lane holds n = it: one
       * scalar reciprocal per step instead of a division per lane.  p and cdf run on in
       * finished lanes too (unused there): only n must be frozen.  Two steps per loop test. */
      for(int it = 1; it < MAX_COUNT && any(active); it += 2)
      {
        p = p * ls * ((REAL)1 / (REAL)it);
        cdf += p;
        n = select(n, (REAL16)((REAL)it), active);
        active = active & (u > cdf);
        p = p * ls * ((REAL)1 / (REAL)(it + 1));
        cdf += p;
        n = select(n, (REAL16)((REAL)(it + 1)), active);
        active = active & (u > cdf);
      }
      dev = select(dev, (n - ls) * g16, small);
    }
#endif
    out += dev;
  }
#endif

#if READ
  out += (REAL)read_e * g16 * r * si;                  /* Gaussian read noise, electrons */
#endif

  const int16 alpha = (int16)(0, 0, 0, -1, 0, 0, 0, -1, 0, 0, 0, -1, 0, 0, 0, -1);
  vstore16(select(convert_float16(out), c, alpha), 0, dst + i);
}
