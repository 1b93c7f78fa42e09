/* streaks.cl: star-filter streaks and aperture diffraction spikes (clfx/plugins/streaks.py).
 *
 * Working buffers (bright, ping, pong, total) are RGBA float32 with zero margins of MX
 * pixels left and right and MY above and below: interior pixel (x, y) lives at pixel index
 * (y + MY) * P + x + MX, where P = interior pitch (a multiple of 4) + 2 MX.  Kernels receive
 * the interior origin as `org` (= MY * P + MX).  When every tap fits in the margins
 * (CHECKED = 0) taps need no bounds test; otherwise (very long rays) MX = MY = 0 and each tap
 * checks the buffer's extent.  Margins and the
 * interior's padding columns stay zero: they stand for "outside the image".
 * Pipeline:
 *   streaks_seeds    each compact light's streaking light (thresholded, weighted by
 *                    (L / peak)^core_power) gathered into one point: its peak's window, at
 *                    the light's centroid (source pixels; a list), the peaks flagged
 *   streaks_dilate   the flags grown to the windows the seeds gathered (x, then y)
 *   streaks_extended (draft, preview) the streaking light no seed gathered, once a frame
 *   streaks_bright   the streaking light no seed gathered (extended lights), summed over
 *                    the FX x FY source pixels of a working pixel (EXTENDED = 1: from
 *                    streaks_extended's image), plus the points splatted
 *                    bilinearly (placed in the output window; the host bins the seeds)
 *   streaks_pass     one Kawase pass: out(x) = sum_{s=0..3} w_s * in(x + s * step), bilinear
 *                    taps, zero outside the buffer; ACCUM adds the result to `out`
 *   streaks_expand   (draft, preview) a ray-aligned working buffer upsampled along its rays
 *                    and added to the full-resolution streak sum
 *   streaks_compose  output = sanitised source + the streak sum
 * Ray-aligned working grids (draft, preview): a ray whose major axis is x runs on a grid
 * reduced FX = factor times in x only (FY = 1), a y-major ray on one reduced in y; working
 * pixel (X, Y) stands for the FX x FY run of output pixels along the ray through its centre
 * (FX X + FX / 2, FY Y + FY / 2), integer division: a whole pixel, so a ray through a pixel
 * centre crosses a 45-degree grid's columns at pixel centres: no interpolation across it):
 * each pixel of the run is moved across the ray by round(shear x its distance along the axis
 * from the centre), `shear` = the ray's cross change per pixel along its major axis.  So a
 * thin ray stays one pixel thin; only its length is sampled every FX (FY) pixels.  At final
 * FX = FY = 1 (no offset).
 * RING = 1 (frames over STREAM_PIXELS at final and reference, CHECKED = 1): the frame
 * streams through in chunks of rows and each buffer a pass reads holds only the rows the
 * next passes still need: absolute row y lives at row y % rows of it (`rows` its height), so
 * a chunk's kernels address rows by their frame row (`y0`: the chunk's first; streaks_wrap)
 * and compute the same floats as over whole buffers.
 * Passes n = 0..N-1 with step 4^n * direction compose to the line kernel
 * sum_{k=0}^{T 4^(N-1)-1} a^k delta(x + k d) exactly (each k has one base-4 expansion; the
 * last pass has T <= 4 taps of non-zero weight).
 */
#include "lib/scatter.h"
#include "lib/precision.h"

#ifndef CHECKED
#define CHECKED 1
#endif
#ifndef EXTENDED
#define EXTENDED 0
#endif

#ifndef RING
#define RING 0
#endif
#if RING
#if !CHECKED
#error "RING buffers need CHECKED taps"
#endif
/* Row y of a ring (x: a multiple of its height y at or below the chunk's first row, y: its
 * height): y % height for the rows a chunk reads (within one height of the chunk), without a
 * division per load; a tap of weight 0 past them reads some held row (finite, times 0). */
inline int streaks_wrap(int y, int2 ring)
{
  int r = y - ring.x;
  r = r < 0 ? r + ring.y : r;
  r = r >= ring.y ? r - ring.y : r;
  return clamp(r, 0, ring.y - 1);
}
inline int2 streaks_ring(int y0, int rows)
{
  return (int2)(y0 - y0 % rows, rows);
}
#define STREAKS_ROW(y, ring) streaks_wrap((y), (ring))
#else
#define STREAKS_ROW(y, ring) (y)
#endif

