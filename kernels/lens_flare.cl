/* lens_flare.cl: aperture-shaped ghosts and a halo, gathered per pixel
 * (clfx/plugins/lens_flare.py).
 *
 * lens_flare_measure  one work-item per light source: sums the highlight (RGB * max(lum - t,
 *                     0) / lum) over the source's bounding box and its luminance-weighted
 *                     centroid, serially in REAL (lib/precision.h; the host builds it with
 *                     float64 where the device has it), deterministic; a flux beyond the
 *                     float range saturates at FLT_MAX.
 * lens_flare_render   each work-item shades 4 pixels of a row (float4 lanes); it loops over
 *                     the entries (ghosts and halos) listed for its TILE x TILE tile, so the
 *                     cost is pixels x overlapping entries, and the sum order is fixed: no
 *                     atomics, identical bytes on every run.
 * Entry layout (ENTRY floats): x, y (frame px, centre), radius px, 1/edge width (in units
 * of the normalised radius), R, G, B radiance, kind (0 ghost, 1 halo), dir x, dir y, 0, 0.
 */
#include "lib/scatter.h"
#include "lib/precision.h"

#define ENTRY 12
#ifndef TILE
#define TILE 32
#endif
#ifndef BLADES
#define BLADES 0
#endif

/* scatter_bright's highlight, with the centroid weight max(lum - t, 0) in alpha. */
inline float4 lens_flare_highlight(float4 c, float threshold)
{
  const float l = clfx_luminance(fmax(clfx_finite4_or_zero(c), (float4)0.0f));
  const float4 h = scatter_bright(c, threshold);
  return (float4)(h.xyz, l > threshold ? fmin(l - threshold, SCATTER_FLT_MAX) : 0.0f);
}

inline float lens_flare_saturate(REAL v)
{
  return TO_FLOAT(fmin(v, (REAL)SCATTER_FLT_MAX));
}

/* boxes: per source x0, y0, x1, y1 in source-window pixels.  out: per source 8 floats:
 * flux R, G, B, weight, weighted x, weighted y (window pixel centres), count, 0. */
kernel void lens_flare_measure(global const float *src, const int pitch,
                               global const int *boxes, const int count,
                               const float threshold, global float *out)
{
  const int i = get_global_id(0);
  if(i >= count) return;
  const int x0 = boxes[4 * i], y0 = boxes[4 * i + 1], x1 = boxes[4 * i + 2], y1 = boxes[4 * i + 3];
  REAL r = 0, g = 0, b = 0, w = 0, wx = 0, wy = 0, n = 0;
  for(int y = y0; y < y1; y++)
    for(int x = x0; x < x1; x++)
    {
      const float4 h = lens_flare_highlight(clfx_load4(src, pitch, x, y), threshold);
      if(h.w <= 0.0f) continue;
      r += h.x; g += h.y; b += h.z; w += h.w;
      wx += (REAL)h.w * ((REAL)x + 0.5); wy += (REAL)h.w * ((REAL)y + 0.5); n += 1;
    }
  global float *o = out + 8 * i;
  o[0] = lens_flare_saturate(r); o[1] = lens_flare_saturate(g); o[2] = lens_flare_saturate(b);
  o[3] = lens_flare_saturate(w);
  o[4] = (float)(w > 0 ? wx / w : 0); o[5] = (float)(w > 0 ? wy / w : 0); o[6] = (float)n;
  if(!(clfx_is_finite(o[4]) & clfx_is_finite(o[5])))  /* float sums overflowed: box centre */
  {
    o[4] = 0.5f * (float)(x0 + x1); o[5] = 0.5f * (float)(y0 + y1);
  }
  o[7] = 0.0f;
}

/* Normalised distance of 4 pixels to a ghost centre: 1 on the shape's edge.  The polygon
 * distance is the largest projection on the edge normals over the apothem; roundness mixes
 * it with the circle's. */
inline float4 lens_flare_rho(float4 dx, float dy, float radius, global const float *normals,
                             float roundness)
{
  const float4 circle = sqrt(dx * dx + dy * dy) / radius;
#if BLADES >= 3
  float4 poly = (float4)(-INFINITY);
  for(int i = 0; i < BLADES; i++)
    poly = fmax(poly, dx * normals[2 * i] + dy * normals[2 * i + 1]);
  poly /= radius * cos(CLFX_PI / BLADES);
  return poly + (circle - poly) * roundness;
#else
  return circle;
#endif
}

kernel void lens_flare_render(global const float *src, const int src_pitch, const int src_w,
                              const int src_h, const int ox, const int oy,
                              global float *dst, const int pitch, const int width,
                              const int height, const int win_x0, const int win_y0,
                              const int tiles_x, global const int *tile_start,
                              global const int *tile_entries, global const float *entries,
                              global const float *normals, const float roundness,
                              const float rim)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(qx * 4 >= pitch || y >= height) return;
  const int x = qx * 4;
  const int tile = (y / TILE) * tiles_x + x / TILE;
  /* frame coordinates of the 4 pixel centres */
  const float4 fx = (float4)((float)(win_x0 + x) + 0.5f) + (float4)(0.0f, 1.0f, 2.0f, 3.0f);
  const float fy = (float)(win_y0 + y) + 0.5f;
  float4 r = (float4)0.0f, g = (float4)0.0f, b = (float4)0.0f;
  for(int t = tile_start[tile]; t < tile_start[tile + 1]; t++)
  {
    global const float *e = entries + ENTRY * tile_entries[t];
    const float4 dx = fx - e[0];
    const float dy = fy - e[1];
    float4 wgt;
    if(e[7] == 0.0f)
    {
      /* ghost: 1 inside, smoothstep to 0 across the edge width */
      const float4 rho = lens_flare_rho(dx, dy, e[2], normals, roundness);
      const float4 s = clamp((1.0f - rho) * e[3], 0.0f, 1.0f);
      wgt = s * s * (3.0f - 2.0f * s) * ((1.0f - rim) + rim * rho * rho);
    }
    else
    {
      /* halo: Gaussian ring of radius e[2], 1/sigma e[3], brightest towards the light */
      const float4 d = sqrt(dx * dx + dy * dy);
      const float4 z = (d - e[2]) * e[3];
      const float4 facing = (dx * e[8] + dy * e[9]) / fmax(d, 1e-6f);
      const float4 m = 0.5f + 0.5f * facing;
      wgt = exp(-0.5f * z * z) * m * m;
    }
    r += wgt * e[4]; g += wgt * e[5]; b += wgt * e[6];
  }
  float rr[4] = {r.x, r.y, r.z, r.w}, gg[4] = {g.x, g.y, g.z, g.w}, bb[4] = {b.x, b.y, b.z, b.w};
  for(int j = 0; j < 4; j++)
  {
    const int xx = x + j;
    const float4 c = scatter_source(src, src_pitch, src_w, src_h, xx - ox, y - oy);
    const float4 o = xx < width ? scatter_add(c, (float4)(rr[j], gg[j], bb[j], 0.0f))
                                : (float4)0.0f;
    clfx_store4(dst, pitch, xx, y, o);
  }
}
