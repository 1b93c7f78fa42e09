/* motion.cl: motion blur reconstructed from a velocity pass (clfx/fx/motion.py; used by
 * clfx/plugins/motion_blur.py and the trucking of clfx/plugins/camera_blur.py).
 *
 * Passes (McGuire et al. 2012, with the tile classification of Jimenez 2014):
 *   motion_prepare           per 4 pixels: velocity sanitised (non-finite -> 0) and clamped to
 *                            the maximum speed VMAX, depth sanitised (invalid -> BIG_DEPTH);
 *                            writes aux = (vx, vy, z, |v|) per pixel
 *   motion_dilate            per 4 pixels, with a depth pass: an antialiased rim pixel of a
 *                            small bright surface in front (a light) takes its motion (quads
 *                            with nothing in front around them are copied)
 *   motion_sanitize          per 4 pixels: non-finite colour components -> 0 (only when the
 *                            analysis counted some)
 *   motion_tilemax           per K x K tile: the velocity of largest magnitude, the depth range
 *   motion_neighbormax       per tile: the largest over the 3 x 3 neighbouring tiles
 *   motion_gather            per 4 pixels of the *moving* tiles only (compact tile lists built
 *                            on the host): N samples along the neighbourhood's dominant
 *                            velocity, depth-aware scatter-as-gather weights; built with
 *                            CUBIC=1 for the short tiles (clamped cubic / tent reads; under
 *                            3/8 px of own smear the closed form mb_short_smear instead;
 *                            under 1.5 px the step model mb_step_smear, by its stepness)
 *
 * Sample model of the gather (see clfx/fx/motion.py): the output pixel x collects the
 * colours of samples y_i = x - v_n t_i, t_i stratified over the open shutter [t0, t1] at the
 * midpoints, or with one per-pixel jitter (interleaved gradient noise) in tiles whose samples
 * are sparse (a per-tile flag).  Sample y covers x if x lies on y's smear
 * y + v_y [t0, t1]; its weight is (source length per sample) x (y's smear density at x).
 * Samples in front of x (soft depth test) occlude x; samples at x's depth or behind it form
 * the layer seen through the gaps (Jimenez's foreground / background split).
 * With CURVED (both halves of the vector pass: forward f and backward b motion per pixel in a
 * second aux record, aux_b = (bx, by, z, |b|)), a point's displacement at time t is the
 * circular arc through its positions one frame before, at and after the frame time, at a
 * constant turn rate (MB_ARC; the quadratic t (f + b) / 2 + t^2 (f - b) / 2 on straight
 * paths, where the turn rate is 0): x's own surface is sampled where x's
 * path was at -t, x + d(-t) (exact for a steady flow such as a turn), occluders along the
 * tile's dominant path, x - d_n(t) (a small object carried along one path), and a sample's
 * smear covers x where its own path passes within a pixel of x.
 * The gather accumulates in REAL (lib/precision.h: double where the level asks for fp64).
 */
#include "lib/arc.h"
#include "lib/motion_gather.h"
#include "lib/precision.h"
#ifndef HAS_DEPTH
#define HAS_DEPTH 1
#endif

#ifndef CUBIC
#define CUBIC 0             /* colour fetches: clamped Catmull-Rom (short blurs) or lib/motion_gather.h's */
#endif
#ifndef MIN_BLUR
#define MIN_BLUR 0.1f       /* px: a smear shorter than this is no motion (clfx/fx/motion.py) */
#endif

#ifndef CURVED
#define CURVED 0            /* 1: a backward motion pass too (aux_b): paths are quadratics */
#endif

/* the gather's pieces, inlined: the first pass of motion_gather runs them with scale 1, which
 * then folds away (x * 1 is x exactly) */
#define MB_INLINE CLFX_INLINE

#define BIG_DEPTH 1e30f     /* sanitised "no surface / invalid depth": behind everything */
#define SOFT_Z 0.02f        /* relative depth difference over which "in front" fades in */
#define MIN_SPEED 1e-3f     /* below this (px/frame) a pixel counts as static */

/* --- preparation ------------------------------------------------------------------------ */
kernel void motion_prepare(global const float *vel, global const float *depth,
                           global float *aux, const int pitch, const int height,
                           const float vmax)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= height || qx * 4 >= pitch) return;
  const int i = y * pitch + qx * 4;
  const float8 v8 = vload8(0, vel + 2 * i);
  float4 vx = v8.even, vy = v8.odd;
  const int4 ok = ((as_int4(vx) & 0x7f800000) != 0x7f800000) &
                  ((as_int4(vy) & 0x7f800000) != 0x7f800000);
  /* clamp components first so the squares cannot overflow (1e30 px/frame stays finite) */
  vx = select((float4)(0.0f), clamp(vx, -1e6f, 1e6f), ok);
  vy = select((float4)(0.0f), clamp(vy, -1e6f, 1e6f), ok);
  float4 s = sqrt(vx * vx + vy * vy);
  const float4 scale = select((float4)(1.0f), vmax / s, s > vmax);  /* reach <= tile radius */
  vx *= scale; vy *= scale; s = fmin(s, vmax);
#if HAS_DEPTH
  float4 z = vload4(0, depth + i);
  z = select((float4)(BIG_DEPTH), z, (z > 0.0f) & (z < BIG_DEPTH));  /* NaN, <= 0, +inf */
#else
  const float4 z = (float4)(1.0f);
#endif
  vstore16((float16)(vx.x, vy.x, z.x, s.x, vx.y, vy.y, z.y, s.y,
                     vx.z, vy.z, z.z, s.z, vx.w, vy.w, z.w, s.w), 0, aux + 4 * i);
}

/* Renderers write the beauty filtered over the pixel but velocity and depth from the surface
 * at its centre: the rim pixels of a small moving light carry the background's (zero)
 * velocity though most of their light is the light's, which then stays behind as a static
 * ring instead of streaking.  A pixel p takes the velocity and depth of its nearest 3 x 3
 * neighbour q when q is in front of p and moves differently, and p's colour is mostly q's:
 * p is more than DILATE_RATIO times brighter than the neighbour b on its other side
 * (p - (q - p), at p's depth or behind: p's background) and darker than q (a mixture of
 * the two).  Only light-on-dark edges pass this test (a ratio of 10 needs an HDR or very
 * bright surface over a dark one); ordinary texture edges keep their centre sample. */
#ifndef DILATE_RATIO
#define DILATE_RATIO 10.0f
#endif
kernel void motion_dilate(global const float *aux, global const float *col, global float *out,
                          const int pitch, const int width, const int height,
                          const float duration
#if CURVED
                          , global const float *auxb, global float *outb
#endif
                          )
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= height || qx * 4 >= pitch) return;
  const int x = qx * 4, i = y * pitch + x;
  float16 own = vload16(0, aux + 4 * i);
#if CURVED
  float16 ownb = vload16(0, auxb + 4 * i);   /* the backward records follow the same choices */
