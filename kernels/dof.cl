/* dof.cl: gather depth of field with near/far fields (clfx/plugins/dof.py has the model).
 *
 * dof_prepare: per padded pixel, the sanitised premultiplied colour and the signed CoC
 *   radius in x pixels (< 0 in front of the focus plane), clamped to clamp_r.  The padded
 *   image (`pad` pixels each side, clamp-to-edge) lets the gather read without bounds tests;
 *   beyond the image its colours' luminance is capped as the hidden background's (dof_cap):
 *   what lies past the frame edge is a guess, and a light on the edge row must not become a
 *   streak of lights reaching a CoC radius past it (issue 35).
 * dof_prepare, dof_edges and dof_mixed take 16 pixels per work-item, with vector loads and
 *   stores where all 16 lie inside the image (and hold no depth edge): PoCL does not
 *   vectorise one-pixel work-items (docs/performance.md), and a group of 4 took 4-5x the
 *   time of a group of 16 on these passes.
 * dof_edges: the radii made edge-aware (see there).
 * dof_mixed: mixed edge pixels (a filtered beauty over a point-sampled depth), their
 *   coverage of the near layer and the two layers' radii and colours (see there); the
 *   gather splits each into its near and far part.
 * dof_tile_cap: per tile, the mean of log(1 + luminance) over every 4th pixel and row: the
 *   gather turns it into the cap of the colours that fill in the background hidden behind a
 *   blurred foreground (dof_cap).
 * dof_down2: the 2 x 2 box of the padded colour and its radius (halved: half-res px),
 *   weighted by each pixel's luminance (and evenly), each term scaled before the sum so
 *   that finite values stay finite; 4 half-res pixels a work-item (DOF_DOWN2_PIXELWISE=1:
 *   one at a time, the same bits).
 * dof_prefilter: one pass of the binomial a-trous pyramid of the padded colour: planes
 *   1..L after plane 0, the tents that the sparse lattices of taps sample.
 * dof_gather: each work-item gathers 4 horizontally adjacent pixels (one float16) over the
 *   same pattern of integer tap offsets, so every tap is a vload16 + vload4 and the weights
 *   are float4 vectors (PoCL does not vectorise one-pixel work-items), 4 taps at a time
 *   (float16 weights, dof_taps) unless a mixed edge pixel is within reach (tap by tap,
 *   dof_tap).  Per tile (host table): copy, gather, or (tiles far out of focus) bilinear
 *   upsampling of the half-resolution gather, gathered again at full resolution where that
 *   is not smooth (the rim of a bokeh disk, a sharp pixel).
 *   DOF_TAP_BY_TAP=1 gathers every group tap by tap: the same bits (tests/plugins/test_dof.py).
 *
 * Build variants (compile-time, nothing in the hot loop when off):
 *   DOF_CATEYE=1: optical vignetting; every tap's coverage is also clipped by the barrel
 *   circle, whose centre (aperture radii) grows linearly from the optical centre with the
 *   destination pixel's position (dof_gather's cateye arguments; the shape varies smoothly,
 *   so the destination pixel's barrel stands for its taps').  DOF_CATEYE=2: two circles
 *   (the rear rim's, shifted away from the optical centre, and the front rim's, towards
 *   it): every coverage is clipped by both, a lemon pointed at both ends.
 * Anamorphic squeeze lives in the tap tables (offsets in aperture space) and axial
 * chromatic aberration in dof_prepare's per-channel radius offset (one gather per distinct
 * offset, dof_merge_channels): neither costs anything here.
 *
 * The gather accumulates in REAL (lib/precision.h: double at the reference level); a sum
 * that overflows float is taken again with every colour scaled by 2^-64.
 */
#include "lib/common.h"
#include "lib/precision.h"

#define NEAR_EPS 0.25f   /* |radius| below this is in focus: never a near-field pixel */
#define EDGE_PX 1.0f     /* radius range over 3 x 3 that makes a depth edge */
#define EDGE_TAU 0.5f    /* log-luminance distance from its own layer that makes a pixel odd */
#define MIX_MIN 0.02f    /* a mixed pixel's smallest coverage of either layer */
#define MIX_TOL 0.25f    /* a mixed pixel's colour off the segment between its layers' */
#define MIX_GAP 2.0f     /* a depth edge's gap over the rest of its 3 x 3 radii's range */
#define MIX_TILE 32      /* dof_mixed's flag tiles (px) */
#define OVERFLOW_SCALE 5.421010862427522e-20f   /* 2^-64 */
#ifndef DOF_CATEYE
#define DOF_CATEYE 0
#endif
#define CATEYE_MIN_FRAC 1e-3f   /* the open aperture's smallest fraction (normalisation) */
#ifndef DOF_DOWN2_PIXELWISE
#define DOF_DOWN2_PIXELWISE 0   /* 1: dof_down2 pixel by pixel (its check: the same bits) */
#endif
#ifndef DOF_TAP_BY_TAP
#define DOF_TAP_BY_TAP 0   /* 1: every gather tap by tap (the blocks' check: the same bits) */
#endif

inline float dof_coc_radius(float z, float k_half, float focus, float clamp_r, float offset)
{
  /* r = K/2 (1 - S/z) + offset (a channel's axial CA; 0 without): finite at z = +inf
     (-> K/2); z NaN, 0 or < 0 is invalid -> in the focus plane. */
  if(!(z > 0.0f)) return clamp(offset, -clamp_r, clamp_r);
  const float r = (clfx_is_finite(z) ? k_half * (1.0f - focus / z) : k_half) + offset;
  return clamp(r, -clamp_r, clamp_r);
}

/* dof_coc_radius of 16 depths (the same operations, lane by lane). */
inline float16 dof_coc_radius16(float16 z, float k_half, float focus, float clamp_r,
                                float offset)
{
  const int16 finite = (as_uint16(z) & 0x7f800000u) != (uint16)0x7f800000u;
  const float16 r = select((float16)(k_half), k_half * (1.0f - focus / z), finite) + offset;
  return clamp(select((float16)(offset), r, z > 0.0f), -clamp_r, clamp_r);
}

inline float dof_log_lum(float4 c)
{
  return log1p(fmax(clfx_luminance(clfx_finite4_or_zero(c)), 0.0f));
}

/* The cap of hidden-background colours for tile (tx, ty): CAP_FACTOR times the geometric
 * mean luminance (minus 1) of the brightest 3 x 3 tiles around (dof_tile_cap's means). */
inline float dof_cap(global const float *log_mean, const int tx, const int ty,
                     const int tiles_x, const int tiles_y, const float cap_factor)
{
  float g = 0.0f;
  for(int dy = -1; dy <= 1; dy++)
    for(int dx = -1; dx <= 1; dx++)
      g = fmax(g, log_mean[clfx_clampi(ty + dy, 0, tiles_y - 1) * tiles_x
                           + clfx_clampi(tx + dx, 0, tiles_x - 1)]);
  return cap_factor * (exp(g) - 1.0f);
}

/* `log_mean` (dof_tile_cap's, `tiles_x` x `tiles_y` tiles of `tile` px on the whole render's
 * grid, image pixel (0, 0) at grid pixel (gx0, gy0)): the padding's colours are capped at
 * dof_cap of the tile of the edge pixel they repeat. */
kernel void dof_prepare(global const float *src, global const float *depth, const int pitch,
                        const int width, const int height, global float *col,
                        global float *coc, const int ppitch, const int pheight,
                        const int pad, const float k_half, const float focus,
                        const float clamp_r, const float offset,
                        global const float *log_mean, const int tiles_x, const int tiles_y,
                        const int tile, const float cap_factor, const int gx0, const int gy0)
{
  const int x = get_global_id(0) * 16, py = get_global_id(1);
  if(py >= pheight || x >= ppitch) return;
  const int sy = clfx_clampi(py - pad, 0, height - 1);
  if(sy == py - pad && x >= pad && x + 16 - pad <= width)
  {  /* 16 pixels inside the image (most): vector loads, no cap */
    const int i = sy * pitch + x - pad, o = py * ppitch + x;
    const global float *s = src + i * 4;
    vstore16(clfx_finite16_or_zero(vload16(0, s)), 0, col + o * 4);
    vstore16(clfx_finite16_or_zero(vload16(1, s)), 1, col + o * 4);
    vstore16(clfx_finite16_or_zero(vload16(2, s)), 2, col + o * 4);
    vstore16(clfx_finite16_or_zero(vload16(3, s)), 3, col + o * 4);
    vstore16(dof_coc_radius16(vload16(0, depth + i), k_half, focus, clamp_r, offset), 0,
             coc + o);
    return;
  }
  const int ty = clfx_clampi((sy + gy0) / tile, 0, tiles_y - 1);
  int cap_tx = -1;   /* the tile whose cap `cap` holds */
  float cap = 0.0f;
  for(int px = x; px < min(x + 16, ppitch); px++)
  {
    const int sx = clfx_clampi(px - pad, 0, width - 1);
    float4 c = clfx_finite4_or_zero(vload4(sy * pitch + sx, src));
    if(sx != px - pad || sy != py - pad)
    {  /* past the frame edge: the edge pixel repeated, its highlights capped */
      const int tx = clfx_clampi((sx + gx0) / tile, 0, tiles_x - 1);
      if(tx != cap_tx)
      {
        cap = dof_cap(log_mean, tx, ty, tiles_x, tiles_y, cap_factor);
        cap_tx = tx;
      }
      const float lum = clfx_luminance(c);
      if(lum > cap) c *= cap / lum;
    }
    vstore4(c, py * ppitch + px, col);
    coc[py * ppitch + px] = dof_coc_radius(depth[sy * pitch + sx], k_half, focus, clamp_r, offset);
  }
}

/* The edge-aware radius of image pixel (x, y) (see dof_edges); neighbours clamp to the
 * image, `coc` and `col` are the padded buffers. */