#ifndef PEAK_TILE
#define PEAK_TILE 32
#endif

/* TILED = 1 (final and reference, whole passes): a kernel runs over the row spans listed in
 * `spans` (int4 (x0, y, x1, 0): pixels x0 <= x < x1 of row y, x0 a multiple of 4), one span
 * per global row (axis 1), `px` pixels per work-item along axis 0; elsewhere the frame holds
 * no light (seeds, bright pixels) or no streak (passes).  TILED = 0: axes 0, 1 are the
 * whole grid.  BLOCK: the side (px) of the blocks the seeds mark in `lit`. */
#ifndef TILED
#define TILED 0
#endif
#ifndef BLOCK
#define BLOCK 8
#endif

/* The work-item's (x in work-items of `px` pixels, y); past its span, x lies past every
 * grid (the kernels' bounds tests return). */
inline int2 streaks_item(global const int *spans, int px)
{
#if TILED
  const int4 s = vload4(get_global_id(1), spans);
  const int x = s.x + (int)get_global_id(0) * px;
  return (int2)(x < s.z ? x / px : 1 << 28, s.y);
#else
  return (int2)((int)get_global_id(0), (int)get_global_id(1));
#endif
}

/* The peak luminance of the light a source pixel belongs to (0 outside every light). */
inline float streaks_peak(global const float *peak, int tiles_x, int tiles_y, int sx, int sy)
{
  const int i = min(sx / PEAK_TILE, tiles_x - 1), j = min(sy / PEAK_TILE, tiles_y - 1);
  return peak[j * tiles_x + i];
}

/* The level a source pixel's light must pass: the threshold, or `core` times the peak of the
 * light it belongs to (`peak`: per scene-analysis tile, tiles_x x tiles_y over the source
 * window, the peak luminance of its connected bright region), whichever is higher.  With a
 * core rule, light in no light's tile does not streak: the analysis is the frame's, so that
 * is light an earlier step drew (a star filter's rays before its spikes), and streaked again
 * pixel by pixel its lines fanned out into wedges. */
inline float streaks_level(global const float *peak, int tiles_x, int tiles_y, int sx, int sy,
                           float threshold, float core)
{
  if(core <= 0.0f) return threshold;
  const float pk = streaks_peak(peak, tiles_x, tiles_y, sx, sy);
  return pk > 0.0f ? fmax(threshold, core * pk) : INFINITY;
}

/* The light that streaks: above its level (scatter_bright), weighted by (L / peak)^core_power
 * (> 0: the brightest rows of a light dominate, the streak's core is thin), its colour kept
 * by `source_color` (0: its luminance, the streak's colour is then the tint). */
inline float4 streaks_light(float4 c, float level, float source_color, float core_power,
                            float peak)
{
  float4 h = scatter_bright(c, level);
  if(core_power > 0.0f && peak > 0.0f)
    h *= pow(clamp(clfx_luminance(c) / peak, 0.0f, 1.0f), core_power);
  if(source_color >= 1.0f) return h;
  const float l = clfx_luminance(h);
  return (float4)((float3)l + (h.xyz - (float3)l) * source_color, 0.0f);
}

/* One seed per compact light: a source pixel whose streaking light is non-zero, whose
 * luminance is the highest within `radius` px (Chebyshev; ties go to the earlier pixel in
 * raster order) and whose window's border ring holds no streaking light above `ring_share`
 * of its own (the light is smaller than the window) gathers the streaking light of that
 * window into a point at its luminance-weighted centroid: seeds[i] = (x, y, centroid x,
 * centroid y, r, g, b, 0), source pixels; `count` counts the seeds (those past `cap` are
 * counted, not stored); flags[x, y] = 1 marks the seed; lit[block] = 1 marks each BLOCK x
 * BLOCK block of the source with streaking light.  A streak is then as thin as
 * diffraction draws it, whatever the light's size; an extended light (a window, the sky)
 * streaks pixel by pixel (streaks_bright). */
