/* analysis.cl: one cheap pass per frame, shared by every effect (clfx/analysis.py).
 *
 * One work-item per TILE x TILE tile.  Per tile it records, over finite values only:
 *   stats[t*8 + 0] max luminance      1 mean luminance     2 count of non-finite RGBA pixels
 *   3 max |velocity| (px/frame)       4 min valid depth    5 max valid depth (inf allowed)
 *   6 count of pixels with depth <= 0 or NaN               7 max alpha
 * Depth and velocity images share the source's window (the host checks).
 */
#include "common.h"

kernel void analysis_tiles(global const float *src, const int pitch, const int width,
                           const int height, global const float *depth,
                           global const float *velocity, const int has_depth,
                           const int has_velocity, global float *stats, const int tiles_x)
{
  const int tx = get_global_id(0), ty = get_global_id(1);
  const int x0 = tx * TILE, y0 = ty * TILE;
  if(x0 >= width || y0 >= height) return;
  const int x1 = min(x0 + TILE, width), y1 = min(y0 + TILE, height);
  float max_lum = 0.0f, sum_lum = 0.0f, bad = 0.0f, max_speed = 0.0f, max_alpha = 0.0f;
  float zmin = INFINITY, zmax = 0.0f, zbad = 0.0f;
  for(int y = y0; y < y1; y++)
  {
    for(int x = x0; x < x1; x++)
    {
      const float4 c = clfx_load4(src, pitch, x, y);
      const int ok = clfx_is_finite(c.x) & clfx_is_finite(c.y) & clfx_is_finite(c.z) & clfx_is_finite(c.w);
      if(!ok) { bad += 1.0f; continue; }
      const float l = clfx_luminance(c);
      max_lum = fmax(max_lum, l);
      sum_lum += l;
      max_alpha = fmax(max_alpha, c.w);
      if(has_velocity)
      {
        const float2 v = vload2(y * pitch + x, velocity);
        if(clfx_is_finite(v.x) && clfx_is_finite(v.y)) max_speed = fmax(max_speed, hypot(v.x, v.y));
      }
      if(has_depth)
      {
        const float z = depth[y * pitch + x];
        if(z > 0.0f) { zmin = fmin(zmin, z); zmax = fmax(zmax, z); }  /* NaN fails z > 0 */
        else zbad += 1.0f;
      }
    }
  }
  const int n = (x1 - x0) * (y1 - y0);
  global float *s = stats + (ty * tiles_x + tx) * 8;
  s[0] = max_lum; s[1] = sum_lum / (float)n; s[2] = bad; s[3] = max_speed;
  s[4] = zmin; s[5] = zmax; s[6] = zbad; s[7] = max_alpha;
}