inline float dof_edge_radius(global const float *col, global const float *coc,
                            const int ppitch, const int pad, const int width,
                            const int height, const int x, const int y)
{
  float r[9], lg[9];
  float rmin = INFINITY, rmax = -INFINITY;
  for(int j = 0; j < 9; j++)
  {
    const int i = (clfx_clampi(y + j / 3 - 1, 0, height - 1) + pad) * ppitch
                  + clfx_clampi(x + j % 3 - 1, 0, width - 1) + pad;
    r[j] = coc[i];
    lg[j] = dof_log_lum(vload4(i, col));
    rmin = fmin(rmin, r[j]);
    rmax = fmax(rmax, r[j]);
  }
  const float rp = r[4];
  if(rmax - rmin < EDGE_PX) return rp;
  const float mid = 0.5f * (rmin + rmax);
  const int own_near = rp < mid;
  float own[8], d_oth = INFINITY, r_oth = rp;
  int n_own = 0;
  for(int j = 0; j < 9; j++)
  {
    if(j == 4) continue;
    if((r[j] < mid) == own_near)
    {  /* insertion sort: the own layer's median, robust to the pixel's own light */
      int k = n_own++;
      for(; k > 0 && own[k - 1] > lg[j]; k--) own[k] = own[k - 1];
      own[k] = lg[j];
    }
    else
    {
      const float d = fabs(lg[j] - lg[4]);
      if(d < d_oth) { d_oth = d; r_oth = r[j]; }
    }
  }
  const float d_own = n_own ? fabs(lg[4] - own[(n_own - 1) / 2]) : 0.0f;
  return d_own > EDGE_TAU && fabs(r_oth) < fabs(rp) ? r_oth : rp;
}

/* Image pixels (x..x + 3, y): whether their 3 x 3 radii span EDGE_PX or more (a depth edge),
 * and their own radii (`centre`); neighbours clamp to the image. */
inline int4 dof_edge4(global const float *coc, const int ppitch, const int pad, const int width,
                      const int height, const int x, const int y, float4 *centre)
{
  float4 rmin = (float4)(INFINITY), rmax = (float4)(-INFINITY);
  for(int dy = -1; dy <= 1; dy++)
  {
    const global float *row = coc + (clfx_clampi(y + dy, 0, height - 1) + pad) * ppitch + pad;
    float4 l, rr;
    if(x > 0 && x + 5 <= width)
    {  /* the 6 radii x - 1 .. x + 4 inside the image */
      l = vload4(0, row + x - 1);
      rr = (float4)(l.s23, vload2(0, row + x + 3));
    }
    else
    {
      float v[6];
      for(int k = 0; k < 6; k++) v[k] = row[clfx_clampi(x + k - 1, 0, width - 1)];
      l = (float4)(v[0], v[1], v[2], v[3]);
      rr = (float4)(v[2], v[3], v[4], v[5]);
    }
    const float4 m = (float4)(l.s123, rr.s2);
    rmin = fmin(rmin, fmin(m, fmin(l, rr)));
    rmax = fmax(rmax, fmax(m, fmax(l, rr)));
    if(dy == 0) *centre = m;
  }
  return rmax - rmin >= EDGE_PX;
}

/* Image pixels (x..x + 15, y) when none of them is on a depth edge (their 3 x 3 radii span
 * less than EDGE_PX) nor on the image border, their radii in `centre`; 0 otherwise (the
 * 4-pixel path decides).  Most pixels: 16 per work-item, vector loads (dof_edge4's test). */
inline int dof_quiet16(global const float *coc, const int ppitch, const int pad,
                       const int width, const int height, const int x, const int y,
                       float16 *centre)
{
  if(!(x > 0 && x + 17 <= width && y > 0 && y < height - 1)) return 0;
  float16 rmin = (float16)(INFINITY), rmax = (float16)(-INFINITY);
  for(int dy = -1; dy <= 1; dy++)
  {
    const global float *row = coc + (y + dy + pad) * ppitch + pad + x;
    const float16 l = vload16(0, row - 1), m = vload16(0, row), rr = vload16(0, row + 1);
    rmin = fmin(rmin, fmin(m, fmin(l, rr)));
    rmax = fmax(rmax, fmax(m, fmax(l, rr)));
    if(dy == 0) *centre = m;
  }
  return !any(rmax - rmin >= EDGE_PX);
}

/* dof_edges of image pixels (x..x + 3, y). */
inline void dof_edges4(global const float *col, global const float *coc, global float *out,
                       const int ppitch, const int pheight, const int pad, const int width,
                       const int height, const int x, const int y)
{
  float4 centre;
  const int4 edge = dof_edge4(coc, ppitch, pad, width, height, x, y, &centre);
  float res[4] = {centre.s0, centre.s1, centre.s2, centre.s3};
  const int is_edge[4] = {edge.s0, edge.s1, edge.s2, edge.s3};
  for(int l = 0; l < 4 && x + l < width; l++)
  {
    if(is_edge[l]) res[l] = dof_edge_radius(col, coc, ppitch, pad, width, height, x + l, y);
    /* border pixels also fill their part of the padding */
    const int xl = x + l;
    const int x0 = xl == 0 ? 0 : xl + pad, x1 = xl == width - 1 ? ppitch - 1 : xl + pad;
    const int y0 = y == 0 ? 0 : y + pad, y1 = y == height - 1 ? pheight - 1 : y + pad;
    for(int py = y0; py <= y1; py++)
      for(int px = x0; px <= x1; px++)
        out[py * ppitch + px] = res[l];
  }
}

/* Edge-aware radii: `coc` (dof_prepare's) -> `out`, 16 image pixels per work-item (the
 * padding takes the border pixels' radii: clamp-to-edge of the result).  Over the pixel's
 * 3 x 3 neighbourhood, if the radii span EDGE_PX or more the pixel sits on a depth edge
 * between a near layer (r < mid-range) and a far one, its own being its centre sample's.
 * A pixel unlike its own layer (log luminance more than EDGE_TAU from the lower median of
 * its own layer's neighbours) takes the radius of the other layer's neighbour closest to it in log
 * luminance when that one is sharper: a light beside a blurred bar, its pixels sampled on
 * the bar, belongs to the sharp background (the antialiased beauty mixes the layers, the
 * point-sampled depth does not).  Most groups of 16 hold no depth edge (dof_quiet16: one
 * vector pass); the others take dof_edges4. */
kernel void dof_edges(global const float *col, global const float *coc, global float *out,
                      const int ppitch, const int pheight, const int pad, const int width,
                      const int height)
{
  const int x = get_global_id(0) * 16, y = get_global_id(1);
  if(x >= width || y >= height) return;
  float16 centre;
  if(dof_quiet16(coc, ppitch, pad, width, height, x, y, &centre))
  {
    vstore16(centre, 0, out + (y + pad) * ppitch + x + pad);
    return;
  }
  for(int x4 = x; x4 < min(x + 16, width); x4 += 4)
    dof_edges4(col, coc, out, ppitch, pheight, pad, width, height, x4, y);
}

/* Mixed edge pixels: a renderer filters the beauty over the pixel but takes the depth at its
 * centre, so on a depth edge a pixel's colour mixes two layers under one layer's depth (the
 * card's edge row under the sky's: gathered with the sky's radius it makes a soft copy of
 * the card above its edge).  Per image pixel (x, y) on a depth edge, whose 3 x 3 radii
 * (dof_edges') have a gap of EDGE_PX or more that is MIX_GAP times the rest of their range
 * or more (two layers; a steep ramp of depth is no edge): its neighbours split at the
 * mid-range radius (in the gap) into a near layer
 * (smaller signed radius: closer to the camera) and a far one; for every pair of a near
 * neighbour n and a far one f the pixel's colour C is projected onto the segment f -> n:
 * C = f + a (n - f) + e.  A pair explains the pixel when a lies in (MIX_MIN, 1 - MIX_MIN)
 * and the residual e is within MIX_TOL of the distances from C to both ends (C lies between
 * them, on the segment); of those the pair farthest apart in colour (the purest ends)
 * wins.  Written: `mixa` the near layer's coverage a (0: not mixed), `mixr` (r_n, r_f) the
 * two neighbours' radii, `mixd` n - f: the near part's colour is C + (1 - a)(n - f), the
 * far part's C - a (n - f) (they mix back to C; the residual stays in both).  RGBA
 * (premultiplied: the beauty mixes linearly in every channel).  Each part estimates a
 * layer's colour, which lies in the range of the colours it is estimated from: a part
 * below min(0, C, n, f) in a channel (the residual extrapolated past 0: a pixel of the
 * beach ball's rim over transparent black split into a far part of negative blue, spread
 * into the blurred background, QC) is set to that bound and the other part takes up the
 * difference, so they still mix back to C (dof_mix_bound).  Border pixels also fill
 * their part of the padding (clamp-to-edge, as dof_edges); `count` counts the mixed pixels
 * of rows y0..y1; `flags` (zeroed, `ftiles_x` per row) flags the MIX_TILE px tiles of the
 * image holding one (the gather reads the split data only within reach of a flagged tile). */
/* The colour difference `d` of a split of colour `c` at near coverage `a`, its far part
 * c - a d and near part c + (1 - a) d kept at or above `lo` (per channel; c >= lo): a part
 * below it is set to it, the other takes up the difference (they mix back to c).  Neither
 * below: `d` itself. */
inline float4 dof_mix_bound(const float4 c, const float a, const float4 d, const float4 lo)
{
  const float4 span = c - lo;   /* >= 0 */
  float4 out = select(d, span / a, c - a * d < lo);                 /* far part at lo */
  return select(out, -span / (1.0f - a), c + (1.0f - a) * d < lo);  /* near part at lo */
}

/* The split of image pixel (x, y) on a depth edge (see dof_mixed): its near coverage (0: not
 * mixed), with `rn`, `rf`, `d` set when mixed. */