kernel void streaks_seeds(global const float *src, const int src_pitch, const int src_w,
                          const int src_h, const float threshold, global const float *peak,
                          const int tiles_x, const int tiles_y, const float core,
                          const float source_color, const float core_power, const int radius,
                          const float ring_share, global float *seeds,
                          volatile global int *count, const int cap, global uchar *flags,
                          global const int *spans, volatile global int *lit)
{
  const int2 item = streaks_item(spans, 1);
  const int x = item.x, y = item.y;
  if(x >= src_w || y >= src_h) return;
  const float4 c = clfx_load4(src, src_pitch, x, y);
  const float pk = streaks_peak(peak, tiles_x, tiles_y, x, y);
  const float4 h = streaks_light(c, streaks_level(peak, tiles_x, tiles_y, x, y, threshold, core),
                                 source_color, core_power, pk);
  if(!(h.x > 0.0f || h.y > 0.0f || h.z > 0.0f)) return;
  /* the BLOCK x BLOCK blocks of the source that hold streaking light (no pixel elsewhere
   * streaks or seeds): what final's passes are limited to */
  atomic_or(lit + (y / BLOCK) * ((src_w + BLOCK - 1) / BLOCK) + x / BLOCK, 1);
  const float l0 = clfx_luminance(fmax(clfx_finite4_or_zero(c), (float4)0.0f));
  const float h0 = clfx_luminance(h);
  float4 sum = (float4)0.0f;
  float wsum = 0.0f, wx = 0.0f, wy = 0.0f;
  /* rows outwards from the seed: a brighter neighbour usually ends the scan early */
  for(int k = 0; k <= 2 * radius; k++)
  {
    const int dy = (k & 1) ? -((k + 1) >> 1) : (k >> 1);
    const int sy = y + dy;
    if(sy < 0 || sy >= src_h) continue;
    for(int dx = -radius; dx <= radius; dx++)
    {
      const int sx = x + dx;
      if(sx < 0 || sx >= src_w) continue;
      const float4 q = clfx_load4(src, src_pitch, sx, sy);
      const float lq = clfx_luminance(fmax(clfx_finite4_or_zero(q), (float4)0.0f));
      if(lq > l0 || (lq == l0 && (dy < 0 || (dy == 0 && dx < 0)))) return;
      const float pq = streaks_peak(peak, tiles_x, tiles_y, sx, sy);
      const float4 hq = streaks_light(q, streaks_level(peak, tiles_x, tiles_y, sx, sy,
                                                       threshold, core),
                                      source_color, core_power, pq);
      const float wq = clfx_luminance(hq);
      if(wq > ring_share * h0 && (abs(dx) == radius || abs(dy) == radius)) return; /* extended */
      sum += hq;
      wsum += wq;
      wx += wq * (float)dx;
      wy += wq * (float)dy;
    }
  }
  flags[y * src_w + x] = 1;
  const int i = atomic_inc(count);
  if(i >= cap) return;
  const float cx = wsum > 0.0f ? wx / wsum : 0.0f, cy = wsum > 0.0f ? wy / wsum : 0.0f;
  sum = fmin(sum, (float4)SCATTER_FLT_MAX);
  vstore8((float8)((float)x, (float)y, (float)x + cx, (float)y + cy, sum.x, sum.y, sum.z, 0.0f),
          i, seeds);
}

/* One pass of the seeds' windows: out(x, y) = max of in over (x + k sx, y + k sy), |k| <=
 * radius (run along x then y: the pixels a seed gathered, flagged 1). */
/* out = in dilated by a line of 2 radius + 1 pixels along (sx, sy) (one of them 1, the other
 * 0): 1 where a flag lies within `radius` pixels along the line, else 0.  One work-item per
 * row (sx = 1) or column (sy = 1) keeps a running count of the flags in its window: each
 * pixel costs two reads whatever the radius (a gather of the 2 radius + 1 pixels cost
 * 0.29 s of CPU on an empty 1080p frame for the two passes). */
kernel void streaks_dilate(global const uchar *in, global uchar *out, const int w, const int h,
                           const int radius, const int sx, const int sy)
{
  const int line = get_global_id(0);
  const int n = sx ? w : h;
  if(line >= (sx ? h : w)) return;
  const int step = sx ? 1 : w;
  global const uchar *src = in + (sx ? line * w : line);
  global uchar *dst = out + (sx ? line * w : line);
  int count = 0;
  for(int k = 0; k < min(radius, n); k++)   /* pixel 0's window less its last pixel */
    count += src[k * step] != 0;
  for(int i = 0; i < n; i++)
  {
    if(i + radius < n) count += src[(i + radius) * step] != 0;
    if(i - radius - 1 >= 0) count -= src[(i - radius - 1) * step] != 0;
    dst[i * step] = count > 0 ? 1 : 0;
  }
}

