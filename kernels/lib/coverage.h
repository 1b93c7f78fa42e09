/* coverage.h: alpha as coverage for the noise effects (grain, sensor_noise; the host side is
 * clfx/kit/noise.py, alpha_is_coverage).
 *
 * A CG element with an empty, alpha-0 background must not get noise over its whole data
 * window (a rectangle around the element, added on top of the plate's own noise in the
 * comp): the deviation is weighted by alpha clamped to [0, 1], out = v + alpha (noisy - v).
 * Pixels with alpha >= 1 keep the noisy value bit for bit (an opaque frame renders exactly as
 * with coverage ignored).  alpha must be finite (the callers zero non-finite values first).
 * Needs precision.h (REAL).
 */
#ifndef CLFX_COVERAGE_H
#define CLFX_COVERAGE_H

#include "precision.h"

/* 4 RGBA pixels: clean and noisy values in REAL, c the (finite) source whose alpha lanes
 * (3, 7, 11, 15) weight each pixel's colour lanes; alpha lanes come back as noisy's. */
inline REAL16 clfx_cover16(const REAL16 clean, const REAL16 noisy, const float16 c)
{
  const REAL16 cov = TO_REAL16(clamp((float16)(c.s3333, c.s7777, c.sbbbb, c.sffff),
                                     0.0f, 1.0f));
  return select(clean + cov * (noisy - clean), noisy, cov >= (REAL)1);
}

/* One pixel, float. */
inline float4 clfx_cover4(const float4 clean, const float4 noisy, const float alpha)
{
  const float cov = clamp(alpha, 0.0f, 1.0f);
  return cov < 1.0f ? clean + cov * (noisy - clean) : noisy;
}

#endif