#endif
  const float4 ax = own.s048c, ay = own.s159d, az = own.s26ae;
  float4 bz = az * (1.0f - SOFT_Z);
  /* the common case: no record of the 3 x 6 around the quad (columns x-1 .. x+4, rows and
   * the outer columns clamped, the quad's own columns read up to the pitch, which
   * motion_prepare fills) lies in front of any of the 4 pixels (each neighbour's test below
   * needs qz < bz): the records stay as they are */
  {
    const int up = clfx_clampi(y - 1, 0, height - 1) * pitch, row = y * pitch;
    const int down = clfx_clampi(y + 1, 0, height - 1) * pitch;
    const int xl = clfx_clampi(x - 1, 0, width - 1), xr = clfx_clampi(x + 4, 0, width - 1);
    const float4 zq = fmin(fmin(vload16(0, aux + 4 * (up + x)).s26ae,
                                vload16(0, aux + 4 * (down + x)).s26ae), az);
    const float4 ze = fmin((float4)(aux[4 * (up + xl) + 2], aux[4 * (row + xl) + 2],
                                    aux[4 * (down + xl) + 2], aux[4 * (up + xr) + 2]),
                           (float4)(aux[4 * (row + xr) + 2], aux[4 * (down + xr) + 2],
                                    INFINITY, INFINITY));
    const float4 zlo = fmin(zq, ze);
    const float2 zlo2 = fmin(zlo.xy, zlo.zw), bz2 = fmax(bz.xy, bz.zw);
    if(fmin(zlo2.x, zlo2.y) >= fmax(bz2.x, bz2.y))
    {
      vstore16(own, 0, out + 4 * i);
#if CURVED
      vstore16(ownb, 0, outb + 4 * i);
#endif
      return;
    }
  }
  float vx[3][6], vy[3][6], z[3][6];
  for(int r = 0; r < 3; r++)
  {
    const int row = clfx_clampi(y + r - 1, 0, height - 1) * pitch;
    const float4 ql = vload4(row + clfx_clampi(x - 1, 0, width - 1), aux);
    const float16 qm = vload16(0, aux + 4 * (row + x));
    const float4 qr = vload4(row + clfx_clampi(x + 4, 0, width - 1), aux);
    vx[r][0] = ql.x; vy[r][0] = ql.y; z[r][0] = ql.z;
    vx[r][1] = qm.s0; vy[r][1] = qm.s1; z[r][1] = qm.s2;
    vx[r][2] = qm.s4; vy[r][2] = qm.s5; z[r][2] = qm.s6;
    vx[r][3] = qm.s8; vy[r][3] = qm.s9; z[r][3] = qm.sa;
    vx[r][4] = qm.sc; vy[r][4] = qm.sd; z[r][4] = qm.se;
    vx[r][5] = qr.x; vy[r][5] = qr.y; z[r][5] = qr.z;
  }
  const float4 lanex = (float4)(x) + (float4)(0.0f, 1.0f, 2.0f, 3.0f);
  int4 bdx = (int4)(0), bdy = (int4)(0);
  for(int dy = -1; dy <= 1; dy++)
    for(int dx = -1; dx <= 1; dx++)
    {
      if(dx == 0 && dy == 0) continue;
      const int r = dy + 1;
      const float4 qz = (float4)(z[r][dx + 1], z[r][dx + 2], z[r][dx + 3], z[r][dx + 4]);
      const float4 qvx = (float4)(vx[r][dx + 1], vx[r][dx + 2], vx[r][dx + 3], vx[r][dx + 4]);
      const float4 qvy = (float4)(vy[r][dx + 1], vy[r][dx + 2], vy[r][dx + 3], vy[r][dx + 4]);
      const float4 ex = qvx - ax, ey = qvy - ay;
      const int4 inside = (lanex + (float)dx >= 0.0f) & (lanex + (float)dx < (float)width) &
                          (int4)(-(int)(y + dy >= 0 && y + dy < height));
      const int4 take = inside & (qz < bz) &
                        (sqrt(ex * ex + ey * ey) * duration >= MIN_BLUR);
      bz = select(bz, qz, take);
      bdx = select(bdx, (int4)(dx), take);
      bdy = select(bdy, (int4)(dy), take);
    }
  if(clfx_any4((bdx | bdy) != 0))   /* rare: a nearer moving neighbour; test the colours */
  {
    float a16[16];
    vstore16(own, 0, a16);
#if CURVED
    float b16[16];
    vstore16(ownb, 0, b16);
#endif
    for(int l = 0; l < 4; l++)
    {
      const int dx = l == 0 ? bdx.x : l == 1 ? bdx.y : l == 2 ? bdx.z : bdx.w;
      const int dy = l == 0 ? bdy.x : l == 1 ? bdy.y : l == 2 ? bdy.z : bdy.w;
      const int px = x + l;
      const int ox = px - dx, oy = y - dy;
      if(!(dx | dy) || px >= width || ox < 0 || oy < 0 || ox >= width || oy >= height) continue;
      const float4 b = vload4(oy * pitch + ox, aux);
      const float lp = dot(vload4(i + l, col).xyz, (float3)(1.0f));
      const float lb = dot(vload4(oy * pitch + ox, col).xyz, (float3)(1.0f));
      const int q = (y + dy) * pitch + px + dx;
      const float lq = dot(vload4(q, col).xyz, (float3)(1.0f));
      if(b.z >= a16[4 * l + 2] * (1.0f - SOFT_Z) && lp - lb > DILATE_RATIO * fmax(lb, 0.0f) &&
         lq > lp)
      {
        vstore4(vload4(q, aux), l, a16);
#if CURVED
        vstore4(vload4(q, auxb), l, b16);
#endif
      }
    }
    own = vload16(0, a16);
#if CURVED
    ownb = vload16(0, b16);
#endif
  }
  vstore16(own, 0, out + 4 * i);
#if CURVED
  vstore16(ownb, 0, outb + 4 * i);
#endif
}

kernel void motion_sanitize(global const float *src, global float *dst, const int pitch,
                            const int height)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= height || qx * 4 >= pitch) return;
  const int i = (y * pitch + qx * 4) * 4;
  vstore16(clfx_finite16_or_zero(vload16(0, src + i)), 0, dst + i);
}

/* --- tile classification ---------------------------------------------------------------- */
/* Tiles lie on a grid of K x K pixels from the canvas's origin (the whole render's window,
 * whatever part of it `aux` holds: canvas rows from row0 on, CLFX_CANVAS_ROWS); this launch
 * computes the tile rows from ty0 on, whose pixel rows the buffer holds.  A record: (vx, vy,
 * |v|, 0) of the tile's fastest pixel (the first in scan order among equals), and in `tiles_b` its
 * backward motion (bx, by) from `auxb` (CURVED; else unused); in `zrange` the (smallest,
 * largest) depth of the tile's pixels (the host's front-free test, motion_gather). */
kernel void motion_tilemax(global const float *aux, global const float *auxb,
                           global float *tiles, global float *tiles_b, global float *zrange,
                           const int pitch, const int width, const int height,
                           const int row0, const int tiles_x, const int tiles_y,
                           const int ty0, const int k)
{
  const int tx = get_global_id(0), ty = ty0 + get_global_id(1);
  if(tx >= tiles_x || ty >= tiles_y) return;
  CLFX_CANVAS_ROWS(aux, pitch, 4, row0);
  const int x0 = tx * k, y0 = ty * k;
  const int x1 = min(x0 + k, width), y1 = min(y0 + k, height);
  /* the fastest pixel: the largest |v| (over 0), the first in scan order among equals, i.e.
   * the smallest index; 4 columns at a time (lane l: the columns x0 + l mod 4, each lane's
   * first maximum), the columns past the last whole 4 (the image's right edge) one by one */
  const int xq = x0 + ((x1 - x0) & ~3);
  float4 lw = (float4)(0.0f), zlo4 = (float4)(INFINITY), zhi4 = (float4)(-INFINITY);
  int4 lat = (int4)(-1);
  float tw = 0.0f;
  int tat = -1;
  for(int y = y0; y < y1; y++)
  {
    for(int x = x0; x < xq; x += 4)
    {
      const float16 a = vload16(0, aux + 4 * ((size_t)y * pitch + x));
      const int4 take = a.s37bf > lw;
      lw = select(lw, a.s37bf, take);
      lat = select(lat, (int4)(y * pitch + x) + (int4)(0, 1, 2, 3), take);
      zlo4 = fmin(zlo4, a.s26ae);
      zhi4 = fmax(zhi4, a.s26ae);
    }
    for(int x = xq; x < x1; x++)
    {
      const float4 a = vload4((size_t)y * pitch + x, aux);
      if(a.w > tw) { tw = a.w; tat = y * pitch + x; }
      zlo4.x = fmin(zlo4.x, a.z);
      zhi4.x = fmax(zhi4.x, a.z);
    }
  }
  float bw = tw;
  int at = tat;
  for(int l = 0; l < 4; l++)
  {
    const float w = l == 0 ? lw.x : l == 1 ? lw.y : l == 2 ? lw.z : lw.w;
    const int i = l == 0 ? lat.x : l == 1 ? lat.y : l == 2 ? lat.z : lat.w;
    if(w > bw || (w == bw && i >= 0 && i < at)) { bw = w; at = i; }
  }
  const float4 a = at >= 0 ? vload4((size_t)at, aux) : (float4)(0.0f);
  vstore4((float4)(a.x, a.y, a.w, 0.0f), ty * tiles_x + tx, tiles);
  vstore2((float2)(fmin(fmin(zlo4.x, zlo4.y), fmin(zlo4.z, zlo4.w)),
                   fmax(fmax(zhi4.x, zhi4.y), fmax(zhi4.z, zhi4.w))), ty * tiles_x + tx, zrange);
#if CURVED
  CLFX_CANVAS_ROWS(auxb, pitch, 4, row0);
  vstore2(at >= 0 ? vload2(0, auxb + 4 * (size_t)at) : (float2)(0.0f), ty * tiles_x + tx,
          tiles_b);
#endif
}