/* The streaking light of source pixel (sx, sy). */
inline float4 streaks_ext(global const float *src, int src_pitch, int sx, int sy,
                          float threshold, global const float *peak, int tiles_x, int tiles_y,
                          float core, float source_color, float core_power)
{
  const float level = streaks_level(peak, tiles_x, tiles_y, sx, sy, threshold, core);
  const float pk = core_power > 0.0f ? streaks_peak(peak, tiles_x, tiles_y, sx, sy) : 0.0f;
  return streaks_light(clfx_load4(src, src_pitch, sx, sy), level, source_color, core_power,
                       pk);
}

/* scale x the sum of the streaking light of the fx x fy source pixels of working pixel
 * (x, y) that no seed gathered (`gathered`: source-sized flags): the run along the reduced
 * axis `lead` pixels ahead of the working pixel's centre, each pixel taken from the nearest
 * pixel across of the ray's line through that centre (`shear`: the ray's cross change per
 * pixel along the reduced axis; fx = fy = 1, lead = 0: the pixel itself); (ox, oy) = source
 * window origin inside the output window, full-resolution pixels. */
inline float4 streaks_box(global const float *src, int src_pitch, int src_w, int src_h, int x,
                          int y, int fx, int fy, float shear, int lead, int ox, int oy,
                          float threshold,
                          float scale, global const float *peak, int tiles_x, int tiles_y,
                          float core, float source_color, float core_power,
                          global const uchar *gathered)
{
  float4 acc = (float4)0.0f;
  const int centre = max(fx, fy) / 2;
  for(int j = 0; j < fy; j++)
  {
    for(int i = 0; i < fx; i++)
    {
      const int a = (fx > 1 ? i : j) - centre + lead;  /* along the axis from the centre */
      const int off = (int)floor(shear * (float)a + 0.5f);
      const int sx = x * fx + (fx > 1 ? centre + a : i) + (fy > 1 ? off : 0) - ox;
      const int sy = y * fy + (fy > 1 ? centre + a : j) + (fx > 1 ? off : 0) - oy;
#if EXTENDED      /* src holds the light already (streaks_extended) */
      if(sy < 0 || sy >= src_h || sx < 0 || sx >= src_w) continue;
      acc += clfx_load4(src, src_pitch, sx, sy) * scale;
#else
      if(sy < 0 || sy >= src_h || sx < 0 || sx >= src_w || gathered[sy * src_w + sx]) continue;
      acc += streaks_ext(src, src_pitch, sx, sy, threshold, peak, tiles_x, tiles_y, core,
                         source_color, core_power) * scale;
#endif
    }
  }
  return acc;
}

/* One work-item per source pixel: its streaking light if no seed gathered it, else 0 (the
 * terms of streaks_box, once a frame for the reduced grids of draft and preview, whose rays
 * each gather them again). */
kernel void streaks_extended(global const float *src, const int src_pitch, const int src_w,
                             const int src_h, const float threshold, global const float *peak,
                             const int tiles_x, const int tiles_y, const float core,
                             const float source_color, const float core_power,
                             global const uchar *gathered, global float *ext)
{
  const int x = get_global_id(0), y = get_global_id(1);
  if(x >= src_w || y >= src_h) return;
  clfx_store4(ext, src_w, x, y, gathered[y * src_w + x] ? (float4)0.0f
              : streaks_ext(src, src_pitch, x, y, threshold, peak, tiles_x, tiles_y, core,
                            source_color, core_power));
}

/* One work-item per working pixel (rows from y0; `rows`: dst's height with RING): the
 * average of the streaking light no seed gathered (extended lights; streaks_box), plus the
 * seeds' points splatted bilinearly along the ray: in the column (row) the point lies
 * between, and in each of those at the row (column) where the ray through the point crosses
 * it (shear x its distance).  Light is moved `lead` pixels
 * back along the reduced axis (on the ray's line): half a working pixel towards the streak,
 * so a working pixel stands for the run of the streak it is the middle of (not half of it
 * behind the light: the line kernel is one-sided).  `points`: (x, y, r, g, b, 0,
 * 0, 0) per seed, working pixels, light already divided by fx x fy; `bin_start` (bins_x *
 * bins_y + 1) and `bin_seed` list, per BIN x BIN block of working pixels, the seeds whose
 * splat touches it, in seed order. */
