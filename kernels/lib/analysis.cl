/* analysis.cl: one cheap pass per frame, shared by every effect (clfx/analysis.py).
 *
 * Per TILE x TILE tile it records, over finite values only:
 *   stats[t*8 + 0] max luminance      1 mean luminance (a non-finite channel counts as 0,
 *     as effects read it: the metered middle grey of a frame with a NaN in one channel is
 *     that of the frame with a 0 there)                     2 count of non-finite RGBA pixels
 *   3 max |velocity| (px/frame)       4 min valid depth    5 max valid depth (inf allowed)
 *   6 count of pixels with depth <= 0 or NaN               7 max alpha
 *   8 count of finite pixels with light but no alpha (alpha <= 0, some RGB != 0): a frame
 *     without any has premultiplied, empty transparent areas (alpha reads as coverage)
 * Two stages so PoCL runs vector code: analysis_rows has one work-item per (tile column,
 * image row) that walks the tile's 32-pixel row segment 4 pixels (one float16) at a time;
 * analysis_tiles reduces each tile's rows.  Depth and velocity share the source's window.
 * Rows are padded to 4 pixels; padding pixels (x >= width) are masked out.
 */
#include "lib/common.h"

#define LANES 4
#define STATS 9

/* per-pixel "all four channels finite" of 4 RGBA pixels */
inline int4 analysis_finite4(float16 c)
{
  const int16 e = (as_int16(c) & 0x7f800000) != 0x7f800000;  /* -1 where finite */
  return (int4)(e.s0 & e.s1 & e.s2 & e.s3, e.s4 & e.s5 & e.s6 & e.s7,
                e.s8 & e.s9 & e.sa & e.sb, e.sc & e.sd & e.se & e.sf);
}

kernel void analysis_rows(global const float *src, const int pitch, const int width,
                          const int height, global const float *depth,
                          global const float *velocity, const int has_depth,
                          const int has_velocity, global float *rows, const int tiles_x)
{
  const int tx = get_global_id(0), y = get_global_id(1);
  if(tx >= tiles_x || y >= height) return;
  const int x0 = tx * TILE, x1 = min(x0 + TILE, width);
  float4 max_lum = 0.0f, sum_lum = 0.0f, bad = 0.0f, max_speed2 = 0.0f, max_alpha = 0.0f;
  float4 zmin = INFINITY, zmax = 0.0f, zbad = 0.0f, stray = 0.0f;
  for(int x = x0; x < x1; x += LANES)
  {
    const int4 inside = (int4)(x, x + 1, x + 2, x + 3) < (int4)(x1);
    const float16 c = vload16(0, src + (y * pitch + x) * 4);
    const int4 ok = analysis_finite4(c) & inside;
    const float4 l = (CLFX_LUMA_R) * c.s048c + (CLFX_LUMA_G) * c.s159d + (CLFX_LUMA_B) * c.s26ae;
    max_lum = select(max_lum, fmax(max_lum, l), ok);
    const float16 cz = clfx_finite16_or_zero(c);                            /* NaN, Inf -> 0 */
    const float4 lz = (CLFX_LUMA_R) * cz.s048c + (CLFX_LUMA_G) * cz.s159d
                      + (CLFX_LUMA_B) * cz.s26ae;
    sum_lum += select((float4)0.0f, lz, inside);
    max_alpha = select(max_alpha, fmax(max_alpha, c.s37bf), ok);
    bad += select((float4)0.0f, (float4)1.0f, inside & ~ok);
    const int4 lit = (c.s048c != 0.0f) | (c.s159d != 0.0f) | (c.s26ae != 0.0f);
    stray += select((float4)0.0f, (float4)1.0f, ok & lit & (c.s37bf <= 0.0f));
    if(has_velocity)
    {
      const float8 v = vload8(0, velocity + (y * pitch + x) * 2);
      const float4 s2 = v.even * v.even + v.odd * v.odd;
      const int4 vok = inside & ((as_int4(s2) & 0x7f800000) != 0x7f800000);
      max_speed2 = select(max_speed2, fmax(max_speed2, s2), vok);
    }
    if(has_depth)
    {
      const float4 z = vload4(0, depth + y * pitch + x);
      const int4 zok = inside & (z > 0.0f);  /* NaN fails z > 0 */
      zmin = select(zmin, fmin(zmin, z), zok);
      zmax = select(zmax, fmax(zmax, z), zok);
      zbad += select((float4)0.0f, (float4)1.0f, inside & ~zok);
    }
  }
  global float *r = rows + (y * tiles_x + tx) * STATS;
  r[0] = fmax(fmax(max_lum.x, max_lum.y), fmax(max_lum.z, max_lum.w));
  r[1] = (sum_lum.x + sum_lum.y) + (sum_lum.z + sum_lum.w);
  r[2] = (bad.x + bad.y) + (bad.z + bad.w);
  r[3] = sqrt(fmax(fmax(max_speed2.x, max_speed2.y), fmax(max_speed2.z, max_speed2.w)));
  r[4] = fmin(fmin(zmin.x, zmin.y), fmin(zmin.z, zmin.w));
  r[5] = fmax(fmax(zmax.x, zmax.y), fmax(zmax.z, zmax.w));
  r[6] = (zbad.x + zbad.y) + (zbad.z + zbad.w);
  r[7] = fmax(fmax(max_alpha.x, max_alpha.y), fmax(max_alpha.z, max_alpha.w));
  r[8] = (stray.x + stray.y) + (stray.z + stray.w);
}

kernel void analysis_tiles(global const float *rows, const int width, const int height,
                           global float *stats, const int tiles_x, const int tiles_y)
{
  const int tx = get_global_id(0), ty = get_global_id(1);
  if(tx >= tiles_x || ty >= tiles_y) return;
  const int y0 = ty * TILE, y1 = min(y0 + TILE, height);
  float s[STATS] = {0.0f, 0.0f, 0.0f, 0.0f, INFINITY, 0.0f, 0.0f, 0.0f, 0.0f};
  for(int y = y0; y < y1; y++)
  {
    global const float *r = rows + (y * tiles_x + tx) * STATS;
    s[0] = fmax(s[0], r[0]); s[1] += r[1]; s[2] += r[2]; s[3] = fmax(s[3], r[3]);
    s[4] = fmin(s[4], r[4]); s[5] = fmax(s[5], r[5]); s[6] += r[6]; s[7] = fmax(s[7], r[7]);
    s[8] += r[8];
  }
  const int n = (min(tx * TILE + TILE, width) - tx * TILE) * (y1 - y0);
  s[1] /= (float)max(n, 1);
  global float *o = stats + (ty * tiles_x + tx) * STATS;
  for(int i = 0; i < STATS; i++) o[i] = s[i];
}