inline float dof_mix_split(global const float *col, global const float *coc, const int ppitch,
                           const int pad, const int width, const int height, const int x,
                           const int y, float *rn, float *rf, float4 *d)
{
  int at[9];
  float r[9];
  float rmin = INFINITY, rmax = -INFINITY;
  for(int j = 0; j < 9; j++)
  {
    at[j] = (clfx_clampi(y + j / 3 - 1, 0, height - 1) + pad) * ppitch
            + clfx_clampi(x + j % 3 - 1, 0, width - 1) + pad;
    r[j] = coc[at[j]];
    rmin = fmin(rmin, r[j]);
    rmax = fmax(rmax, r[j]);
  }
  /* a discontinuity: the largest gap between the sorted radii, >= EDGE_PX and >= MIX_GAP
     times the rest of their range (two layers, not a steep depth ramp) */
  float sr[9];
  for(int j = 0; j < 9; j++)
  {
    int k = j;
    for(; k > 0 && sr[k - 1] > r[j]; k--) sr[k] = sr[k - 1];
    sr[k] = r[j];
  }
  float gap = 0.0f;
  for(int k = 0; k < 8; k++) gap = fmax(gap, sr[k + 1] - sr[k]);
  if(!(gap >= EDGE_PX && gap >= MIX_GAP * (rmax - rmin - gap))) return 0.0f;
  const float mid = 0.5f * (rmin + rmax);
  const float4 c4 = vload4(at[4], col);
  float best = 0.0f, a = 0.0f;
  float4 lo = (float4)(0.0f);   /* the winning pair's lower bound of the layers' colours */
  for(int jn = 0; jn < 9; jn++)
  {
    if(jn == 4 || !(r[jn] < mid)) continue;
    const float4 cn = vload4(at[jn], col), en = c4 - cn;
    for(int jf = 0; jf < 9; jf++)
    {
      if(jf == 4 || r[jf] < mid) continue;
      const float4 cf = vload4(at[jf], col);
      const float4 dd = cn - cf, ef = c4 - cf;
      const float l2 = dot(dd, dd);
      if(!(l2 > best && l2 <= FLT_MAX)) continue;
      const float t = dot(ef, dd) / l2;
      if(!(t > MIX_MIN && t < 1.0f - MIX_MIN)) continue;
      const float4 e = ef - t * dd;
      if(dot(e, e) > MIX_TOL * MIX_TOL * fmin(dot(ef, ef), dot(en, en))) continue;
      best = l2;
      a = t;
      *d = dd;
      lo = fmin(fmin(cn, cf), fmin(c4, (float4)(0.0f)));
      *rn = r[jn];
      *rf = r[jf];
    }
  }
  if(a > 0.0f) *d = dof_mix_bound(c4, a, *d, lo);
  return a;
}

/* dof_mixed of image pixels (x..x + 3, y). */
inline void dof_mixed4(global const float *col, global const float *coc, global float *mixa,
                       global float *mixr, global float *mixd, const int ppitch,
                       const int pheight, const int pad, const int width, const int height,
                       const int y0, const int y1, global int *count, global int *flags,
                       const int ftiles_x, const int x, const int y)
{
  /* only a 3 x 3 radius range of EDGE_PX or more can hold a depth edge */
  float4 centre;
  const int4 edge = dof_edge4(coc, ppitch, pad, width, height, x, y, &centre);
  const int is_edge[4] = {edge.s0, edge.s1, edge.s2, edge.s3};
  for(int l = 0; l < 4 && x + l < width; l++)
  {
    const int xl = x + l;
    float rn = 0.0f, rf = 0.0f;
    float4 d = (float4)(0.0f);
    const float a = is_edge[l] ? dof_mix_split(col, coc, ppitch, pad, width, height, xl, y,
                                               &rn, &rf, &d) : 0.0f;
    if(a > 0.0f)
    {
      flags[y / MIX_TILE * ftiles_x + xl / MIX_TILE] = 1;   /* every writer writes 1 */
      if(y >= y0 && y < y1) atomic_inc(count);
    }
    /* border pixels also fill their part of the padding; mixr and mixd are read only where
       mixa > 0 */
    const int bx0 = xl == 0 ? 0 : xl + pad, bx1 = xl == width - 1 ? ppitch - 1 : xl + pad;
    const int by0 = y == 0 ? 0 : y + pad, by1 = y == height - 1 ? pheight - 1 : y + pad;
    for(int py = by0; py <= by1; py++)
      for(int px = bx0; px <= bx1; px++)
      {
        const int i = py * ppitch + px;
        mixa[i] = a;
        if(a > 0.0f)
        {
          vstore2((float2)(rn, rf), i, mixr);
          vstore4(d, i, mixd);
        }
      }
  }
}

/* 16 image pixels per work-item: most are no depth edge (dof_quiet16: none mixed), the rest
 * take dof_mixed4. */
kernel void dof_mixed(global const float *col, global const float *coc, global float *mixa,
                      global float *mixr, global float *mixd, const int ppitch,
                      const int pheight, const int pad, const int width, const int height,
                      const int y0, const int y1, global int *count, global int *flags,
                      const int ftiles_x)
{
  const int x = get_global_id(0) * 16, y = get_global_id(1);
  if(x >= width || y >= height) return;
  float16 centre;
  if(dof_quiet16(coc, ppitch, pad, width, height, x, y, &centre))
  {
    vstore16((float16)(0.0f), 0, mixa + (y + pad) * ppitch + x + pad);
    return;
  }
  for(int x4 = x; x4 < min(x + 16, width); x4 += 4)
    dof_mixed4(col, coc, mixa, mixr, mixd, ppitch, pheight, pad, width, height, y0, y1,
               count, flags, ftiles_x, x4, y);
}

/* Per tile of the whole render's window (`width` x `height`, the grid the gather's tiles
 * use), from the source `src` whose pixel (0, 0) is the window's pixel (ox, oy) (`sw` x
 * `sh`; the window may be larger: transparent black there), sanitised as dof_prepare does:
 * computed once per frame, so a band of a tiled render reads the whole frame's caps. */
kernel void dof_tile_cap(global const float *src, const int pitch, const int ox,
                         const int oy, const int sw, const int sh, const int width,
                         const int height, const int tile, const int tiles_x,
                         const int tiles_y, global float *out)
{
  const int tx = get_global_id(0), ty = get_global_id(1);
  if(tx >= tiles_x || ty >= tiles_y) return;
  const int x0 = tx * tile, y0 = ty * tile;
  const int x1 = min(x0 + tile, width), y1 = min(y0 + tile, height);
  float sum = 0.0f;
  int n = 0;
  for(int y = y0; y < y1; y += 4)   /* every 4th pixel and row: an estimate suffices */
  {
    float row = 0.0f;
    const int sy = y - oy;
    for(int x = x0; x < x1; x += 4)
    {
      const int sx = x - ox;
      const float4 c = sx >= 0 && sx < sw && sy >= 0 && sy < sh
                       ? clfx_finite4_or_zero(vload4(sy * pitch + sx, src)) : (float4)(0.0f);
      row += native_log(1.0f + fmax(clfx_luminance(c), 0.0f));
      n++;
    }
    sum += row;
  }
  out[ty * tiles_x + tx] = sum / (float)max(n, 1);
}

/* One separable pass of a-trous level L (`step` = 2^(L-1)): dst = 1/4 src(-step) +
 * 1/2 src + 1/4 src(+step) along x (`vertical` 0) or y, clamped to the padded plane (the
 * image's clamp-to-edge: the padding repeats the edge pixels).  Offsets in pixels. */
kernel void dof_prefilter(global const float *src, const int src_off, global float *dst,
                          const int dst_off, const int ppitch, const int pheight,
                          const int step, const int vertical)
{
  const int x = get_global_id(0), y = get_global_id(1);
  if(x >= ppitch || y >= pheight) return;
  const int xa = vertical ? x : max(x - step, 0), xb = vertical ? x : min(x + step, ppitch - 1);
  const int ya = vertical ? max(y - step, 0) : y, yb = vertical ? min(y + step, pheight - 1) : y;
  const float4 c = 0.25f * vload4(src_off + ya * ppitch + xa, src)
                 + 0.5f * vload4(src_off + y * ppitch + x, src)
                 + 0.25f * vload4(src_off + yb * ppitch + xb, src);
  vstore4(c, dst_off + y * ppitch + x, dst);
}

/* dof_down2's half-resolution pixel (x, y). */
inline void dof_down2_px(global const float *col, global const float *coc, const int ppitch,
                         const int pheight, global float *hcol, global float *hcoc,
                         const int hpitch, const int x, const int y)
{
  const int x0 = min(2 * x, ppitch - 1), x1 = min(2 * x + 1, ppitch - 1);
  const int y0 = min(2 * y, pheight - 1), y1 = min(2 * y + 1, pheight - 1);
  const float4 c = 0.25f * vload4(y0 * ppitch + x0, col) + 0.25f * vload4(y0 * ppitch + x1, col)
                 + 0.25f * vload4(y1 * ppitch + x0, col) + 0.25f * vload4(y1 * ppitch + x1, col);
  vstore4(c, y * hpitch + x, hcol);
  /* the radius the box's light spreads with: each pixel's weighted by its luminance over
   * the box's brightest (plus 1 %), so a light's antialiased edge pixel beside the sky
   * spreads at the light's radius, not at the mean with the sky's (a broken ring of half-res
   * dots around a light, issue 25); the plain mean where the box is even or dark */
  const int i00 = y0 * ppitch + x0, i01 = y0 * ppitch + x1;
  const int i10 = y1 * ppitch + x0, i11 = y1 * ppitch + x1;
  const float4 l = fmax((float4)(clfx_luminance(vload4(i00, col)),
                                 clfx_luminance(vload4(i01, col)),
                                 clfx_luminance(vload4(i10, col)),
                                 clfx_luminance(vload4(i11, col))), 0.0f);
  const float m = fmax(fmax(l.x, l.y), fmax(l.z, l.w));
  const float4 w = m > 0.0f && m <= FLT_MAX ? l / m + 0.01f : (float4)1.0f;
  const float4 r = (float4)(coc[i00], coc[i01], coc[i10], coc[i11]);
  hcoc[y * hpitch + x] = 0.5f * dot(w, r) / dot(w, (float4)1.0f);
}