kernel void streaks_bright(global const float *src, const int src_pitch, const int src_w,
                           const int src_h, global float *dst, const int org,
                           const int dst_pitch, const int dst_wp, const int dst_h,
                           const int fx, const int fy, const float shear, const int lead,
                           const int ox, const int oy, const float threshold,
                           global const float *peak, const int tiles_x, const int tiles_y,
                           const float core, const float source_color,
                           const float core_power, global const uchar *gathered,
                           global const float *points, global const int *bin_start,
                           global const int *bin_seed, const int bins_x, const int bin,
                           const int y0, const int rows, global const int *spans)
{
  const int2 item = streaks_item(spans, 1);
  const int x = item.x, y = item.y + y0;
  if(x >= dst_wp || y >= dst_h) return;
  dst += 4 * org;
  const float inv = 1.0f / (float)(fx * fy);
  float4 acc = streaks_box(src, src_pitch, src_w, src_h, x, y, fx, fy, shear, lead, ox, oy,
                           threshold, 1.0f, peak, tiles_x, tiles_y, core, source_color,
                           core_power, gathered) * inv;
  if(!scatter_pixel_finite(acc))  /* the sum passed FLT_MAX: average term by term instead */
    acc = streaks_box(src, src_pitch, src_w, src_h, x, y, fx, fy, shear, lead, ox, oy, threshold,
                      inv, peak, tiles_x, tiles_y, core, source_color, core_power, gathered);
  const int b = (y / bin) * bins_x + x / bin;
  for(int k = bin_start[b]; k < bin_start[b + 1]; k++)
  {
    float8 s = vload8(bin_seed[k], points);
    if(lead)        /* moved `lead` pixels back along the ray's line */
    {
      s.s0 -= fx > 1 ? (float)lead / (float)fx : shear * (float)lead;
      s.s1 -= fy > 1 ? (float)lead / (float)fy : shear * (float)lead;
    }
    const float cx = fy > 1 ? s.s0 + shear * (float)fy * ((float)y - s.s1) : s.s0;
    const float cy = fx > 1 ? s.s1 + shear * (float)fx * ((float)x - s.s0) : s.s1;
    const float w = fmax(1.0f - fabs(cx - (float)x), 0.0f)
                    * fmax(1.0f - fabs(cy - (float)y), 0.0f);
    acc += (float4)(s.s2, s.s3, s.s4, 0.0f) * w;
  }
#if RING
  const int2 ring = streaks_ring(y0, rows);
#endif
  clfx_store4(dst, dst_pitch, x, STREAKS_ROW(y, ring), fmin(acc, (float4)SCATTER_FLT_MAX));
}

/* Reads relative to the interior origin; `wp` = interior pitch, `h` = interior rows.  With
 * CHECKED = 0 every tap lies inside the margin (the host sized it), so no test is needed. */
#if CHECKED
inline float4 streaks_at(global const float *img, int pitch, int wp, int h, int2 ring, int x,
                         int y)
{
  if(x < 0 || x >= wp || y < 0 || y >= h) return (float4)0.0f;
  return vload4(STREAKS_ROW(y, ring) * pitch + x, img);
}
#endif

inline float16 streaks_at4(global const float *img, int pitch, int wp, int h, int2 ring, int x,
                           int y)
{
#if CHECKED
  if(y < 0 || y >= h || x < 0 || x + 4 > wp)
    return (float16)(streaks_at(img, pitch, wp, h, ring, x, y),
                     streaks_at(img, pitch, wp, h, ring, x + 1, y),
                     streaks_at(img, pitch, wp, h, ring, x + 2, y),
                     streaks_at(img, pitch, wp, h, ring, x + 3, y));
#endif
  return vload16(0, img + (STREAKS_ROW(y, ring) * pitch + x) * 4);
}

/* Bilinear sample of 4 consecutive pixels shifted by (dx, dy): the weights are the same for
 * all four, so it is four float16 loads and four vector multiply-adds. */