kernel void motion_neighbormax(global const float *tiles, global const float *tiles_b,
                               global float *nmax, global float *nmax_b, const int tiles_x,
                               const int tiles_y)
{
  const int tx = get_global_id(0), ty = get_global_id(1);
  if(tx >= tiles_x || ty >= tiles_y) return;
  float4 best = (float4)(0.0f);
  int at = -1;
  for(int dy = -1; dy <= 1; dy++)
    for(int dx = -1; dx <= 1; dx++)
    {
      const int x = tx + dx, y = ty + dy;
      if(x < 0 || y < 0 || x >= tiles_x || y >= tiles_y) continue;
      const float4 t = vload4(y * tiles_x + x, tiles);
      if(t.z > best.z) { best = t; at = y * tiles_x + x; }
    }
  vstore4(best, ty * tiles_x + tx, nmax);
#if CURVED
  vstore2(at >= 0 ? vload2(at, tiles_b) : (float2)(0.0f), ty * tiles_x + tx, nmax_b);
#endif
}

/* --- gather ----------------------------------------------------------------------------- */
/* Displacement at time t (frames) of a point moving with forward f and backward b (px/frame):
 * the circular arc through -b (t = -1), 0 and f (t = 1) at a constant turn rate w (mb_turn),
 * lib/arc.h.  MB_ARC_TANGENT: its time derivative.  Per component (x and y share w). */
inline float4 mb_turn(const float4 fx, const float4 fy, const float4 bx, const float4 by)
{
  return ARC_TURN(float4, fx + bx, fy + by, fx - bx, fy - by);
}
#define MB_CURVED(w) ((w) > (float4)(ARC_MIN_TURN))
inline float4 mb_arc_a(const float4 t, const float4 w)
{ return select(t, ARC_A(float4, t, w), MB_CURVED(w)); }
inline float4 mb_arc_c(const float4 t, const float4 w)
{ const float4 r = ARC_R(float4, t, w); return select(t * t, r * r, MB_CURVED(w)); }
inline float4 mb_arc_da(const float4 t, const float4 w)
{ return select((float4)(1.0f), ARC_DA(float4, t, w), MB_CURVED(w)); }
inline float4 mb_arc_dc(const float4 t, const float4 w)
{ return select(2.0f * t, ARC_DC(float4, t, w), MB_CURVED(w)); }
#define MB_ARC(f, b, t, w) ARC_PATH(float4, mb_arc_a(t, w), mb_arc_c(t, w), (f) + (b), (f) - (b))
#define MB_ARC_TANGENT(f, b, t, w) \
  (mb_arc_da(t, w) * 0.5f * ((f) + (b)) + mb_arc_dc(t, w) * 0.5f * ((f) - (b)))
#define SPLAT16I(m) (int16)((m).xxxx, (m).yyyy, (m).zzzz, (m).wwww)   /* a lane mask */

/* Load the aux records of 4 sample positions (nearest pixel) as vectors. */
#define MB_LOAD_AUX(ix, iy, VX, VY, Z, S) \
  { const int4 idx_ = (iy) * pitch + (ix); \
    const float4 a0_ = vload4(idx_.x, aux), a1_ = vload4(idx_.y, aux); \
    const float4 a2_ = vload4(idx_.z, aux), a3_ = vload4(idx_.w, aux); \
    VX = (float4)(a0_.x, a1_.x, a2_.x, a3_.x); VY = (float4)(a0_.y, a1_.y, a2_.y, a3_.y); \
    Z = (float4)(a0_.z, a1_.z, a2_.z, a3_.z); S = (float4)(a0_.w, a1_.w, a2_.w, a3_.w); }

/* The same from the backward records (CURVED) */
#define MB_LOAD_AUXB(ix, iy, VX, VY, Z, S) \
  { global const float *aux = auxb; MB_LOAD_AUX(ix, iy, VX, VY, Z, S) }

/* Weights of the 4 taps around a sample at fraction a in [0, 1): Catmull-Rom blended with
 * the linear tent by 1 - beta (see mb_beta). */
inline float4 mb_cubic_weights(const float a, const float beta)
{
  const float a2 = a * a, a3 = a2 * a;
  const float4 cr = (float4)(-0.5f * a3 + a2 - 0.5f * a, 1.5f * a3 - 2.5f * a2 + 1.0f,
                             -1.5f * a3 + 2.0f * a2 + 0.5f * a, 0.5f * a3 - 0.5f * a2);
  const float4 lin = (float4)(0.0f, 1.0f - a, a, 0.0f);
  return lin + (cr - lin) * beta;
}

/* How much of the Catmull-Rom a smear of `len` px wants (against the tent): rendered images
 * are box-filtered, piecewise linear between sub-pixel edges; over a smear up to ~3/8 px
 * those kinks dominate what changes on blocky texture and the tent follows them best (the
 * layers wall at 270 degrees: 1.8 dB better than the cubic), while from half a pixel on the
 * cubic wins everywhere: the tent's own blur at a sample a quarter pixel off (variance
 * a (1 - a)) is ~6x the motion's over a half-pixel smear, which flattened fine stripes and
 * grain moving 1 px/frame 2-8 dB below the unblurred input (issue 24; the ramp used to
 * reach the full cubic only at a whole pixel). */
#define MB_BETA(len) clamp(((len) - 0.375f) * 8.0f, 0.0f, 1.0f)    /* float or float4 */
inline float mb_beta(const float len)
{
  return MB_BETA(len);
}

/* Sub-pixel smears (issue 24): the closed form that replaces the gather's own-surface average
 * where mb_beta leaves the tent (weight 1 - mb_beta, centred shutters only).  Along the unit
 * direction u of the pixel's path, with p_k the colour at x + k u (bilinear, k = -2..2) and
 * L the smear length, a box of length L < 1 changes a pixel by
 *   c (p_-1 + p_1 - 2 p_0),  c = L^2 / SHORT_SMOOTH  ... L / 8
 * L^2 / 24 for a smooth image, about L^2 / 10 at the Nyquist frequency (1 - sinc(pi L / 2)
 * of a sampled cosine), L / 8 for an edge on a pixel boundary (the tent's own response,
 * exact there).  c is L^2 / SHORT_SMOOTH unless the samples alternate along u (p_-1 = p_1
 * and p_0 repeats at p_-2 or p_2, within SHORT_KAPPA of the second difference): there the
 * samples cannot say where the edges lie inside the pixels, and the tent's L / 8 is the
 * expected response of edges anywhere between the renderer's sub-samples (the blocky walls
 * of the layered bench: L^2 / 12 alone ends 2 dB below the tent on its wall at 270 deg).
 * A flat field stays flat;
 * with one coefficient along a row the row's sum is kept (the alternation switch moves a
 * little light between pixels).
 * These closed forms run on a quad's 4 pixels at once (mb_short_quad): colours as float16,
 * lane-major RGBA x 4, a lane's scalars splatted over its RGBA (SPLAT16); per element the
 * same float maths as one pixel's. */
#define SHORT_SMOOTH 16.0f
#define SHORT_KAPPA 0.05f
inline float16 mb_short_smear(const float16 pm2, const float16 pm1, const float16 p0,
                              const float16 pp1, const float16 pp2, const float16 len)
{
  const float16 d2 = pm1 + pp1 - 2.0f * p0;
  const float16 e = fabs(pm1 - pp1) + fmin(fabs(pm2 - p0), fabs(pp2 - p0));
  const float16 alt = clamp(1.0f - e / fmax(SHORT_KAPPA * fabs(d2), FLT_MIN), 0.0f, 1.0f);
  const float16 smooth = len * len / SHORT_SMOOTH;
  return p0 + (smooth + alt * (0.125f * len - smooth)) * d2;
}