/* The luminance of 4 pixels' colours (float16: pixel p's RGBA in lanes 4 p..4 p + 3),
 * clfx_luminance's operations lane by lane. */
inline float4 dof_lum4(float16 c)
{
  return (CLFX_LUMA_R) * c.s048c + (CLFX_LUMA_G) * c.s159d + (CLFX_LUMA_B) * c.s26ae;
}

/* 4 half-resolution pixels a work-item: dof_down2_px's operations lane by lane (dot(w, r)
 * as PoCL's: unfused products, added in pairs), away from the rows' clamped ends. */
kernel void dof_down2(global const float *col, global const float *coc, const int ppitch,
                      const int pheight, global float *hcol, global float *hcoc,
                      const int hpitch, const int hheight)
{
  const int x = get_global_id(0) * 4, y = get_global_id(1);
  if(x >= hpitch || y >= hheight) return;
  if(DOF_DOWN2_PIXELWISE || 2 * x + 8 > ppitch || x + 4 > hpitch)
  {
    for(int j = x; j < min(x + 4, hpitch); j++)
      dof_down2_px(col, coc, ppitch, pheight, hcol, hcoc, hpitch, j, y);
    return;
  }
  const int i0 = min(2 * y, pheight - 1) * ppitch + 2 * x;
  const int i1 = min(2 * y + 1, pheight - 1) * ppitch + 2 * x;
  const float16 a0 = vload16(0, col + i0 * 4), b0 = vload16(1, col + i0 * 4);
  const float16 a1 = vload16(0, col + i1 * 4), b1 = vload16(1, col + i1 * 4);
  /* the 4 boxes' top left, top right, bottom left and bottom right pixels */
  const float16 p00 = (float16)(a0.s0123, a0.s89ab, b0.s0123, b0.s89ab);
  const float16 p01 = (float16)(a0.s4567, a0.scdef, b0.s4567, b0.scdef);
  const float16 p10 = (float16)(a1.s0123, a1.s89ab, b1.s0123, b1.s89ab);
  const float16 p11 = (float16)(a1.s4567, a1.scdef, b1.s4567, b1.scdef);
  vstore16(0.25f * p00 + 0.25f * p01 + 0.25f * p10 + 0.25f * p11, 0,
           hcol + (y * hpitch + x) * 4);
  const float4 l00 = fmax(dof_lum4(p00), 0.0f), l01 = fmax(dof_lum4(p01), 0.0f);
  const float4 l10 = fmax(dof_lum4(p10), 0.0f), l11 = fmax(dof_lum4(p11), 0.0f);
  const float4 m = fmax(fmax(l00, l01), fmax(l10, l11));
  const int4 lit = m > 0.0f && m <= FLT_MAX;
  const float4 one = (float4)(1.0f);
  const float4 w00 = select(one, l00 / m + 0.01f, lit), w01 = select(one, l01 / m + 0.01f, lit);
  const float4 w10 = select(one, l10 / m + 0.01f, lit), w11 = select(one, l11 / m + 0.01f, lit);
  const float8 r0 = vload8(0, coc + i0), r1 = vload8(0, coc + i1);
  const float4 q00 = w00 * r0.s0246;   /* products on their own: not fused into the sums */
  const float4 q01 = w01 * r0.s1357;
  const float4 q10 = w10 * r1.s0246;
  const float4 q11 = w11 * r1.s1357;
  vstore4(0.5f * ((q00 + q01) + (q10 + q11)) / ((w00 + w01) + (w10 + w11)), 0,
          hcoc + y * hpitch + x);
}

#define LANES(v) ((v).s0000111122223333)

#if DOF_CATEYE >= 2
#define CATEYE_ARGS , const float4 ce_x, const float4 ce_y, const float4 cf_x, \
                    const float4 cf_y, const float4 ce_frac
#define CATEYE_PASS , ce_x, ce_y, cf_x, cf_y, ce_frac
#define DOF_CE_ARGS(T) , const T ax, const T ay, const T ce_x, const T ce_y, const T cf_x, \
                       const T cf_y, const T ce_frac
#define DOF_CE_PASS(ax, ay, PIX) , ax, ay, PIX(ce_x), PIX(ce_y), PIX(cf_x), PIX(cf_y), \
                                 PIX(ce_frac)
#define DOF_CE_IN , ax, ay, ce_x, ce_y, cf_x, cf_y, ce_frac
#elif DOF_CATEYE
#define CATEYE_ARGS , const float4 ce_x, const float4 ce_y, const float4 ce_frac
#define CATEYE_PASS , ce_x, ce_y, ce_frac
#define DOF_CE_ARGS(T) , const T ax, const T ay, const T ce_x, const T ce_y, const T ce_frac
#define DOF_CE_PASS(ax, ay, PIX) , ax, ay, PIX(ce_x), PIX(ce_y), PIX(ce_frac)
#define DOF_CE_IN , ax, ay, ce_x, ce_y, ce_frac
#else
#define CATEYE_ARGS
#define CATEYE_PASS
#define DOF_CE_ARGS(T)
#define DOF_CE_PASS(ax, ay, PIX)
#define DOF_CE_IN
#endif
/* The cat-eye clip of a coverage (radius `r`, ramps of width 1 / `inv_s`): `clip` that of
 * the barrel circle(s), ex = ax OP ce_x r (ey likewise; the second circle's gx, gy), and
 * DOF_COV_CLIP a coverage clipped by it; without DOF_CATEYE nothing. */
#define DOF_CLIP(ex, ey, r) clamp(((r) - sqrt((ex) * (ex) + (ey) * (ey))) * inv_s + 0.5f, \
                                  0.0f, 1.0f)
#if DOF_CATEYE
#define DOF_CLIPS(T, clip, ex, ey, gx, gy, r, OP) \
  const T ex = ax OP ce_x * (r), ey = ay OP ce_y * (r); \
  T clip = DOF_CLIP(ex, ey, r); \
  DOF_CLIP2(T, clip, gx, gy, r, OP)
#define DOF_COV_CLIP(cov, clip) fmin(cov, clip)
#define DOF_CE_FRAC * ce_frac
#else
#define DOF_CLIPS(T, clip, ex, ey, gx, gy, r, OP)
#define DOF_COV_CLIP(cov, clip) cov
#define DOF_CE_FRAC
#endif
#if DOF_CATEYE >= 2
#define DOF_CLIP2(T, clip, gx, gy, r, OP) \
  const T gx = ax OP cf_x * (r), gy = ay OP cf_y * (r); \
  clip = fmin(clip, DOF_CLIP(gx, gy, r));
#else
#define DOF_CLIP2(T, clip, gx, gy, r, OP)
#endif

/* The gather's running sums of 4 pixels: near and far fields' colours and weights, the
 * near field's coverage. */
typedef struct
{
  REAL16 fn, ff;
  REAL4 wn_sum, wf_sum, alpha;
} dof_sums;

/* A per-pixel float4 in every slot of a block of taps (lane 4 t + p: slot t, pixel p; LANES
 * puts a per-slot float4 in every pixel's lane), and slot t's float4 of a float16. */
#define PIXELS(v) ((v).s0123012301230123)
#define SLOT(v, t) ((t) == 0 ? (v).s0123 : (t) == 1 ? (v).s4567 : (t) == 2 ? (v).s89ab \
                                                                         : (v).scdef)

/* clfx_any4 / clfx_all4 of an int16 mask. */
inline int dof_any16(const int16 m)
{
  const int8 h = m.lo | m.hi;
  return clfx_any4(h.lo | h.hi);
}

inline int dof_all16(const int16 m)
{
  const int8 h = m.lo & m.hi;
  return clfx_all4(h.lo & h.hi);
}

/* Taps (host table, clfx/plugins/dof.py tap_table): 8 floats each: integer offset x, y;
 * distance in aperture units for a near tap (shape upright at o) and a far tap (shape at -o);
 * aperture area the tap stands for (px^2); the offset in aperture space (x times the
 * anamorphic squeeze, y over the pixel aspect: px of the CoC radius); the tap's lattice
 * level L: its colour is read from plane L of the prefilter pyramid (`plane` pixels after
 * plane 0, `col`), and its coverage ramps are 2^L px wide (`inv_s` = 2^-L; a lattice of
 * spacing 2^L: the tents interpolate the ramp).  The rows are followed by the same table
 * column by column (each column `n4` floats: the table's taps and 4 of padding), which a
 * block of 4 taps reads as float4s.  A table mixes levels where the pixels in
 * focus or nearly of a tile within reach of a large near-field blur gather (tap_table's
 * `core`): a lattice serving the near field only (far distance "never") and the every-pixel
 * taps of the pixel's own small radius serving the far field only (near distance "never").
 * With DOF_CATEYE, `ce_x`, `ce_y` are the 4 pixels' barrel centres (aperture radii) and
 * `ce_frac` the open fraction of their apertures: a point at lens position l (aperture
 * radii) is seen only if |l - c| <= 1; a tap q whose light lands at p = q - o comes through
 * l = -o / r_q (signed radius), so its coverage is also that of |o + c r_q| <= |r_q|.  The
 * near field's weights (a tap's light over its own bokeh) divide by the clipped area.
 * DOF_CATEYE=2: `cf_x`, `cf_y` the second circle's centres, clipping the same way.
 * `cap_s`: the largest luminance a colour may have where it fills in the background hidden
 * behind a blurred foreground pixel (beyond its own CoC's reach).
 *
 * The weights below are written once for two shapes of lanes (DOF_WEIGHTS): float4, one
 * tap's weights for the 4 pixels (dof_tap), and float16, 4 taps' (dof_taps: slot t = lanes
 * 4 t + p, pixel p).  Per tap: radius `rq` (`arq` = |rq|, `q_near` where rq < -NEAR_EPS),
 * standing for the fraction `frac` of its pixel (1; a part of a mixed edge pixel: its
 * coverage, dof_mixed), table columns `d_near`, `d_far`, `inv_s` (and `ax`, `ay`); the 4
 * pixels' radii `r0` (`p_near`: r0 < -NEAR_EPS). */
