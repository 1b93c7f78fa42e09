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
 * of the normalised radius), R, G, B radiance, kind (0 ghost, 1 halo), dir x, dir y (halo),
 * rim (ghost: 1 - rim + rim rho^2), 0.
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
#ifndef FULL
#define FULL 0
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

/* The whole light of a pixel above threshold (the physical model's flux: every pixel of the
 * light makes ghosts), with its luminance as the centroid weight in alpha. */
inline float4 lens_flare_light(float4 c, float threshold)
{
  c = fmax(clfx_finite4_or_zero(c), (float4)0.0f);
  const float l = clfx_luminance(c);
  return l > threshold ? (float4)(c.xyz, fmin(l, SCATTER_FLT_MAX)) : (float4)0.0f;
}

/* boxes: per source x0, y0, x1, y1 in source-window pixels.  out: per source 8 floats:
 * flux R, G, B, weight, weighted x, weighted y (window pixel centres), count, rms radius of
 * the weight about the centroid (px).  FULL = 0: the highlight above threshold, weighted by
 * max(lum - t, 0) (artistic); FULL = 1: the whole pixel, weighted by its luminance. */
kernel void lens_flare_measure(global const float *src, const int pitch,
                               global const int *boxes, const int count,
                               const float threshold, global float *out)
{
  const int i = get_global_id(0);
  if(i >= count) return;
  const int x0 = boxes[4 * i], y0 = boxes[4 * i + 1], x1 = boxes[4 * i + 2], y1 = boxes[4 * i + 3];
  REAL r = 0, g = 0, b = 0, w = 0, wx = 0, wy = 0, wxx = 0, n = 0;
  for(int y = y0; y < y1; y++)
    for(int x = x0; x < x1; x++)
    {
#if FULL
      const float4 h = lens_flare_light(clfx_load4(src, pitch, x, y), threshold);
#else
      const float4 h = lens_flare_highlight(clfx_load4(src, pitch, x, y), threshold);
#endif
      if(h.w <= 0.0f) continue;
      r += h.x; g += h.y; b += h.z; w += h.w;
      const REAL px = (REAL)x + 0.5, py = (REAL)y + 0.5;
      wx += (REAL)h.w * px; wy += (REAL)h.w * py; n += 1;
#if FULL
      wxx += (REAL)h.w * (px * px + py * py);
#endif
    }
  global float *o = out + 8 * i;
  o[0] = lens_flare_saturate(r); o[1] = lens_flare_saturate(g); o[2] = lens_flare_saturate(b);
  o[3] = lens_flare_saturate(w);
  o[4] = (float)(w > 0 ? wx / w : 0); o[5] = (float)(w > 0 ? wy / w : 0); o[6] = (float)n;
  o[7] = 0.0f;
#if FULL
  if(w > 0)
  {
    const REAL mx = wx / w, my = wy / w;
    o[7] = (float)sqrt(fmax(wxx / w - mx * mx - my * my, (REAL)0));
  }
#endif
  if(!(clfx_is_finite(o[4]) & clfx_is_finite(o[5]) & clfx_is_finite(o[7])))
  {                                         /* float sums overflowed: the box's centre, size */
    o[4] = 0.5f * (float)(x0 + x1); o[5] = 0.5f * (float)(y0 + y1);
    o[7] = 0.5f * (float)(FULL ? max(x1 - x0, y1 - y0) : 0);
  }
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
      wgt = s * s * (3.0f - 2.0f * s) * ((1.0f - e[10]) + e[10] * rho * rho);
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


/* -- physically based ghosts (clfx/fx/flare.py) ----------------------------------------
 * lens_flare_ghosts  one resolution level of the ghost layer: each work-item shades 4
 * pixels of a row; it starts from its tile's constant (ghosts the tile lies deep inside),
 * adds every entry listed for the tile (ghosts whose edge crosses it) and the bilinear
 * upsample of the next coarser level; COMPOSE = 1 (level 0): adds the layer to the
 * sanitised source instead of storing it.  Entry (GHOST_ENTRY floats): x, y (frame px,
 * green centre), ux, uy (axis), dR, dG, dB (channel offsets along the axis), aR, aG, aB
 * (apothem or radius px), 1/sR, 1/sG, 1/sB (inverse edge scale), ER, EG, EB (radiance),
 * shape (0 disc, +-1 polygon upright / turned 180 degrees), edge-table row, inner clip
 * (offset along the axis, radius; 0 none), outer clip (offset, radius), 2 unused.
 */
#define GHOST_ENTRY 24
#ifndef EDGE_SAMPLES
#define EDGE_SAMPLES 129
#endif
#ifndef EDGE_REACH
#define EDGE_REACH 4.0f
#endif
#ifndef COMPOSE
#define COMPOSE 0
#endif

/* The edge profile G(row, t) of 4 pixels (linear interpolation; 1 / 0 beyond the ends). */
inline float4 lens_flare_edge(global const float *tab, int row, float4 t)
{
  const float4 x = clamp((t + EDGE_REACH) * ((EDGE_SAMPLES - 1) / (2.0f * EDGE_REACH)), 0.0f,
                         (float)(EDGE_SAMPLES - 1));
  const float4 fl = fmin(floor(x), (float)(EDGE_SAMPLES - 2));
  const float4 f = x - fl;
  const int4 i = convert_int4(fl) + row * EDGE_SAMPLES;
  const float4 a = (float4)(tab[i.x], tab[i.y], tab[i.z], tab[i.w]);
  const float4 b = (float4)(tab[i.x + 1], tab[i.y + 1], tab[i.z + 1], tab[i.w + 1]);
  return a + (b - a) * f;
}

/* Signed distance (px, > 0 outside) of 4 pixels to a disc at offset `off` along the axis. */
inline float4 lens_flare_disc(float4 dx, float dy, float ux, float uy, float off, float radius)
{
  const float4 ex = dx - off * ux;
  const float ey = dy - off * uy;
  return sqrt(ex * ex + ey * ey) - radius;
}

kernel void lens_flare_ghosts(global float *layer, const int pitch, const int width,
                              const int height, const float fx0, const float fy0,
                              const float factor, const int tiles_x,
                              global const int *tile_start, global const int *tile_items,
                              global const float *entries, global const float *constants,
                              global const float *normals, global const float *edge,
                              global const float *coarse, const int c_pitch, const int c_w,
                              const int c_h, const int has_coarse,
                              global const float *src, const int src_pitch, const int src_w,
                              const int src_h, const int ox, const int oy)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(qx * 4 >= pitch || y >= height) return;
  const int x = qx * 4;
  const int tile = (y / TILE) * tiles_x + min(x / TILE, tiles_x - 1);  /* padding: last tile */
  const float4 fx = (float4)fx0 + factor * ((float4)(float)x + (float4)(0.0f, 1.0f, 2.0f, 3.0f));
  const float fy = fy0 + factor * (float)y;
  const float4 k = vload4(tile, constants);
  float4 r = (float4)k.x, g = (float4)k.y, b = (float4)k.z;
  for(int t = tile_start[tile]; t < tile_start[tile + 1]; t++)
  {
    global const float *e = entries + GHOST_ENTRY * tile_items[t];
    const float4 dx = fx - e[0];
    const float dy = fy - e[1];
    const float ux = e[2], uy = e[3];
    float4 dr, dg, db;
#if BLADES >= 3
    if(e[16] != 0.0f)
    {
      /* polygon: the largest projection on the (possibly turned) edge normals; each channel's
       * polygon is shifted along the axis, moving the nearest face by d (n . u) */
      const float s = e[16];
      float4 pm = (float4)(-INFINITY), nu = (float4)0.0f;
      for(int i = 0; i < BLADES; i++)
      {
        const float nx = s * normals[2 * i], ny = s * normals[2 * i + 1];
        const float4 proj = dx * nx + dy * ny;
        nu = select(nu, (float4)(nx * ux + ny * uy), isgreater(proj, pm));
        pm = fmax(pm, proj);
      }
      dr = pm - e[4] * nu - e[7];
      dg = pm - e[5] * nu - e[8];
      db = pm - e[6] * nu - e[9];
    }
    else
#endif
    {
      dr = lens_flare_disc(dx, dy, ux, uy, e[4], e[7]);
      dg = lens_flare_disc(dx, dy, ux, uy, e[5], e[8]);
      db = lens_flare_disc(dx, dy, ux, uy, e[6], e[9]);
    }
    const int row = (int)e[17];
    float4 clip = (float4)1.0f;
    if(e[19] > 0.0f)
      clip = lens_flare_edge(edge, row, lens_flare_disc(dx, dy, ux, uy, e[18], e[19]) * e[11]);
    if(e[21] > 0.0f)
      clip *= lens_flare_edge(edge, row, lens_flare_disc(dx, dy, ux, uy, e[20], e[21]) * e[11]);
    r += e[13] * clip * lens_flare_edge(edge, row, dr * e[10]);
    g += e[14] * clip * lens_flare_edge(edge, row, dg * e[11]);
    b += e[15] * clip * lens_flare_edge(edge, row, db * e[12]);
  }
  float4 v[4] = {(float4)(r.x, g.x, b.x, 0.0f), (float4)(r.y, g.y, b.y, 0.0f),
                 (float4)(r.z, g.z, b.z, 0.0f), (float4)(r.w, g.w, b.w, 0.0f)};
  if(has_coarse)
  {
    /* + the coarser level, bilinear at half resolution with pixel centres aligned: output
     * pixel x = 4k + j samples coarse u = 2k - 1/4 + j/2, rows likewise; clamped edges */
    const int cx = x / 2;
    const int ra = (y & 1) ? y / 2 : y / 2 - 1;
    const float wb = (y & 1) ? 0.25f : 0.75f, wa = 1.0f - wb;
    float4 m[4];
    for(int i = 0; i < 4; i++)
      m[i] = wa * clfx_load4_clamped(coarse, c_pitch, c_w, c_h, cx - 1 + i, ra)
             + wb * clfx_load4_clamped(coarse, c_pitch, c_w, c_h, cx - 1 + i, ra + 1);
    v[0] += 0.25f * m[0] + 0.75f * m[1];
    v[1] += 0.75f * m[1] + 0.25f * m[2];
    v[2] += 0.25f * m[1] + 0.75f * m[2];
    v[3] += 0.75f * m[2] + 0.25f * m[3];
  }
  for(int j = 0; j < 4; j++)
  {
    const int xx = x + j;
#if COMPOSE
    const float4 c = scatter_source(src, src_pitch, src_w, src_h, xx - ox, y - oy);
    const float4 o = xx < width ? scatter_add(c, (float4)(v[j].xyz, 0.0f)) : (float4)0.0f;
#else
    const float4 o = xx < width ? fmin(v[j], SCATTER_FLT_MAX) : (float4)0.0f;
#endif
    clfx_store4(layer, pitch, xx, y, o);
  }
}