inline float16 streaks_tap(global const float *img, int pitch, int wp, int h, int2 ring, int x,
                           int y, float dx, float dy)
{
  const float fx0 = floor(dx), fy0 = floor(dy);
  const int ix = x + (int)fx0, iy = y + (int)fy0;
  const float fx = dx - fx0, fy = dy - fy0;
  float16 top = streaks_at4(img, pitch, wp, h, ring, ix, iy) * (1.0f - fx);
  if(fx > 0.0f) top += streaks_at4(img, pitch, wp, h, ring, ix + 1, iy) * fx;
  if(fy <= 0.0f) return top;
  float16 bot = streaks_at4(img, pitch, wp, h, ring, ix, iy + 1) * (1.0f - fx);
  if(fx > 0.0f) bot += streaks_at4(img, pitch, wp, h, ring, ix + 1, iy + 1) * fx;
  return top * (1.0f - fy) + bot * fy;
}

inline float16 streaks_rgba4(float4 w)
{
  return (float16)(w, w, w, w);
}

/* One tap's share of a pass: the float product, rounded to float before it is summed in REAL
 * (convert_float16 keeps the compiler from fusing it into the sum: the oracle's order). */
inline REAL16 streaks_term(float16 v, float4 w)
{
  return TO_REAL16(convert_float16(v * streaks_rgba4(w)));
}

/* One pass of one direction.  w0..w3 are the per-channel tap weights (alpha weight 0).
 * Each work-item produces 4 pixels of a row (rows from y0; `in_rows`, `out_rows`: the
 * buffers' heights with RING).  ACCUM = 1: out += result (last pass). */
kernel void streaks_pass(global const float *in, global float *out, const int org,
                         const int pitch, const int wp, const int w, const int h,
                         const float step_x, const float step_y,
                         const float4 w0, const float4 w1, const float4 w2, const float4 w3,
                         const int y0, const int in_rows, const int out_rows,
                         global const int *spans)
{
  const int2 item = streaks_item(spans, 4);
  const int qx = item.x, y = item.y + y0;
  if(qx * 4 >= wp || y >= h) return;
  const int x = qx * 4;
  in += 4 * org;
  out += 4 * org;
#if RING
  const int2 ring = streaks_ring(y0, in_rows), ring_out = streaks_ring(y0, out_rows);
#else
  const int2 ring = (int2)(0, 0), ring_out = ring;
#endif
  REAL16 sum = streaks_term(vload16(0, in + (STREAKS_ROW(y, ring) * pitch + x) * 4), w0);
  sum += streaks_term(streaks_tap(in, pitch, wp, h, ring, x, y, step_x, step_y), w1);
  sum += streaks_term(streaks_tap(in, pitch, wp, h, ring, x, y, 2.0f * step_x,
                                  2.0f * step_y), w2);
  sum += streaks_term(streaks_tap(in, pitch, wp, h, ring, x, y, 3.0f * step_x,
                                  3.0f * step_y), w3);
  sum = fmin(sum, (REAL)SCATTER_FLT_MAX);  /* saturate: finite input, finite output */
  if(x + 4 > w)  /* padding stays zero: it stands for "outside the image" */
  {
    const float4 m = (float4)((float)(x < w), (float)(x + 1 < w), (float)(x + 2 < w),
                              (float)(x + 3 < w));
    sum *= TO_REAL16((float16)(m.xxxx, m.yyyy, m.zzzz, m.wwww));
  }
  out += (STREAKS_ROW(y, ring_out) * pitch + x) * 4;
#if ACCUM
  sum += TO_REAL16(vload16(0, out));
#endif
  vstore16(fmin(TO_FLOAT16(sum), SCATTER_FLT_MAX), 0, out);
}

/* A ray-aligned working buffer (interior lo_w x lo_h, reduced f times in x for ALONG_X = 1,
 * in y for ALONG_X = 0; the output window starts `ext` pixels into its reduced axis) added to
 * the full-resolution streak sum `acc` (pitch acc_pitch, w x h): each output pixel
 * interpolates linearly between the two working columns (rows) around it along the reduced
 * axis (clamped at the ends), and in each at the row (column) where the ray through the
 * pixel crosses it (shear x the distance), linearly across; zero
 * outside the interior. */
#ifndef ALONG_X
#define ALONG_X 1
#endif
inline float4 streaks_line_at(global const float *lo, int pitch, int u, int v)
{
#if ALONG_X
  return clfx_load4(lo, pitch, u, v);
#else
  return clfx_load4(lo, pitch, v, u);
#endif
}