#define DOF_WEIGHTS(T, IT, SUF) \
/* near field: the tap's light spread over its own CoC area */ \
CLFX_INLINE T dof_near_w##SUF( \
    const T arq, const IT q_near, const T frac, const T d_near, const T inv_s DOF_CE_ARGS(T)) \
{ \
  DOF_CLIPS(T, clip_n, enx, eny, gnx, gny, arq, -) \
  const T cov_n = DOF_COV_CLIP(clamp((arq - d_near) * inv_s + 0.5f, 0.0f, 1.0f), clip_n); \
  return select((T)(0.0f), cov_n / fmax(CLFX_PI * arq * arq DOF_CE_FRAC, 1.0f), q_near) \
         * frac; \
} \
/* far field: `wf` the weight sums', `wk` the colours'.  A tap behind p spreads at most p's \
   own radius (p occludes it); for a near p the far field is the background hidden behind \
   it, estimated from the visible background within p's radius; with `cap_it`, the part of \
   the coverage behind a near p that the tap's own CoC does not give is a guess at hidden \
   background: its highlights are capped (`k`: the colour's scale), so a light beside a \
   blurred bar does not shine through it. */ \
CLFX_INLINE void dof_far_w##SUF( \
    const T rq, const T arq, const IT q_near, const T frac, const T d_far, const T inv_s, \
    const T r0, const IT p_near, const int cap_it, const T k, T *wf, T *wk DOF_CE_ARGS(T)) \
{ \
  const T rf = select(select(arq, fmin(arq, fmax(r0, 0.0f)), rq > r0), fmax(arq, fabs(r0)), \
                      p_near); \
  DOF_CLIPS(T, clip_f, efx, efy, gfx, gfy, rf, +) \
  const T cov_f = DOF_COV_CLIP(clamp((rf - d_far) * inv_s + 0.5f, 0.0f, 1.0f), clip_f); \
  const T norm = select(1.0f / fmax(CLFX_PI * rf * rf, 1.0f), (T)(0.0f), q_near) * frac; \
  T w = cov_f * norm; \
  if(!cap_it) \
  { \
    *wf = *wk = w; \
    return; \
  } \
  DOF_CLIPS(T, clip_q, eqx, eqy, gqx, gqy, arq, +) \
  const T cov_q = fmin(DOF_COV_CLIP(clamp((arq - d_far) * inv_s + 0.5f, 0.0f, 1.0f), clip_q), \
                       cov_f); \
  const T w_fill = select((T)(0.0f), (cov_f - cov_q) * norm, p_near); \
  w -= w_fill; \
  *wk = w + w_fill * k; \
  *wf = w + w_fill; \
}
DOF_WEIGHTS(float4, int4, 4)
DOF_WEIGHTS(float16, int16, 16)
#undef DOF_WEIGHTS
#define DOF_SAME(v) (v)
#define DOF_CAP_K(lum) fmin(1.0f, cap_s / fmax(lum, 1e-30f))

/* dof_tap's near field (the tap's colour `c`). */
CLFX_INLINE void dof_tap_near(dof_sums *s, const float16 c,
                              const float4 arq, const int4 q_near,
                              const float4 frac, const float8 tp,
                              const float inv_s CATEYE_ARGS)
{
  const float4 wn = dof_near_w4(arq, q_near, frac, (float4)(tp.s2), (float4)(inv_s)
                                DOF_CE_PASS((float4)(tp.s5), (float4)(tp.s6), DOF_SAME));
  s->fn += TO_REAL16(c * LANES(wn));
  s->wn_sum += TO_REAL4(wn);
  s->alpha += TO_REAL4(wn * tp.s4);
}

/* One tap (table row `tp`) of colour `c` to the sums of the 4 pixels whose radii are `r0`
 * (`any_near`: any of them in front of the focus plane); the gather of 4 pixels within
 * reach of a mixed edge pixel goes tap by tap (dof_gather4).  A tap behind every pixel adds
 * exact zeros to the near field, one in front of every pixel to the far field: skipped. */
CLFX_INLINE void dof_tap(dof_sums *s, const float16 c,
                         const float4 rq, const float4 frac,
                         const float8 tp, const float inv_s,
                         const float4 r0, const int4 p_near,
                         const int any_near, const float cap_s
                         CATEYE_ARGS)
{
  const float4 arq = fabs(rq);
  const int4 q_near = rq < -NEAR_EPS;
  if(clfx_any4(q_near))
  {
    dof_tap_near(s, c, arq, q_near, frac, tp, inv_s CATEYE_PASS);
    if(clfx_all4(q_near)) return;
  }
  const int cap_it = any_near && clfx_any4(p_near & ~q_near);
  float4 wf, wk;
  dof_far_w4(rq, arq, q_near, frac, (float4)(tp.s3), (float4)(inv_s), r0, p_near, cap_it,
             cap_it ? DOF_CAP_K(dof_lum4(c)) : (float4)(0.0f), &wf, &wk
             DOF_CE_PASS((float4)(tp.s5), (float4)(tp.s6), DOF_SAME));
  s->ff += TO_REAL16(c * LANES(wk));
  s->wf_sum += TO_REAL4(wf);
}

/* Slot t's near-field (far-field) sums of weights `w` (the far colours' `wk`) where `use`
 * says, in slot order. */