/* Step edges under a sub-pixel smear (issue 35).  A renderer's pixel is the box average of
 * the scene over it; where a texture is made of flat patches with hard edges (a checker, a
 * printed card), a pixel between two different neighbours along the motion holds an edge whose
 * place inside it its value gives (the fraction of each side), and a pixel equal to a
 * neighbour lies on a plateau.  Moving such a row of cell averages by tau < 1 px is the
 * advection of finite-volume schemes; with each cell rebuilt as a step between its neighbours
 * (SLIC, Noh & Woodward 1976: monotone cells, the step placed so that the cell keeps its
 * average; extrema stay flat) the smear of a box-filtered edge is exact wherever it lies in
 * the pixel: an edge on a pixel boundary spreads by the tent's L / 8, one in the middle of a
 * pixel stays inside it.  The linear fetches cannot tell the two apart (a 2-3 px checker
 * drifting 1.7 px/frame: the cubic ended 4-5 dB below the truth, the naive bilinear line
 * blur exact only on pixel-aligned edges).
 *
 * mb_step_mean: the mean over [a, b] (cell coordinates, -1/2 .. 1/2) of the cumulative
 * integral G from the cell's left side of the step rebuilt from (pm, pk, pp). */
inline float16 mb_step_mean(const float16 pm, const float16 pk, const float16 pp,
                             const float16 a, const float16 b)
{
  const int16 mono = (pm - pk) * (pk - pp) > 0.0f;
  const float16 l = select(pk, pm, mono), r = select(pk, pp, mono);
  const float16 xe = select((float16)(0.0f),
                            (r - pk) / select((float16)(1.0f), r - l, mono) - 0.5f, mono);
  const float16 ra = fmax(a - xe, 0.0f), rb = fmax(b - xe, 0.0f);
  return (l * ((b + 0.5f) * (b + 0.5f) - (a + 0.5f) * (a + 0.5f)) * 0.5f
          + (r - l) * (rb * rb - ra * ra) * 0.5f) / (b - a);
}

/* The step model's smear of length len (centred shutter, len clamped to a pixel) of p0 with
 * the taps p-2 .. p2 along the motion: the mean over tau in [0, len / 2] of the cell shifted
 * by +tau (cell -1's right end enters) and by -tau (cell 1's left end). */
inline float16 mb_step_smear(const float16 pm2, const float16 pm1, const float16 p0,
                              const float16 pp1, const float16 pp2, const float16 len)
{
  const float16 h = 0.5f * fmin(len, 1.0f), c = (float16)(0.5f);
  const float16 plus = pm1 - mb_step_mean(pm2, pm1, p0, 0.5f - h, c)
                       + mb_step_mean(pm1, p0, pp1, 0.5f - h, c);
  const float16 minus = mb_step_mean(p0, pp1, pp2, -c, h - 0.5f) + p0
                        - mb_step_mean(pm1, p0, pp1, -c, h - 0.5f);
  return 0.5f * (plus + minus);
}

/* How much the taps look like flat patches with hard edges: 1 where the smallest step
 * between neighbouring taps (summed RGB) is under STEP_KAPPA of the largest (a plateau beside
 * an edge), 0 where every neighbour differs (smooth or pre-filtered texture: a camera's or
 * Cycles' wider pixel filter, where the step model over-sharpens) and where three steps in a
 * row go the same way by more than STEP_RAMP of the largest (a ramp: an edge slanted across
 * the axis, or a soft one, spans more than the one pixel a hard edge covers). */
#define STEP_KAPPA 0.001f
#define STEP_RAMP 0.1f
#define STEP_MAX_PX 1.5f    /* smears up to a pixel take the step model, fading out by 1.5 px */
#define MB_RGB_SUM(v) ((v).s048c + (v).s159d + (v).s26ae)  /* per lane: dot(rgb, 1) */
inline float4 mb_stepness(const float16 pm2, const float16 pm1, const float16 p0,
                          const float16 pp1, const float16 pp2)
{
  const float4 d0 = MB_RGB_SUM(pm1 - pm2), d1 = MB_RGB_SUM(p0 - pm1);
  const float4 d2 = MB_RGB_SUM(pp1 - p0), d3 = MB_RGB_SUM(pp2 - pp1);
  const float4 a0 = fabs(d0), a1 = fabs(d1), a2 = fabs(d2), a3 = fabs(d3);
  const float4 lo = fmin(fmin(a0, a1), fmin(a2, a3)), hi = fmax(fmax(a0, a1), fmax(a2, a3));
  const float4 s1 = select((float4)(-1.0f), (float4)(1.0f), d1 >= 0.0f);
  const float4 s2 = select((float4)(-1.0f), (float4)(1.0f), d2 >= 0.0f);
  const float4 ramp = fmax(fmin(fmin(s1 * d0, a1), s1 * d2), fmin(fmin(s2 * d1, a2), s2 * d3));
  /* flat taps (every step 0) have no ramp: 0 divided by STEP_RAMP there, not by the
   * subnormal STEP_RAMP * FLT_MIN (the same 0, but a subnormal product costs the CPU a
   * microcode assist: ~7 % of the short tiles' gather on the 1080p demo frame) */
  const float4 scale = fmax(hi, select((float4)(FLT_MIN), (float4)(1.0f), hi == 0.0f));
  return clamp(1.0f - lo / fmax(STEP_KAPPA * hi, FLT_MIN), 0.0f, 1.0f)
         * clamp(1.0f - fmax(ramp, 0.0f) / (STEP_RAMP * scale), 0.0f, 1.0f);
}

/* mb_fetch4_cubic at the 4 positions (px + k, py), k = 0..3, of a quad whose lanes share one
 * offset: the 4 x 7 pixels the lanes' taps cover are loaded once (28 loads, not 64) and the
 * weights computed once. */
MB_INLINE float16 mb_fetch_quad_cubic(global const float *col, const int pitch, const int w,
                                      const int row0, const int row1, const float px,
                                      const float py, const float scale, const float beta)
{
  const float u = px - 0.5f, v = py - 0.5f;
  const float fu = floor(u), fv = floor(v);
  const float4 wx = mb_cubic_weights(u - fu, beta), wy = mb_cubic_weights(v - fv, beta);
  const int iu = (int)clamp(fu, -8.0f, (float)w + 8.0f);
  const int iv = (int)clamp(fv, (float)(row0 - 2), (float)row1);
  const int x0 = clfx_clampi(iu - 1, 0, w - 1), x1 = clfx_clampi(iu, 0, w - 1);
  const int x2 = clfx_clampi(iu + 1, 0, w - 1), x3 = clfx_clampi(iu + 2, 0, w - 1);
  const int x4 = clfx_clampi(iu + 3, 0, w - 1), x5 = clfx_clampi(iu + 4, 0, w - 1);
  const int x6 = clfx_clampi(iu + 5, 0, w - 1);
  const int run = x0 == iu - 1 && x6 == iu + 5;   /* the 7 columns side by side */
  float16 acc = (float16)(0.0f), lo = (float16)(INFINITY), hi = (float16)(-INFINITY);
  for(int j = 0; j < 4; j++)
  {
    const int row = clfx_clampi(iv - 1 + j, row0, row1 - 1) * pitch;
    /* r_k: the taps k of the 4 lanes, (c_k, c_k+1, c_k+2, c_k+3) */
    float16 r0, r1, r2, r3;
    if(run)
    {
      global const float *p = col + 4 * (row + x0);
      r0 = vload16(0, p) * scale; r1 = vload16(0, p + 4) * scale;
      r2 = vload16(0, p + 8) * scale; r3 = vload16(0, p + 12) * scale;
    }
    else
    {
      const float4 c0 = vload4(row + x0, col) * scale, c1 = vload4(row + x1, col) * scale;
      const float4 c2 = vload4(row + x2, col) * scale, c3 = vload4(row + x3, col) * scale;
      const float4 c4 = vload4(row + x4, col) * scale, c5 = vload4(row + x5, col) * scale;
      const float4 c6 = vload4(row + x6, col) * scale;
      r0 = (float16)(c0, c1, c2, c3); r1 = (float16)(c1, c2, c3, c4);
      r2 = (float16)(c2, c3, c4, c5); r3 = (float16)(c3, c4, c5, c6);
    }
    if(j == 1 || j == 2)
    {
      lo = fmin(lo, fmin(r1, r2));
      hi = fmax(hi, fmax(r1, r2));
    }
    const float wj = j == 0 ? wy.x : j == 1 ? wy.y : j == 2 ? wy.z : wy.w;
    acc += wj * (wx.x * r0 + wx.y * r1 + wx.z * r2 + wx.w * r3);
  }
  return clamp(acc, lo, hi);
}

