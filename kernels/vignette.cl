/* vignette.cl: natural cos^4 falloff times an artistic radial falloff (clfx/plugins/vignette.py).
 *
 * Each work-item shades 8 consecutive pixels (two float16s: rows are padded to 4 pixels), so
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

/* The gains of 8 pixels (one REAL8 per quantity: the float levels' arithmetic on 8 lanes,
 * half the instructions of 4 pixels twice): the gains q of a quad's 4 pixels applied to c. */
inline float16 vignette_quad(const float16 c, const float4 q)
{
  return (float16)(c.s0 * q.x, c.s1 * q.x, c.s2 * q.x, c.s3, c.s4 * q.y, c.s5 * q.y, c.s6 * q.y,
                   c.s7, c.s8 * q.z, c.s9 * q.z, c.sa * q.z, c.sb, c.sc * q.w, c.sd * q.w,
                   c.se * q.w, c.sf);
}

/* 8 pixels per work-item (two quads; the second is skipped past a row of pitch % 8 == 4):
 * 1080p 12.9 -> 11.3 ms of CPU, the same pixels */
kernel void vignette_apply(global const float *src, global float *dst, const int pitch,
                           const int height, const int x0, const int y0,
                           const float cx, const float cy, const float sx, const float sy,
                           const float inv_focal_mm, const float natural,
                           const float ax, const float ay, const float amount,
                           const float radius, const float inv_softness)
{
  const int ox = get_global_id(0), y = get_global_id(1);
  if(y >= height || ox * 8 >= pitch) return;
  const int i = y * pitch + ox * 8;
  const REAL8 px = (REAL8)((REAL)(x0 + ox * 8) + (REAL)0.5) + (REAL8)(0, 1, 2, 3, 4, 5, 6, 7)
                   - (REAL)cx;
  const REAL py = (REAL)(y0 + y) + (REAL)0.5 - (REAL)cy;

  /* natural: cos^4(theta) = 1 / (1 + tan^2)^2 */
  const REAL8 tx = px * (REAL)(sx * inv_focal_mm);
  const REAL ty = py * (REAL)(sy * inv_focal_mm);
  const REAL8 t2 = tx * tx + ty * ty;
  const REAL8 cos4 = (REAL)1 / ((1 + t2) * (1 + t2));
  const REAL8 nat = (REAL)1 - (REAL)natural * ((REAL)1 - cos4);

  /* artistic: smoothstep falloff of the (aspect-blended) normalised radius */
  const REAL8 u = px * (REAL)ax;
  const REAL v = py * (REAL)ay;
  const REAL8 r = sqrt(u * u + v * v);
  const REAL8 t = clamp((r - (REAL)radius) * (REAL)inv_softness, (REAL)0, (REAL)1);
  const REAL8 art = (REAL)1 - (REAL)amount * t * t * ((REAL)3 - (REAL)2 * t);

  const float8 g = TO_FLOAT8(clamp(nat * art, (REAL)0, (REAL)1));
  vstore16(vignette_quad(clfx_finite16_or_zero(vload16(0, src + i * 4)), g.lo), 0,
           dst + i * 4);
  if(ox * 8 + 4 < pitch)
    vstore16(vignette_quad(clfx_finite16_or_zero(vload16(1, src + i * 4)), g.hi), 1,
             dst + i * 4);
}