#define DOF_ADD_NEAR(t, c) \
  if(use.s##t) \
  { \
    s->fn += TO_REAL16((c) * LANES(SLOT(wn, t))); \
    s->wn_sum += TO_REAL4(SLOT(wn, t)); \
    s->alpha += TO_REAL4(SLOT(wn, t) * area.s##t); \
  }
#define DOF_ADD_FAR(t, c) \
  if(use.s##t) \
  { \
    s->ff += TO_REAL16((c) * LANES(SLOT(wk, t))); \
    s->wf_sum += TO_REAL4(SLOT(wf, t)); \
  }

/* The gather's taps 4 at a time (slots 0-3), the weights of all 4 as float16 lanes (one
 * tap's weights are 4 lanes of a 16-lane machine otherwise) and each slot's sums added in
 * slot order: the same sums in the same order as tap by tap.  Slot t: colour `ct`, radius
 * `rq` (its lanes), added where `use` says (a slot not added, or a field a slot adds
 * nothing to beside those it does, adds exact zeros or nothing: the sums never hold -0).
 * dof_taps_near: the near field only (the taps beyond the pixels' own radii). */
CLFX_INLINE void dof_taps_near(
    dof_sums *s, const float16 c0, const float16 c1, const float16 c2, const float16 c3,
    const float16 rq, const int4 use, const float16 d_near, const float4 area,
    const float16 inv_s DOF_CE_ARGS(float16))
{
  const float16 wn = dof_near_w16(fabs(rq), rq < -NEAR_EPS, (float16)(1.0f), d_near, inv_s
                                  DOF_CE_IN);
  DOF_ADD_NEAR(0, c0) DOF_ADD_NEAR(1, c1) DOF_ADD_NEAR(2, c2) DOF_ADD_NEAR(3, c3)
}

CLFX_INLINE void dof_taps(
    dof_sums *s, const float16 c0, const float16 c1, const float16 c2, const float16 c3,
    const float16 rq, const int4 use, const float16 d_near, const float16 d_far,
    const float4 area, const float16 inv_s, const float16 r0, const int16 p_near,
    const int any_near, const float cap_s DOF_CE_ARGS(float16))
{
  const float16 arq = fabs(rq);
  const int16 q_near = rq < -NEAR_EPS;
  if(dof_any16(q_near))
  {
    const float16 wn = dof_near_w16(arq, q_near, (float16)(1.0f), d_near, inv_s DOF_CE_IN);
    DOF_ADD_NEAR(0, c0) DOF_ADD_NEAR(1, c1) DOF_ADD_NEAR(2, c2) DOF_ADD_NEAR(3, c3)
    if(dof_all16(q_near)) return;
  }
  const int cap_it = any_near && dof_any16(p_near & ~q_near);
  const float16 lum = cap_it ? (float16)(dof_lum4(c0), dof_lum4(c1), dof_lum4(c2),
                                         dof_lum4(c3)) : (float16)(0.0f);
  float16 wf, wk;
  dof_far_w16(rq, arq, q_near, (float16)(1.0f), d_far, inv_s, r0, p_near, cap_it,
              DOF_CAP_K(lum), &wf, &wk DOF_CE_IN);
  DOF_ADD_FAR(0, c0) DOF_ADD_FAR(1, c1) DOF_ADD_FAR(2, c2) DOF_ADD_FAR(3, c3)
}
#undef DOF_ADD_NEAR
#undef DOF_ADD_FAR

/* The gather of 4 pixels at `base` (padded index) whose radii are `r0`, colours times
 * `scale`; `c0`: their colours, the result where every tap is rejected.  With `mix` (a
 * table over the full-resolution image), mixed edge pixels among its level-0 taps are split
 * into their near and far parts (dof_mixed: near coverage `mixa`, near and far radii
 * `mixr`, near minus far colour `mixd`), each part a tap of its own radius standing for its
 * coverage; `layer` 1 (2): at the centre tap a mixed pixel stands for its far (near) part
 * only (the two gathers of a mixed pixel, dof_gather): those go tap by tap (dof_tap), the
 * others 4 taps at a time (dof_taps; `n4`: the table's column stride). */
inline REAL16 dof_gather4(global const float *col, global const float *coc, const int ppitch,
                          const int plane, const int base,
                          const float16 c0_in, const float4 r0, global const float *taps,
                          const int n4, const int first, const int2 count, const float cap,
                          const float scale, global const float *mixa,
                          global const float *mixr, global const float *mixd, const int mix,
                          const int layer CATEYE_ARGS)
{
  const float16 c0 = c0_in * scale;
  const int4 p_near = r0 < -NEAR_EPS;
  const int any_near = clfx_any4(p_near);
  const float cap_s = cap * scale;
  const float4 one = (float4)(1.0f);
  dof_sums s = {(REAL16)(0), (REAL16)(0), (REAL4)(0), (REAL4)(0), (REAL4)(0)};
  const int end1 = first + count.x, end2 = first + count.y;
#if DOF_TAP_BY_TAP
  const int blocks = 0;
#else
  const int blocks = !mix;   /* (a constant operand of && draws a compiler warning) */
#endif
  if(blocks)
  {
    const float16 r016 = PIXELS(r0);
    const int16 p_near16 = PIXELS(p_near);
    global const float *cols = taps + 8 * (n4 - 4);   /* the table column by column */
    /* a block: the taps from `i` in slots 0-3 (`use`: those before `end`; those after are
       read, not added: every table's taps lie within the padding, the columns' padding is
       tap 0) */
#define DOF_BLOCK(end) \
    const int4 use = (int4)(i) + (int4)(0, 1, 2, 3) < (int4)(end); \
    const int4 lv = convert_int4(vload4(0, cols + 7 * n4 + i)); \
    const int4 at = base + convert_int4(vload4(0, cols + n4 + i)) * ppitch \
                    + convert_int4(vload4(0, cols + i)); \
    const float16 rq = (float16)(vload4(0, coc + at.s0), vload4(0, coc + at.s1), \
                                 vload4(0, coc + at.s2), vload4(0, coc + at.s3)); \
    const float16 inv_s = LANES(as_float4((127 - lv) << 23));   /* 2^-L, exactly */
#define DOF_COLOUR(t) \
    (vload16(0, col + ((size_t)lv.s##t * (size_t)plane + (size_t)at.s##t) * 4) * scale)
#define DOF_COLUMN(k) vload4(0, cols + (k) * n4 + i)
    for(int i = first; i < end1; i += 4)
    {
      DOF_BLOCK(end1)
      dof_taps(&s, DOF_COLOUR(0), DOF_COLOUR(1), DOF_COLOUR(2), DOF_COLOUR(3), rq, use,
               LANES(DOF_COLUMN(2)), LANES(DOF_COLUMN(3)), DOF_COLUMN(4), inv_s, r016,
               p_near16, any_near, cap_s
               DOF_CE_PASS(LANES(DOF_COLUMN(5)), LANES(DOF_COLUMN(6)), PIXELS));
    }
    /* the taps beyond the pixels' own radii (dof_tap_count): their far weights are 0, only
       those in front of the focus plane add light */
    for(int i = end1; i < end2; i += 4)
    {
      DOF_BLOCK(end2)
      const int16 q = rq < -NEAR_EPS;
      const int4 near = use & ((int4)(clfx_any4(q.s0123), clfx_any4(q.s4567),
                                      clfx_any4(q.s89ab), clfx_any4(q.scdef)) != 0);
      if(!clfx_any4(near)) continue;
      const float16 zero = (float16)(0.0f);
      dof_taps_near(&s, near.s0 ? DOF_COLOUR(0) : zero, near.s1 ? DOF_COLOUR(1) : zero,
                    near.s2 ? DOF_COLOUR(2) : zero, near.s3 ? DOF_COLOUR(3) : zero, rq, near,
                    LANES(DOF_COLUMN(2)), DOF_COLUMN(4), inv_s
                    DOF_CE_PASS(LANES(DOF_COLUMN(5)), LANES(DOF_COLUMN(6)), PIXELS));
    }
#undef DOF_BLOCK
#undef DOF_COLOUR
#undef DOF_COLUMN
  }
  else
  {
    for(int i = first; i < end1; i++)
    {
      const float8 tp = vload8(i, taps);
      const int at = base + (int)tp.s1 * ppitch + (int)tp.s0;
      const int lv = (int)tp.s7;
      const float inv_s = as_float((127 - lv) << 23);     /* 2^-L, exactly */
      const float4 rq = vload4(0, coc + at);
      const float4 aq = mix && lv == 0 ? vload4(0, mixa + at) : (float4)(0.0f);
      const float16 c = vload16(0, col + ((size_t)lv * (size_t)plane + (size_t)at) * 4) * scale;
      if(!clfx_any4(aq > 0.0f))
      {
        dof_tap(&s, c, rq, one, tp, inv_s, r0, p_near, any_near, cap_s CATEYE_PASS);
        continue;
      }
      /* a mixed pixel: its far part C - a d at the far layer's radius and its near part
         C + (1 - a) d at the near layer's, each standing for its coverage (the first tap is
         the centre: in one of a mixed pixel's two gathers only that gather's part) */
      const int4 sq = aq > 0.0f;
      const float8 rr = vload8(0, mixr + at * 2);
      const float16 d = vload16(0, mixd + at * 4) * scale;
      float4 an = aq;
      if(layer && i == first) an = select(an, (float4)(layer == 2 ? 1.0f : 0.0f), sq);
      const int16 sq16 = LANES(sq);
      dof_tap(&s, select(c, c - d * LANES(aq), sq16), select(rq, rr.s1357, sq), one - an, tp,
              inv_s, r0, p_near, any_near, cap_s CATEYE_PASS);
      dof_tap(&s, select(c, c + d * LANES(one - aq), sq16), select(rq, rr.s0246, sq), an, tp,
              inv_s, r0, p_near, any_near, cap_s CATEYE_PASS);
    }
    /* the taps beyond the pixels' own radii: only those in front of the focus plane */
    for(int i = end1; i < end2; i++)
    {
      const float8 tp = vload8(i, taps);
      const int at = base + (int)tp.s1 * ppitch + (int)tp.s0;
      const int lv = (int)tp.s7;
      const float4 rq = vload4(0, coc + at);
      const float4 aq = mix && lv == 0 ? vload4(0, mixa + at) : (float4)(0.0f);
      const int4 sq = aq > 0.0f;
      const int split = clfx_any4(sq);
      const float8 rr = split ? vload8(0, mixr + at * 2) : (float8)(0.0f);
      const float4 rq_far = select(rq, rr.s1357, sq), rq_near = select(rq, rr.s0246, sq);
      const int4 far_near = rq_far < -NEAR_EPS, near_near = rq_near < -NEAR_EPS;
      if(!clfx_any4(far_near) && !(split && clfx_any4(near_near))) continue;
      const float inv_s = as_float((127 - lv) << 23);     /* 2^-L, exactly */
      const float16 c = vload16(0, col + ((size_t)lv * (size_t)plane + (size_t)at) * 4) * scale;
      if(!split)
      {
        dof_tap_near(&s, c, fabs(rq), far_near, one, tp, inv_s CATEYE_PASS);
        continue;
      }
      const float16 d = vload16(0, mixd + at * 4) * scale;
      const int16 sq16 = LANES(sq);
      if(clfx_any4(far_near))
        dof_tap_near(&s, select(c, c - d * LANES(aq), sq16), fabs(rq_far), far_near, one - aq,
                     tp, inv_s CATEYE_PASS);
      if(clfx_any4(near_near))
        dof_tap_near(&s, select(c, c + d * LANES(one - aq), sq16), fabs(rq_near), near_near,
                     aq, tp, inv_s CATEYE_PASS);
    }
  }
  /* normalise each field; every tap rejected -> the centre pixel (no 0/0) */
  const REAL4 tiny = (REAL4)(1e-20);
  const REAL4 a = clamp(s.alpha, (REAL4)(0), (REAL4)(1));
  const REAL4 inv_n = select((REAL4)(0), (REAL4)(1) / s.wn_sum, s.wn_sum > tiny);
  const REAL4 inv_f = select((REAL4)(0), (REAL4)(1) / s.wf_sum, s.wf_sum > tiny);
  const REAL16 centre = TO_REAL16(c0);
  const REAL16 near = select(centre, s.fn * LANES(inv_n), LANES(s.wn_sum > tiny));
  const REAL16 far = select(near, s.ff * LANES(inv_f), LANES(s.wf_sum > tiny));
  const REAL16 mix_a = LANES(select(a, (REAL4)(1), s.wf_sum <= tiny));
  return far * ((REAL16)(1) - mix_a) + near * mix_a;   /* no difference: stays finite */
}

inline int dof_all_finite16(float16 v)
{
  return all((as_uint16(v) & 0x7f800000u) != (uint16)0x7f800000u);
}

/* The gather of 4 pixels, taken again with scaled colours if float sums overflowed. */

inline float16 dof_gather_safe(global const float *col, global const float *coc,
                               const int ppitch, const int plane, const int base,
                               const float16 c0,
                               const float4 r0, global const float *taps, const int n4,
                               const int first,
                               const int2 count, const float cap, global const float *mixa,
                               global const float *mixr, global const float *mixd,
                               const int mix, const int layer CATEYE_ARGS)
{
  const REAL16 out = dof_gather4(col, coc, ppitch, plane, base, c0, r0, taps, n4, first,
                                 count, cap, 1.0f, mixa, mixr, mixd, mix, layer CATEYE_PASS);
  const float16 o = TO_FLOAT16(clamp(out, (REAL16)(-FLT_MAX), (REAL16)(FLT_MAX)));
  if(dof_all_finite16(o)) return o;
  const REAL16 s = dof_gather4(col, coc, ppitch, plane, base, c0, r0, taps, n4, first,
                               count, cap, OVERFLOW_SCALE, mixa, mixr, mixd, mix, layer
                               CATEYE_PASS);
  return clamp(TO_FLOAT16(s) * (1.0f / OVERFLOW_SCALE), -FLT_MAX, FLT_MAX);
}

/* Bilinear sample of the half-resolution result at full-resolution pixel (x, y) of the
 * whole render's grid (`hwidth` x `hheight`: the whole render's half-resolution size; `hres`
 * holds its rows from `hy0`, columns from `hx0`) over the half-resolution pixels that were
 * gathered (their tile, `tile` full-resolution px, is a half-resolution one: tile_info's mode
 * bit 0; the other tiles' half-resolution pixels are the 2 x 2 box of the unblurred source,
 * copied by the half gather: at a half-resolution tile's edge a sharp light there is not the
 * blurred light of the tile beside it; the weights of the gathered ones are renormalised: the pixel's
 * own half-resolution pixel, 3/4 x 3/4 of the weight, always is one); `lmin`, `lmax`: the
 * luminance range of the 4 half-resolution pixels it reads, widened (those not gathered
 * too: a tile beside that is not at half resolution holds sharper pixels, a contrast that
 * a dense table gathers again at full resolution).
 *
 * Pixels (x..x + 3, y) in lanes s0123, s4567, ...: the half-resolution pixels they share (at
 * most 4 columns of 2 rows), their luminance and whether they were gathered are loaded and
 * tested once. */
inline float16 dof_upsample4(global const float *hres, const int hpitch, const int hwidth,
                             const int hheight, const int hx0, const int hy0, const int x,
                             const int y, global const int *tile_info, const int tiles_x,
                             const int tiles_y, const int tile, float *lmin, float *lmax)
{
  const float hy = clamp(0.5f * ((float)y + 0.5f) - 0.5f, 0.0f, (float)(hheight - 1));
  const int y0 = (int)hy, y1 = min(y0 + 1, hheight - 1);
  const float fy = hy - (float)y0;
  const int r0 = (y0 - hy0) * hpitch - hx0, r1 = (y1 - hy0) * hpitch - hx0;
  const global int *mode0 = tile_info + clfx_clampi(2 * y0 / tile, 0, tiles_y - 1) * tiles_x * 16 + 4;
  const global int *mode1 = tile_info + clfx_clampi(2 * y1 / tile, 0, tiles_y - 1) * tiles_x * 16 + 4;
  const int k = x / 2 - 1;
  if(x % 4 == 0 && k >= 0 && k + 3 <= hwidth - 1)
  {  /* most groups: columns x/2 - 1 .. x/2 + 2, the pixels' (0, 1), (1, 2), (1, 2), (2, 3)
        at fx = 3/4, 1/4, 3/4, 1/4 (what the general path finds), as float16 lanes */
    const float16 a = vload16(0, hres + (r0 + k) * 4), b = vload16(0, hres + (r1 + k) * 4);
    const float4 la = dof_lum4(a), lb = dof_lum4(b);
    const float4 lo = fmin(la, lb), hi = fmax(la, lb);
    *lmin = fmin(*lmin, fmin(fmin(lo.x, lo.y), fmin(lo.z, lo.w)));
    *lmax = fmax(*lmax, fmax(fmax(hi.x, hi.y), fmax(hi.z, hi.w)));
    const int4 t = min(max(2 * (k + (int4)(0, 1, 2, 3)) / tile, (int4)(0)),
                       (int4)(tiles_x - 1)) * 16;
    const int4 va = (int4)(mode0[t.x], mode0[t.y], mode0[t.z], mode0[t.w]) & 1;
    const int4 vb = (int4)(mode1[t.x], mode1[t.y], mode1[t.z], mode1[t.w]) & 1;
    if(all((va & vb) != 0))
    {
      const float16 f = (float16)(0.75f, 0.75f, 0.75f, 0.75f, 0.25f, 0.25f, 0.25f, 0.25f,
                                  0.75f, 0.75f, 0.75f, 0.75f, 0.25f, 0.25f, 0.25f, 0.25f);
      const float16 al = (float16)(a.s0123, a.s4567, a.s4567, a.s89ab);
      const float16 ar = (float16)(a.s4567, a.s89ab, a.s89ab, a.scdef);
      const float16 bl = (float16)(b.s0123, b.s4567, b.s4567, b.s89ab);
      const float16 br = (float16)(b.s4567, b.s89ab, b.s89ab, b.scdef);
      return (al * (1.0f - f) + ar * f) * (1.0f - fy) + (bl * (1.0f - f) + br * f) * fy;
    }
  }
  int cx0[4], cx1[4];
  float fx[4];
  for(int l = 0; l < 4; l++)
  {
    const float hx = clamp(0.5f * ((float)(x + l) + 0.5f) - 0.5f, 0.0f, (float)(hwidth - 1));
    cx0[l] = (int)hx;
    cx1[l] = min(cx0[l] + 1, hwidth - 1);
    fx[l] = hx - (float)cx0[l];
  }
  /* the columns cx0[0] .. cx1[3] (consecutive: hx steps by 1/2) */
  const int c0 = cx0[0], n = cx1[3] - c0 + 1;
  float4 a[4], b[4];
  int va[4], vb[4];
  float la[4], lb[4];
  /* whether the 2 x n pixels were gathered: their tiles' mode bit 0 */
  for(int j = 0; j < n; j++)
  {
    a[j] = vload4(r0 + c0 + j, hres);
    b[j] = vload4(r1 + c0 + j, hres);
    const int t = clfx_clampi(2 * (c0 + j) / tile, 0, tiles_x - 1) * 16;
    va[j] = mode0[t] & 1;
    vb[j] = mode1[t] & 1;
    la[j] = clfx_luminance(a[j]);
    lb[j] = clfx_luminance(b[j]);
    *lmin = fmin(*lmin, fmin(la[j], lb[j]));
    *lmax = fmax(*lmax, fmax(la[j], lb[j]));
  }
  float16 out;
  for(int l = 0; l < 4; l++)
  {
    const int i0 = cx0[l] - c0, i1 = cx1[l] - c0;
    const float4 c00 = a[i0], c01 = a[i1], c10 = b[i0], c11 = b[i1];
    const float f = fx[l];
    const int4 ok = (int4)(va[i0], va[i1], vb[i0], vb[i1]) != 0;
    float4 o;
    if(all(ok))
      o = (c00 * (1.0f - f) + c01 * f) * (1.0f - fy) + (c10 * (1.0f - f) + c11 * f) * fy;
    else
    {
      const float4 w = select((float4)(0.0f), (float4)((1.0f - f) * (1.0f - fy), f * (1.0f - fy),
                                                       (1.0f - f) * fy, f * fy), ok);
      const float4 wn = w / (w.x + w.y + w.z + w.w);
      o = c00 * wn.x + c01 * wn.y + c10 * wn.z + c11 * wn.w;
    }
    if(l == 0) out.s0123 = o;
    else if(l == 1) out.s4567 = o;
    else if(l == 2) out.s89ab = o;
    else out.scdef = o;
  }
  return out;
}

/* How many of a table's first taps (`count` in all) can add anything to 4 pixels of radii
 * `r0`: where none is in front of the focus plane, .y: those within the largest of their
 * radii (at least NEAR_EPS) and `near_r`, the tile's bound of the radii in front of the
 * focus plane that its taps read; .x: those within their radii alone, the taps after which
 * have no far weight (the host's tap_counts: `counts_n` entries from `counts` in tile_info,
 * 0: no table).  The taps left out add exact zeros to every sum (a far tap spreads at most
 * the pixel's radius, NEAR_EPS if it lies in front of it; a near tap at most its own): the
 * same bits from fewer taps, mostly in-focus pixels beside a far background. */
inline int2 dof_tap_count(global const int *tile_info, const int counts, const int counts_n,
                          const float near_r, const float4 r0, const int count)
{
  if(counts_n == 0 || any(r0 < -NEAR_EPS)) return (int2)(count);
  const float r = fmax(fmax(fmax(r0.s0, r0.s1), fmax(r0.s2, r0.s3)), NEAR_EPS);
  const int own = min(tile_info[counts + min((int)ceil(2.0f * r), counts_n - 1)], count);
  const float rn = fmax(r, near_r);
  return (int2)(own, min(tile_info[counts + min((int)ceil(2.0f * rn), counts_n - 1)], count));
}

/* tile_info[t] = (first, count, sharp first, sharp count, mode, level, sharp level, reach,
 * near bound, counts, counts length, sharp counts, sharp counts length, 0, 0, 0), 16 ints
 * per tile, the tables' tap counts (dof_tap_count) after the tiles: the largest lattice
 * levels of the two tables' taps (tap_table's column 7; 0: every tap reads the image
 * itself), the farthest x or y offset of a tap of the first (px); count 0 copies the
 * sanitised source.  4 pixels in focus or nearly (0 <= radius < sharp_r, no near
 * pixel) gather with the sharp table (every pixel within sharp_r a far-field tap, the near
 * field around: tap_table's core), as do such pixels of a group gathered with a sparse
 * first table (level > 0); with mode bit 0,
 * 4 pixels all out of focus (|radius| >= low_r) take the half-resolution result `hres`
 * unless (mode bit 1: a dense table, a full-resolution gather there is worth it) its
 * half-res pixels span more than `refine` in log luminance (a bokeh rim); every other
 * group gathers at full resolution with (first, count).
 * `cateye` (used with DOF_CATEYE): the barrel centre of buffer pixel (x, y) is
 * (s0 (x + 0.5) + s1, s2 (y + 0.5) + s3) aperture radii (the host folds in the signed
 * strength, the optical centre, the half diagonal, the pixel aspect and the buffer's
 * scale); with DOF_CATEYE=2 the second circle's from s4..s7.
 * `plane`: pixels between the planes of `col`'s prefilter pyramid (dof_prefilter).
 * `place`: where the buffers sit on the grid of the whole render's window (the tiles, the
 * cat-eye centres, the half-resolution sampling): dst pixel (x, y) is grid pixel
 * (x + s0, y + s1), `col` / `coc` pixel (x, y) grid pixel (x + s2, y + s3); `hplace.s01`:
 * the grid pixel (half resolution) of `hres` pixel (0, 0).  A whole render: all 0; a band of
 * a tiled render: its rows of the whole render's grid (clfx/plugins/dof.py). */
kernel void dof_gather(global const float *col, global const float *coc, const int ppitch,
                       const int pad, global float *dst, const int pitch,
                       const int width, const int height, global const float *taps,
                       const int taps_n4, global const int *tile_info,
                       global const float *log_mean,
                       const int tiles_x, const int tiles_y, const int tile,
                       const float cap_factor, global const float *hres, const int hpitch,
                       const int hwidth, const int hheight, const float4 refine,
                       const float low_r, const float sharp_r, const float8 cateye,
                       const int plane,
                       const int4 place, const int4 hplace, global const float *mixa,
                       global const float *mixr, global const float *mixd,
                       global const int *mflags, const int mtiles_x, const int mtiles_y)
{
  const int qx = get_global_id(0), yd = get_global_id(1);
  const int xd = qx * 4;
  if(yd >= height || xd >= width) return;
  const int x = xd + place.s0, y = yd + place.s1;   /* the whole render's grid */
  const int tx = x / tile, ty = y / tile;
  const int16 info = vload16(ty * tiles_x + tx, tile_info);
  const int base = (y - place.s3 + pad) * ppitch + x - place.s2 + pad;
  global float *out = dst + (yd * pitch + xd) * 4;
  if(info.s1 == 0)
  {  /* the sanitised source */
    vstore16(vload16(0, col + base * 4), 0, out);
    return;
  }
  const float4 r = vload4(0, coc + base);
  /* a mixed edge pixel among the 4 (dof_mixed; none in the half-resolution gather): they
     are gathered twice, as their far and as their near part (the table must serve both
     radii; a dense table's gather, not the half-resolution result, where one of them is
     mixed) */
  const float4 am = mtiles_x > 0 ? vload4(0, mixa + base) : (float4)(0.0f);
  const int4 sm = am > 0.0f;
  const int split = any(sm);
  float4 rn = r, rf = r;
  if(split)
  {
    const float8 rr = vload8(0, mixr + base * 2);   /* read where mixa > 0 only */
    rn = select(r, rr.s0246, sm);
    rf = select(r, rr.s1357, sm);
  }
  int first = info.s0, count = info.s1, counts = info.s9, counts_n = info.sa;
  const float near_r = as_float(info.s8);
  /* a mixed pixel among the 4 is gathered twice with a dense table serving both its radii:
     the sharp one if both are in focus or nearly, else the full one; otherwise (a sparse
     table) as any pixel, at its own radius */
  int twice = 0;
  if(split && all(fmin(rn, rf) >= -NEAR_EPS && fmax(rn, rf) < sharp_r) && info.s6 == 0)
  {
    first = info.s2;
    count = info.s3;
    counts = info.sb;
    counts_n = info.sc;
    twice = 1;
  }
  else if(split && info.s5 == 0)
    twice = 1;
  else if(all(r >= -NEAR_EPS && r < sharp_r))
  {
    first = info.s2;
    count = info.s3;
    counts = info.sb;
    counts_n = info.sc;
  }
  else if((info.s4 & 1) && all(fabs(r) >= low_r))
  {
    float lmin = INFINITY, lmax = -INFINITY;
    const float16 up = dof_upsample4(hres, hpitch, hwidth, hheight, hplace.s0, hplace.s1, x,
                                     y, tile_info, tiles_x, tiles_y, tile, &lmin, &lmax);
    /* log(1 + max) - log(1 + min): the contrast an eye (and the log error) sees; the
       logarithm only where the ratio lies within 1e-4 of exp(refine) (refine.s12: below
       and above; the same test elsewhere, without a logarithm per group) */
    const float ratio = (1.0f + fmax(lmax, 0.0f)) / (1.0f + fmax(lmin, 0.0f));
    if(!(info.s4 & 2) || ratio <= refine.s1
       || (!(ratio > refine.s2) && native_log(ratio) <= refine.s0))
    {
      vstore16(up, 0, out);
      return;
    }
  }
  /* mixed edge pixels within the reach of the tile's table (info.s7, px; the flag tiles
     of the buffer's image, clamped to it as the padding is): a dense table's taps split
     them (a pixel's own mixed flag lies within reach: `mix` is set wherever `am` is) */
  int mix = 0;
  if(mtiles_x > 0)
  {
    const int bx = x - place.s2, by = y - place.s3, rch = info.s7;
    const int fx0 = clfx_clampi(max(bx - rch, 0) / MIX_TILE, 0, mtiles_x - 1);
    const int fx1 = clfx_clampi((bx + 3 + rch) / MIX_TILE, 0, mtiles_x - 1);
    const int fy0 = clfx_clampi(max(by - rch, 0) / MIX_TILE, 0, mtiles_y - 1);
    const int fy1 = clfx_clampi((by + rch) / MIX_TILE, 0, mtiles_y - 1);
    for(int fy = fy0; fy <= fy1 && !mix; fy++)
      for(int fx = fx0; fx <= fx1; fx++) mix |= mflags[fy * mtiles_x + fx];
  }
  /* the cap of hidden background: read only where a pixel lies in front of the focus plane */
  const float cap = clfx_any4(fmin(r, fmin(rn, rf)) < -NEAR_EPS)
                    ? dof_cap(log_mean, tx, ty, tiles_x, tiles_y, cap_factor) : 0.0f;
#if DOF_CATEYE
  const float4 ce_x = cateye.s0 * ((float)x + (float4)(0.5f, 1.5f, 2.5f, 3.5f)) + cateye.s1;
  const float4 ce_y = (float4)(cateye.s2 * ((float)y + 0.5f) + cateye.s3);
  /* the open fraction of the unit aperture clipped by a unit circle d away:
     (2 acos(d/2) - d/2 sqrt(4 - d^2)) / pi; two circles on a line through the aperture's
     centre, on either side of it: their intersection lies inside it, d their distance */
#if DOF_CATEYE >= 2
  const float4 cf_x = cateye.s4 * ((float)x + (float4)(0.5f, 1.5f, 2.5f, 3.5f)) + cateye.s5;
  const float4 cf_y = (float4)(cateye.s6 * ((float)y + 0.5f) + cateye.s7);
  const float4 d = fmin(sqrt((ce_x - cf_x) * (ce_x - cf_x) + (ce_y - cf_y) * (ce_y - cf_y)),
                        2.0f);
#else
  const float4 d = fmin(sqrt(ce_x * ce_x + ce_y * ce_y), 2.0f);
#endif
  const float4 ce_frac = fmax((2.0f * acos(0.5f * d) - 0.5f * d * sqrt(4.0f - d * d))
                              * (1.0f / CLFX_PI), CATEYE_MIN_FRAC);
#endif
  /* rows are padded to 4 pixels: the lanes past the width land in the padding */
  /* each tap reads the plane of its lattice level; mixed pixels are split over the image's
     own pixels: level-0 taps only */
  const float16 c0 = vload16(0, col + base * 4);
  if(!twice)
  {
    float16 o = dof_gather_safe(col, coc, ppitch, plane, base, c0, r, taps, taps_n4, first,
                                dof_tap_count(tile_info, counts, counts_n, near_r, r, count),
                                cap, mixa, mixr, mixd, mix, 0 CATEYE_PASS);
    /* pixels in focus or nearly beside out-of-focus ones in a sparse table's group: a
       lattice's far field would give them their own pixel through its prefilter tent (an
       in-focus edge against a 41 px background went soft 2^L px deep); they take the sharp
       table's gather (every pixel within sharp_r), as a group of 4 such pixels does */
    const int4 sharp4 = r >= -NEAR_EPS && r < sharp_r;
    if(info.s5 > 0 && first == info.s0 && any(sharp4))
      o = select(o, dof_gather_safe(col, coc, ppitch, plane, base, c0, r, taps, taps_n4, info.s2,
                                    dof_tap_count(tile_info, info.sb, info.sc, near_r, r,
                                                  info.s3),
                                    cap, mixa, mixr, mixd, mix, 0 CATEYE_PASS),
                 LANES(sharp4));
    vstore16(o, 0, out);
    return;
  }
  /* a mixed pixel: its far part's gather (at the far layer's radius) and its near part's,
     blended by its coverage */
  const float16 dm = vload16(0, mixd + base * 4);
  const int16 sm16 = LANES(sm);
  const float16 o_far = dof_gather_safe(col, coc, ppitch, plane, base,
                                        select(c0, c0 - dm * LANES(am), sm16), rf, taps, taps_n4,
                                        first,
                                        dof_tap_count(tile_info, counts, counts_n, near_r, rf,
                                                      count),
                                        cap, mixa, mixr, mixd, 1, 1 CATEYE_PASS);
  const float16 o_near = dof_gather_safe(col, coc, ppitch, plane, base,
                                         select(c0, c0 + dm * LANES(1.0f - am), sm16), rn,
                                         taps, taps_n4, first,
                                         dof_tap_count(tile_info, counts, counts_n, near_r, rn,
                                                       count), cap, mixa, mixr, mixd, 1, 2
                                         CATEYE_PASS);
  vstore16(select(o_far, o_far * LANES(1.0f - am) + o_near * LANES(am), sm16), 0, out);
}

/* Axial chromatic aberration: red, green and blue from the gathers of their own radius
 * offsets (`r`, `g`, `b` may be the same buffer), alpha from green's. */
kernel void dof_merge_channels(global const float *r, global const float *g,
                               global const float *b, global float *dst, const int pitch,
                               const int width, const int height)
{
  const int x = get_global_id(0), y = get_global_id(1);
  if(x >= width || y >= height) return;
  const int i = (y * pitch + x) * 4;
  vstore4((float4)(r[i], g[i + 1], b[i + 2], g[i + 3]), 0, dst + i);
}