/* Bilinear (BILINEAR) or nearest at the 4 positions (px + k, py) of a quad sharing one
 * offset: 2 x 5 loads (4 for nearest), as mg_fetch_scaled per lane. */
MB_INLINE float16 mb_fetch_quad_linear(global const float *col, const int pitch, const int w,
                                       const int row0, const int row1, const float px,
                                       const float py, const float scale, const float beta)
{
#if BILINEAR
  const float u = px - 0.5f, v = py - 0.5f;
  const float fu = floor(u), fv = floor(v);
  const float ax = u - fu, ay = v - fv;
  const int iu = (int)clamp(fu, -8.0f, (float)w + 8.0f);
  const int iv = (int)clamp(fv, (float)(row0 - 1), (float)row1);
  const int ya = clfx_clampi(iv, row0, row1 - 1) * pitch;
  const int yb = clfx_clampi(iv + 1, row0, row1 - 1) * pitch;
  const int x0 = clfx_clampi(iu, 0, w - 1), x1 = clfx_clampi(iu + 1, 0, w - 1);
  const int x2 = clfx_clampi(iu + 2, 0, w - 1), x3 = clfx_clampi(iu + 3, 0, w - 1);
  const int x4 = clfx_clampi(iu + 4, 0, w - 1);
  float16 top, top1, bot, bot1;
  if(x0 == iu && x4 == iu + 4)   /* the 5 columns side by side: runs of the two rows */
  {
    top = vload16(0, col + 4 * (ya + x0)) * scale;
    top1 = vload16(0, col + 4 * (ya + x1)) * scale;
    bot = vload16(0, col + 4 * (yb + x0)) * scale;
    bot1 = vload16(0, col + 4 * (yb + x1)) * scale;
  }
  else
  {
    const float4 t0 = vload4(ya + x0, col) * scale, t1 = vload4(ya + x1, col) * scale;
    const float4 t2 = vload4(ya + x2, col) * scale, t3 = vload4(ya + x3, col) * scale;
    const float4 t4 = vload4(ya + x4, col) * scale;
    const float4 b0 = vload4(yb + x0, col) * scale, b1 = vload4(yb + x1, col) * scale;
    const float4 b2 = vload4(yb + x2, col) * scale, b3 = vload4(yb + x3, col) * scale;
    const float4 b4 = vload4(yb + x4, col) * scale;
    top = (float16)(t0, t1, t2, t3); top1 = (float16)(t1, t2, t3, t4);
    bot = (float16)(b0, b1, b2, b3); bot1 = (float16)(b1, b2, b3, b4);
  }
  const float16 tt = top + (top1 - top) * ax, bb = bot + (bot1 - bot) * ax;
  return tt + (bb - tt) * ay;
#else
  const int x = (int)clamp(floor(px), -8.0f, (float)w + 8.0f);
  const int row = (int)clamp(floor(py), (float)row0, (float)(row1 - 1)) * pitch;
  return (float16)(vload4(row + clfx_clampi(x, 0, w - 1), col) * scale,
                   vload4(row + clfx_clampi(x + 1, 0, w - 1), col) * scale,
                   vload4(row + clfx_clampi(x + 2, 0, w - 1), col) * scale,
                   vload4(row + clfx_clampi(x + 3, 0, w - 1), col) * scale);
#endif
}

/* Colours at the 4 lanes' own continuous positions (px, py), clamp-to-edge, times `scale`:
 * Catmull-Rom (4 x 4 taps, blended with the tent by `beta`, mb_cubic_weights) clamped per
 * channel to the 2 x 2 pixels around each position.  Short blurs integrate the image over
 * under a pixel or a few: bilinear reconstruction blurs every sample by up to a quarter pixel
 * more (as much again as a one-pixel smear), the cubic keeps the detail; the clamp stops its
 * negative lobes ringing around HDR lights.  The lanes' arithmetic in one float16, as
 * mg_fetch4_scaled. */
MB_INLINE float16 mb_fetch4_cubic(global const float *col, const int pitch, const int w,
                                  const int row0, const int row1, const float4 px, const float4 py,
                                  const float scale, const float4 beta)
{
  const float4 u = px - 0.5f, v = py - 0.5f;
  const float4 fu = floor(u), fv = floor(v);
  /* the taps' weights, tap k of the 4 lanes in wxk: mb_cubic_weights per lane, term for
   * term (lin + (cr - lin) beta, lin's zeros included) */
  const float4 a = u - fu, a2 = a * a, a3 = a2 * a;
  const float4 b = v - fv, b2 = b * b, b3 = b2 * b;
  const float4 wx0 = 0.0f + ((-0.5f * a3 + a2 - 0.5f * a) - 0.0f) * beta;
  const float4 wx1 = (1.0f - a) + ((1.5f * a3 - 2.5f * a2 + 1.0f) - (1.0f - a)) * beta;
  const float4 wx2 = a + ((-1.5f * a3 + 2.0f * a2 + 0.5f * a) - a) * beta;
  const float4 wx3 = 0.0f + ((0.5f * a3 - 0.5f * a2) - 0.0f) * beta;
  const float4 wy[4] = {0.0f + ((-0.5f * b3 + b2 - 0.5f * b) - 0.0f) * beta,
                        (1.0f - b) + ((1.5f * b3 - 2.5f * b2 + 1.0f) - (1.0f - b)) * beta,
                        b + ((-1.5f * b3 + 2.0f * b2 + 0.5f * b) - b) * beta,
                        0.0f + ((0.5f * b3 - 0.5f * b2) - 0.0f) * beta};
  const int4 iu = convert_int4(clamp(fu, -2.0f, (float)w));
  const int4 iv = convert_int4(clamp(fv, (float)(row0 - 2), (float)row1));
  const int4 lo_x = (int4)(0), hi_x = (int4)(w - 1);
  const int4 x0 = clamp(iu - 1, lo_x, hi_x), x1 = clamp(iu, lo_x, hi_x);
  const int4 x2 = clamp(iu + 1, lo_x, hi_x), x3 = clamp(iu + 2, lo_x, hi_x);
  float16 acc = (float16)(0.0f), lo = (float16)(INFINITY), hi = (float16)(-INFINITY);
  for(int j = 0; j < 4; j++)
  {
    const int4 row = clamp(iv - 1 + j, (int4)(row0), (int4)(row1 - 1)) * pitch;
    const float16 c0 = MG_GATHER4(col, row + x0, scale), c1 = MG_GATHER4(col, row + x1, scale);
    const float16 c2 = MG_GATHER4(col, row + x2, scale), c3 = MG_GATHER4(col, row + x3, scale);
    if(j == 1 || j == 2)
    {
      lo = fmin(lo, fmin(c1, c2));
      hi = fmax(hi, fmax(c1, c2));
    }
    acc += SPLAT16(wy[j]) * (SPLAT16(wx0) * c0 + SPLAT16(wx1) * c1 + SPLAT16(wx2) * c2
                             + SPLAT16(wx3) * c3);
  }
  return clamp(acc, lo, hi);
}

/* The pixels (r, c) of the 4 lanes, clamped to the rows held and the image: one vload16 where
 * they lie side by side in memory (a run of one row: the common case), else one per lane. */
MB_INLINE float16 mb_lanes(global const float *buf, const int pitch, const int w, const int row0,
                           const int row1, const int4 r, const int4 c)
{
  /* vector bounds: Oclgrind misread clamp(int4, int, int) (reads off the buffer) */
  const int4 i = clamp(r, (int4)(row0), (int4)(row1 - 1)) * pitch
                 + clamp(c, (int4)(0), (int4)(w - 1));
  if(clfx_all4(i - i.x == (int4)(0, 1, 2, 3)))
    return vload16(0, buf + 4 * i.x);
  return (float16)(vload4(i.x, buf), vload4(i.y, buf), vload4(i.z, buf), vload4(i.w, buf));
}