inline float4 streaks_cross(global const float *lo, int pitch, int u, int cross_n, float r)
{
  const float r0 = floor(r), fr = r - r0;
  const int v0 = (int)r0, v1 = v0 + 1;
  const float w0 = (v0 >= 0 && v0 < cross_n) ? 1.0f - fr : 0.0f;
  const float w1 = (v1 >= 0 && v1 < cross_n) ? fr : 0.0f;
  return streaks_line_at(lo, pitch, u, clamp(v0, 0, cross_n - 1)) * w0
         + streaks_line_at(lo, pitch, u, clamp(v1, 0, cross_n - 1)) * w1;
}

kernel void streaks_expand(global const float *lo, const int org, const int pitch,
                           const int lo_w, const int lo_h, const int f, const int ext,
                           const float shear, global float *acc, const int acc_pitch,
                           const int w, const int h)
{
  const int x = get_global_id(0), y = get_global_id(1);
  if(x >= w || y >= h) return;
  lo += 4 * org;
#if ALONG_X
  const int a = x + ext, c = y, n = lo_w, cross_n = lo_h;
#else
  const int a = y + ext, c = x, n = lo_h, cross_n = lo_w;
#endif
  const int mid = f / 2;
  const float t = (float)(a - mid) / (float)f, t0 = floor(t), wt = t - t0;
  const int u0 = clamp((int)t0, 0, n - 1), u1 = clamp((int)t0 + 1, 0, n - 1);
  const float4 s = streaks_cross(lo, pitch, u0, cross_n,
                                 (float)c + shear * (float)(u0 * f + mid - a)) * (1.0f - wt)
                   + streaks_cross(lo, pitch, u1, cross_n,
                                   (float)c + shear * (float)(u1 * f + mid - a)) * wt;
  clfx_store4(acc, acc_pitch, x, y, clfx_load4(acc, acc_pitch, x, y) + s);
}

/* out = sanitised source (zero outside its window) + the full-resolution streak sum.  `out`
 * is the part of the output window from (dx0, dy0), its rows from row0 here; `streak` holds
 * rows r0.. of the streak sum (pitch s_pitch).  4 pixels per work-item (dst_pitch is a
 * multiple of 4): float16 where all 4 lie in the source and the output, else pixel by pixel
 * (the same floats: scatter_source and scatter_add per channel). */
kernel void streaks_compose(global const float *src, const int src_pitch, const int src_w,
                            const int src_h, const int ox, const int oy,
                            global const float *streak, const int org, const int s_pitch,
                            const int r0, global float *dst, const int dst_pitch,
                            const int dst_w, const int dst_h, const int dx0, const int dy0,
                            const int row0)
{
  const int x = get_global_id(0) * 4, y = get_global_id(1) + row0;
  streak += 4 * org;
  if(x >= dst_pitch || y >= dst_h) return;
  const int sx = x - ox, sy = y - oy;
  global const float *s = streak + ((size_t)(y + dy0 - r0) * s_pitch + x + dx0) * 4;
  if(x + 4 <= dst_w && sx >= 0 && sx + 4 <= src_w && sy >= 0 && sy < src_h)
  {
    const float16 c = clfx_finite16_or_zero(vload16(0, src + ((size_t)sy * src_pitch + sx) * 4));
    const float16 r = clamp(c + vload16(0, s), -SCATTER_FLT_MAX, SCATTER_FLT_MAX);
    vstore16((float16)(r.s012, c.s3, r.s456, c.s7, r.s89a, c.sb, r.scde, c.sf), 0,
             dst + ((size_t)y * dst_pitch + x) * 4);
    return;
  }
  for(int i = 0; i < 4; i++)
  {
    float4 o = (float4)0.0f;   /* the output's padding columns: 0 */
    if(x + i < dst_w)
      o = scatter_add(scatter_source(src, src_pitch, src_w, src_h, sx + i, sy),
                      vload4(i, s));
    clfx_store4(dst, dst_pitch, x + i, y, o);
  }
}

/* Zero the row spans of `buf` (interior from `org`, rows `pitch` apart, wp x h) listed in
 * `spans` (TILED = 1), 4 pixels per work-item: the parts of a pass buffer that a ray's
 * passes read but do not write (they hold no streak), which an earlier ray or frame left
 * set. */
kernel void streaks_clear(global float *buf, const int org, const int pitch, const int wp,
                          const int h, global const int *spans)
{
  const int2 item = streaks_item(spans, 4);
  if(item.x * 4 >= wp || item.y >= h) return;
  vstore16((float16)0.0f, 0, buf + (org + item.y * pitch + item.x * 4) * 4);
}
