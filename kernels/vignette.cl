/* vignette.cl: natural cos^4 falloff times an artistic radial falloff (clfx/plugins/vignette.py).
 *
 * Each work-item shades 4 consecutive pixels (one float16: rows are padded to 4 pixels), so
 * PoCL runs the arithmetic as vectors; the cost is one read and one write of the frame.
 * Coordinates: pixel (x, y) of the window has its centre at (x0 + x + 0.5, y0 + y + 0.5) in
 * the frame; (cx, cy) is the optical centre.  sx, sy convert pixels to millimetres on the
 * sensor (sy = sx / pixel_aspect), so tan(theta) = |r_mm| / focal_mm.  Non-finite values
 * (colour or alpha) become 0, so the factor never multiplies a NaN or Inf (the plugin notes
 * how many pixels had one).  The reference level evaluates the factor in double
 * (kernels/lib/precision.h).
 */
#include "lib/common.h"
#include "lib/precision.h"

kernel void vignette_apply(global const float *src, global float *dst, const int pitch,
                           const int height, const int x0, const int y0,
                           const float cx, const float cy, const float sx, const float sy,
                           const float inv_focal_mm, const float natural,
                           const float ax, const float ay, const float amount,
                           const float radius, const float inv_softness)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= height || qx * 4 >= pitch) return;
  const int i = y * pitch + qx * 4;
  const float16 c = clfx_finite16_or_zero(vload16(0, src + i * 4));
  const REAL4 px = (REAL4)((REAL)(x0 + qx * 4) + (REAL)0.5) + (REAL4)(0, 1, 2, 3) - (REAL)cx;
  const REAL py = (REAL)(y0 + y) + (REAL)0.5 - (REAL)cy;

  /* natural: cos^4(theta) = 1 / (1 + tan^2)^2 */
  const REAL4 tx = px * (REAL)(sx * inv_focal_mm);
  const REAL ty = py * (REAL)(sy * inv_focal_mm);
  const REAL4 t2 = tx * tx + ty * ty;
  const REAL4 cos4 = (REAL)1 / ((1 + t2) * (1 + t2));
  const REAL4 nat = (REAL)1 - (REAL)natural * ((REAL)1 - cos4);

  /* artistic: smoothstep falloff of the (aspect-blended) normalised radius */
  const REAL4 u = px * (REAL)ax;
  const REAL v = py * (REAL)ay;
  const REAL4 r = sqrt(u * u + v * v);
  const REAL4 t = clamp((r - (REAL)radius) * (REAL)inv_softness, (REAL)0, (REAL)1);
  const REAL4 art = (REAL)1 - (REAL)amount * t * t * ((REAL)3 - (REAL)2 * t);

  const float4 g = TO_FLOAT4(clamp(nat * art, (REAL)0, (REAL)1));
  const float16 o = (float16)(c.s0 * g.x, c.s1 * g.x, c.s2 * g.x, c.s3,
                              c.s4 * g.y, c.s5 * g.y, c.s6 * g.y, c.s7,
                              c.s8 * g.z, c.s9 * g.z, c.sa * g.z, c.sb,
                              c.sc * g.w, c.sd * g.w, c.se * g.w, c.sf);
  vstore16(o, 0, dst + i * 4);
}