/* Colours at the lanes' positions (x, y), mg_fetch_scaled's: where the lanes sit at one
 * offset (one row, one fraction, whole pixels apart) the quad fetch (2 x 5 loads), which
 * then gives each lane the same value. */
MB_INLINE float16 mb_fetch_lanes(global const float *col, const int pitch, const int w,
                                 const int row0, const int row1, const float4 x, const float4 y,
                                 const float scale)
{
  const float4 u = x - 0.5f, fu = floor(u);
  if(clfx_all4((y == y.x) & (u - fu == u.x - fu.x)
                & (fu - fu.x == (float4)(0.0f, 1.0f, 2.0f, 3.0f))))
    return mb_fetch_quad_linear(col, pitch, w, row0, row1, x.x, y.x, scale, 0.0f);
  return mg_fetch4_scaled(col, pitch, w, row0, row1, x, y, scale);
}

/* The step model along one pixel axis for the 4 lanes: the taps p-2, p-1, p1, p2 (times
 * `scale`) and the depths zm, zp of p-1 and p1; a neighbour behind x (depth z0) flattened
 * (what x's moving edge reveals enters as it is, not as a step continuing x's surface);
 * *st: its stepness.  Returns the change of p0 under a box of `len` px along the axis (0
 * where len is negligible). */
MB_INLINE float16 mb_step_axis(const float16 tm2, const float16 tm1, const float16 tp1,
                               const float16 tp2, const float4 zm, const float4 zp,
                               const float16 p0, const float4 z0, const float4 len, float4 *st)
{
  *st = mb_stepness(tm2, tm1, p0, tp1, tp2);
  const int4 still = len < 1e-3f;
  if(clfx_all4(still))
    return (float16)(0.0f);
  const float4 bm = clamp((zm - z0) / (SOFT_Z * fmin(z0, zm)), 0.0f, 1.0f);
  const float4 bp = clamp((zp - z0) / (SOFT_Z * fmin(z0, zp)), 0.0f, 1.0f);
  const float16 d = mb_step_smear(tm2 + (tm1 - tm2) * SPLAT16(bm), tm1, p0, tp1,
                                  tp2 + (tp1 - tp2) * SPLAT16(bp), SPLAT16(len)) - p0;
  return select(d, (float16)(0.0f), SPLAT16I(still));
}

/* The closed forms at the centres of the quad's pixels (lanes `lane`, row fy) along
 * (ux, uy), their colours p0 (times `scale`), depths z0, smear lengths len: the four taps
 * read bilinearly, times `scale`; *q: how much of the neighbourhood is x's own layer or
 * behind it (a tap in front of x pulls it to 0; `clear`: the tile is front-free, 1).
 * Returns mb_short_smear.  *step: the step model's smear, taken along the pixel axes (the
 * smear's parts len |ux| and len |uy|, their changes added: exact for edges along the pixel
 * grid, whatever the motion's direction, where taps read along u between pixels would mix
 * the patches), *st: its weight (the stepness of the axes that carry a fair part of it).
 * The axes' taps sit at whole pixels whatever the direction: runs of the rows y-2 .. y+2. */
MB_INLINE float16 mb_short_quad(global const float *col, global const float *aux, const int pitch,
                                const int w, const int row0, const int row1, const float4 lane,
                                const float fy, const float4 ux, const float4 uy, const float16 p0,
                                const float4 z0, const float4 len, const float scale,
                                const int clear, float4 *q, float16 *step, float4 *st)
{
  const float4 px = lane + 0.5f;
  const float py = fy + 0.5f;
  float16 tap[4];
  float4 keep = (float4)(1.0f);
  for(int k = 0; k < 4; k++)
  {
    const float o = k < 2 ? (float)(k - 2) : (float)(k - 1);     /* -2, -1, 1, 2 */
    const float4 x = px + o * ux, y = py + o * uy;
    tap[k] = mb_fetch_lanes(col, pitch, w, row0, row1, x, y, scale);
    if(clear)
      continue;   /* no tap in front of x: each factor is 1 */
    const int4 ix = convert_int4(clamp(floor(x), -1.0f, (float)w));
    const int4 iy = convert_int4(clamp(floor(y), (float)(row0 - 1), (float)row1));
    const float4 z = mb_lanes(aux, pitch, w, row0, row1, iy, ix).s26ae;
    keep *= 1.0f - clamp((z0 - z) / (SOFT_Z * fmin(z0, z)), 0.0f, 1.0f);
  }
  *q = keep;
  const int4 ix = clamp(convert_int4(clamp(floor(px), 0.0f, (float)(w - 1))), (int4)(0),
                        (int4)(w - 1));
  const int4 iy = (int4)(clfx_clampi((int)clamp(floor(py), (float)row0, (float)(row1 - 1)),
                                     row0, row1 - 1));
  const float4 lx = len * fabs(ux), ly = len * fabs(uy);
#define MB_LANES(b, dy, dx) mb_lanes(b, pitch, w, row0, row1, iy + (dy), ix + (dx))
  const float16 xm1 = MB_LANES(col, 0, -1) * scale, xp1 = MB_LANES(col, 0, 1) * scale;
  const float16 ym1 = MB_LANES(col, -1, 0) * scale, yp1 = MB_LANES(col, 1, 0) * scale;
  /* an axis no lane's smear crosses (a motion along the other axis) changes nothing and
   * weighs nothing in *st below (its g is 0): neither its step nor its stepness is taken */
  float4 sx = (float4)(0.0f), sy = (float4)(0.0f);
  float16 ex = (float16)(0.0f), ey = (float16)(0.0f);
  if(!clfx_all4(lx == 0.0f))
    ex = mb_step_axis(MB_LANES(col, 0, -2) * scale, xm1, xp1, MB_LANES(col, 0, 2) * scale,
                      MB_LANES(aux, 0, -1).s26ae, MB_LANES(aux, 0, 1).s26ae, p0, z0, lx, &sx);
  if(!clfx_all4(ly == 0.0f))
    ey = mb_step_axis(MB_LANES(col, -2, 0) * scale, ym1, yp1, MB_LANES(col, 2, 0) * scale,
                      MB_LANES(aux, -1, 0).s26ae, MB_LANES(aux, 1, 0).s26ae, p0, z0, ly, &sy);
  /* the cross term of a diagonal smear (the pixel's box moved along the line overlaps the
   * diagonal neighbour ahead, and the one behind, by lx ly / 24 on average): without it a
   * corner of a checker took the colour across both edges twice */
  const int4 ox = select((int4)(-1), (int4)(1), ux >= 0.0f);
  const int4 oy = select((int4)(-1), (int4)(1), uy >= 0.0f);
  const float16 da = MB_LANES(col, oy, ox) * scale, db = MB_LANES(col, -oy, -ox) * scale;
#undef MB_LANES
  const int16 fx = SPLAT16I(ox > 0), fwd_y = SPLAT16I(oy > 0);
  const float16 xa = select(xm1, xp1, fx), xb = select(xp1, xm1, fx);
  const float16 ya = select(ym1, yp1, fwd_y), yb = select(yp1, ym1, fwd_y);
  *step = p0 + ex + ey + SPLAT16(lx * ly / 24.0f) * ((da - xa - ya + p0) + (db - xb - yb + p0));
  /* both axes that carry a fair part of the smear must look like steps */
  const float4 gx = clamp(4.0f * lx / fmax(lx + ly, FLT_MIN), 0.0f, 1.0f);
  const float4 gy = clamp(4.0f * ly / fmax(lx + ly, FLT_MIN), 0.0f, 1.0f);
  *st = fmin(1.0f - gx * (1.0f - sx), 1.0f - gy * (1.0f - sy));
  return mb_short_smear(tap[0], tap[1], p0, tap[2], tap[3], SPLAT16(len));
}

#if CUBIC
#define MB_FETCH_LANES mb_fetch4_cubic
#define MB_FETCH_QUAD mb_fetch_quad_cubic
#else
#define MB_FETCH_LANES(col, pitch, w, row0, row1, px, py, scale, beta) \
  mg_fetch4_scaled(col, pitch, w, row0, row1, px, py, scale)
#define MB_FETCH_QUAD mb_fetch_quad_linear
#endif

/* Colours at 4 positions, times `scale` (in scope), cubic blends `beta` (float4, per lane);
 * `same` (runtime): the lanes share one offset and blend, i.e. the positions are
 * (px.x + k, py.x). */
#define MB_FETCH4(px, py, same, beta) \
  ((same) ? MB_FETCH_QUAD(col, pitch, width, row0, row1, (px).x, (py).x, scale, (beta).x) : \
   MB_FETCH_LANES(col, pitch, width, row0, row1, px, py, scale, beta))

/* The gather of the 4 pixels of one work-item (lanes `lane`, row fy; centre colours cc, own
 * velocities (vxx, vxy), depths zx), every colour sample times `scale` (the result too).
 *
 * Two interleaved sample sets per pixel x (McGuire et al. 2013 sample both the
 * neighbourhood's and the pixel's own velocity):
 *  - along x's own velocity v_x: the surface x belongs to and what its motion reveals behind
 *    it; a sample at y = x - v_x t shows what covers x at time t unless y is in front of x
 *    (then it is left to the occluder set).  Exact for any uniform motion; static pixels
 *    stay sharp.
 *  - along the tile's dominant velocity v_n: occluders, i.e. samples in front of x whose
 *    smear y + v_y [t0, t1] passes over x; weight = source length per sample / smear length
 *    (scatter as gather), so their summed weight is the fraction of the shutter they cover x.
 * out = occluders (normalised if they overlap) + (1 - their coverage) x own-velocity layer. */
MB_INLINE REAL16 motion_gather_quad(global const float *col, global const float *aux,
                                    global const float *auxb, const float2 bn, const float4 bxx,
                                    const float4 bxy, const int pitch, const int width,
                                    const int row0, const int row1, const float4 vn,
                                    const float4 lane, const float fy, const float16 cc,
                                    const float4 vxx, const float4 vxy, const float4 zx,
                                    const int any_moving, const int clear, const float t0,
                                    const float t1, const float dt, const int n, const float ell,
                                    const float hell, const float4 jit, const float scale)
{
  REAL16 F = (REAL16)(0), S = (REAL16)(0);
  REAL4 aF = (REAL4)(0), aS = (REAL4)(0);
  /* lanes whose samples sit at one offset (no jitter; for the own set, one velocity) read
   * their colours together */
  const int same_t = clfx_all4(jit == jit.x);
  const int same_v = same_t && clfx_all4((vxx == vxx.x) & (vxy == vxy.x) & (bxx == bxx.x)
                                         & (bxy == bxy.x));
  const float4 beta_n = (float4)(mb_beta(vn.z * (t1 - t0)));         /* along v_n */
#if CURVED
  const float4 wn = mb_turn((float4)(vn.x), (float4)(vn.y), (float4)(bn.x), (float4)(bn.y));
  const float4 wx = mb_turn(vxx, vxy, bxx, bxy);       /* turn rates of the paths (MB_ARC) */
#endif
  const float4 beta_x = (float4)(mb_beta(sqrt(vxx.x * vxx.x + vxy.x * vxy.x) * (t1 - t0)),
                                 mb_beta(sqrt(vxx.y * vxx.y + vxy.y * vxy.y) * (t1 - t0)),
                                 mb_beta(sqrt(vxx.z * vxx.z + vxy.z * vxy.z) * (t1 - t0)),
                                 mb_beta(sqrt(vxx.w * vxx.w + vxy.w * vxy.w) * (t1 - t0)));
  for(int i = 0; i < n; i++)
  {
    const float4 t = t0 + ((float)i + jit) * dt;
    float4 vyx, vyy, zy, sy;

    /* occluders, along v_n (none in a front-free tile) */
    if(!clear)
    {
#if CURVED
      /* an occluder moves along the path of the tile's fastest pixel: the one over x at
       * time t sits at x - d(t) at the frame time */
      const float4 dx = MB_ARC(vn.x, bn.x, t, wn), dy = MB_ARC(vn.y, bn.y, t, wn);  /* d = x - y */
#else
      const float4 dx = vn.x * t, dy = vn.y * t;             /* d = x - y */
#endif
      const float4 px = lane + 0.5f - dx, py = fy + 0.5f - dy;
      const int4 ix = clamp(convert_int4(floor(px)), (int4)(0), (int4)(width - 1));
      const int4 iy = clamp(convert_int4(floor(py)), (int4)(row0), (int4)(row1 - 1));
      MB_LOAD_AUX(ix, iy, vyx, vyy, zy, sy);
      const float4 rel = (zx - zy) / (SOFT_Z * fmin(zx, zy));
      const float4 f = clamp(rel, 0.0f, 1.0f);
      if(clfx_any4(f > 0.0f))   /* else every weight is 0: nothing here lies in front of x */
      {
        const float4 len = (t1 - t0) * sy;                     /* y's smear length */
#if CURVED
        /* y's own path at t: how far x is from it along its tangent (-> the time t* its path
         * passes x, which must lie in the shutter) and across it */
        float4 byx, byy, bz_, bs_;
        MB_LOAD_AUXB(ix, iy, byx, byy, bz_, bs_);
        const float4 wy = mb_turn(vyx, vyy, byx, byy);
        const float4 ex = dx - MB_ARC(vyx, byx, t, wy), ey = dy - MB_ARC(vyy, byy, t, wy);
        const float4 gx = MB_ARC_TANGENT(vyx, byx, t, wy), gy = MB_ARC_TANGENT(vyy, byy, t, wy);
        const float4 st = sqrt(gx * gx + gy * gy);
        const float4 inv_st = 1.0f / fmax(st, MIN_SPEED);
        const float4 al = (ex * gx + ey * gy) * inv_st;
        const float4 perp = fabs(ex * gy - ey * gx) * inv_st;
        const float4 rho = clamp(0.5f + fmin(al + (t - t0) * st, (t1 - t) * st - al) / hell,
                                 0.0f, 1.0f)
#else
        /* distance along y's motion and across it; ramps of one sample spacing centred on
         * the smear's ends make the weights of a regular sample grid sum to its length */
        const float4 inv_sy = 1.0f / fmax(sy, MIN_SPEED);
        const float4 ay = (dx * vyx + dy * vyy) * inv_sy;
        const float4 perp = fabs(dx * vyy - dy * vyx) * inv_sy;
        const float4 rho = clamp(0.5f + fmin(ay - t0 * sy, t1 * sy - ay) / hell, 0.0f, 1.0f)
#endif
                         * clamp(1.5f - perp, 0.0f, 1.0f)
                         * clamp(len / MIN_BLUR - 1.0f, 0.0f, 1.0f);  /* statics never occlude */
        const float4 wf = f * rho * (ell / fmax(len, hell));
        if(clfx_any4(wf > 0.0f))
        {
          const float16 c = SPLAT16(wf) * MB_FETCH4(px, py, same_t, beta_n);  /* rounded, summed */
          aF += TO_REAL4(wf);
          F += TO_REAL16(c);
        }
      }
    }
    /* x's own surface and what it reveals, along v_x */
    if(any_moving)
    {
#if CURVED
      /* the point of x's surface over x at time t came from where x's own path was at -t
       * (a steady flow, exact for turning and translating surfaces): y = x + d(-t); x - d(t)
       * would bend the other way */
      const float4 px = lane + 0.5f + MB_ARC(vxx, bxx, -t, wx);
      const float4 py = fy + 0.5f + MB_ARC(vxy, bxy, -t, wx);
#else
      const float4 px = lane + 0.5f - vxx * t, py = fy + 0.5f - vxy * t;
#endif
      if(clear)   /* no sample in front of x: every weight is 1 */
      {
        aS += TO_REAL4((float4)(1.0f));
        S += TO_REAL16(MB_FETCH4(px, py, same_v, beta_x));
        continue;
      }
      const int4 ix = clamp(convert_int4(floor(px)), (int4)(0), (int4)(width - 1));
      const int4 iy = clamp(convert_int4(floor(py)), (int4)(row0), (int4)(row1 - 1));
      MB_LOAD_AUX(ix, iy, vyx, vyy, zy, sy);
      const float4 rel = (zx - zy) / (SOFT_Z * fmin(zx, zy));
      const float4 ws = 1.0f - clamp(rel, 0.0f, 1.0f);
      const float16 c = SPLAT16(ws) * MB_FETCH4(px, py, same_v, beta_x);
      aS += TO_REAL4(ws);
      S += TO_REAL16(c);
    }
  }
  const REAL4 one = (REAL4)(1);
  const REAL4 cov = fmin(aF, one);
  const REAL4 fscale = one / fmax(aF, one);
  /* the layer behind the occluders: the own-velocity average, or the centre pixel if no
   * sample belongs to it (all rejected) or nothing moves in this quad */
  const REAL4 sown = select((REAL4)(0), one / fmax(aS, (REAL4)(1e-6)), aS > (REAL4)(1e-6));
  const REAL4 cown = select(one, (REAL4)(0), aS > (REAL4)(1e-6));
  REAL16 own = S * (REAL16)(sown.xxxx, sown.yyyy, sown.zzzz, sown.wwww)
               + TO_REAL16(cc * scale) * (REAL16)(cown.xxxx, cown.yyyy, cown.zzzz, cown.wwww);
  /* sub-pixel smears through a centred shutter: the closed form (mb_short_smear), blended
   * in by each pixel's own path length where the gather's fetch is the tent */
#if CURVED
  const float4 gx = MB_ARC_TANGENT(vxx, bxx, (float4)(0.0f), wx);
  const float4 gy = MB_ARC_TANGENT(vxy, bxy, (float4)(0.0f), wx);
#else
  const float4 gx = vxx, gy = vxy;
#endif
  const float4 glen = sqrt(gx * gx + gy * gy);
  const float4 slen = glen * (t1 - t0);
  const int4 centred = (int4)(-(fabs(t0 + t1) <= 1e-6f * (t1 - t0)));
  const int4 short_ = (slen >= MIN_BLUR) & centred;
  const float4 wsh = select((float4)(0.0f), 1.0f - MB_BETA(slen), short_);
  /* the step model (mb_step_smear) on every smear under STEP_MAX_PX, by its stepness */
  const float4 wln = select((float4)(0.0f),
                            clamp((STEP_MAX_PX - slen) / (STEP_MAX_PX - 1.0f), 0.0f, 1.0f),
                            short_);
  if(clfx_any4(wln > 0.0f))
  {
    /* the quad at once; a lane without the closed forms gets a harmless direction and no
     * change */
    const int4 on = wln > 0.0f;
    const float4 ux = select((float4)(1.0f), gx / glen, on);
    const float4 uy = select((float4)(0.0f), gy / glen, on);
    float4 q, st;
    float16 step;
    const float16 c = mb_short_quad(col, aux, pitch, width, row0, row1, lane, fy, ux, uy,
                                    cc * scale, zx, select((float4)(0.0f), slen, on), scale,
                                    clear, &q, &step, &st);
    const float16 o = TO_FLOAT16(own);
    const float16 base = o + (c - o) * SPLAT16(wsh * q);
    const float16 d = base - o + (step - base) * SPLAT16(st * wln * q);
    own += TO_REAL16(select((float16)(0.0f), d, SPLAT16I(on)));
  }
  const REAL4 keep = one - cov;
  return F * (REAL16)(fscale.xxxx, fscale.yyyy, fscale.zzzz, fscale.wwww)
         + own * (REAL16)(keep.xxxx, keep.yyyy, keep.zzzz, keep.wwww);
}

/* tiles: (tx, ty, samples, flags) per moving tile; flags bit 0, jitter (0: the midpoint rule,
 * exact for the few, dense samples of a short blur; 1: per-pixel jitter where samples are
 * sparse); bit 1, front-free: no pixel the tile's samples and closed-form taps can reach lies
 * in front of any of its pixels (the host's test on the tiles' depth ranges, motion_tilemax),
 * so every soft depth test would give 0 (the occluders' weights, the own set's and the
 * taps' rejections): the occluder set is skipped and the own set taken without them;
 * k: tile size (multiple of 4); qpt = k * k / 4.  The buffers hold the canvas rows
 * row0 <= y < row1 (CLFX_CANVAS_ROWS: a band of a tiled render and its margin; 0 and the
 * canvas's height in a whole render); the rows band0 <= y < band1 are written.  nmax_b: the
 * backward motion of each NeighborMax record's pixel (CURVED).
 * `col` holds finite colours (the host sanitises NaN/Inf first); a float32 sum of huge ones
 * that overflows is taken again with every colour halved and divided by n first, so finite
 * input gives finite output. */
kernel void motion_gather(global const float *col, global const float *aux,
                          global const float *auxb,
                          global const float *nmax, global const float *nmax_b,
                          global const int *tiles, const int ntiles, global float *dst,
                          const int pitch, const int width, const int row0, const int row1,
                          const int band0, const int band1, const int tiles_x, const int k,
                          const float t0, const float t1, const int frame)
{
  const int gid = get_global_id(0);
  const int qpt = k * k / 4;
  const int tile = gid / qpt;
  if(tile >= ntiles) return;
  const int r = gid - tile * qpt, qrow = k / 4;
  const int tx = tiles[4 * tile], ty = tiles[4 * tile + 1], n = tiles[4 * tile + 2];
  const int flags = tiles[4 * tile + 3], jittered = flags & 1, clear = flags & 2;
  const int x = tx * k + (r % qrow) * 4, y = ty * k + r / qrow;
  if(y < band0 || y >= band1 || x >= pitch) return;
  CLFX_CANVAS_ROWS(col, pitch, 4, row0);
  CLFX_CANVAS_ROWS(aux, pitch, 4, row0);
  CLFX_CANVAS_ROWS(dst, pitch, 4, row0);
#if CURVED
  CLFX_CANVAS_ROWS(auxb, pitch, 4, row0);
#endif

  const float4 vn = vload4(ty * tiles_x + tx, nmax);   /* dominant velocity, |v| in .z */
  const float4 lane = (float4)(x) + (float4)(0.0f, 1.0f, 2.0f, 3.0f);
  const float fy = (float)y;
  const int base = y * pitch + x;
  const float16 cc = vload16(0, col + base * 4);
  const float16 ac = vload16(0, aux + base * 4);
  const float4 vxx = ac.s048c, vxy = ac.s159d, zx = ac.s26ae, sx = ac.s37bf;
#if CURVED
  const float16 bc = vload16(0, auxb + base * 4);
  const float4 bxx = bc.s048c, bxy = bc.s159d;
  /* the tile's dominant path: the backward motion of its fastest pixel */
  const float2 bn = vload2(ty * tiles_x + tx, nmax_b);
#else
  const float4 bxx = vxx, bxy = vxy;
  const float2 bn = vn.xy;
#endif
  const float dt = (t1 - t0) / (float)n;
  const float ell = vn.z * dt;                 /* source length per occluder sample, px */
  const float hell = fmax(ell, 1e-3f);
  const float4 jit = jittered ? mg_jitter(lane, fy, frame) : (float4)(0.5f);
  const int any_moving = clfx_any4(sx * (t1 - t0) >= MIN_BLUR);

  float16 out = TO_FLOAT16(motion_gather_quad(col, aux, auxb, bn, bxx, bxy, pitch, width, row0,
                                              row1, vn, lane, fy, cc, vxx, vxy, zx, any_moving,
                                              clear, t0, t1, dt, n, ell, hell, jit, 1.0f));
  const int16 inf = (as_int16(out) & 0x7f800000) == 0x7f800000;
  const int8 inf8 = inf.lo | inf.hi;
  if(clfx_any4(inf8.lo | inf8.hi))   /* overflowed: the second pass */
  {
    const float scale = 0.5f / (float)n;
    out = TO_FLOAT16(motion_gather_quad(col, aux, auxb, bn, bxx, bxy, pitch, width, row0, row1,
                                        vn, lane, fy, cc, vxx, vxy, zx, any_moving, clear, t0,
                                        t1, dt, n, ell, hell, jit, scale));
    out = clamp(out / scale, -FLT_MAX, FLT_MAX);
  }
  vstore16(out, 0, dst + base * 4);
}
