/* rolling_shutter.cl: rows read at different times (clfx/plugins/rolling_shutter.py).
 *
 * Input: the source colours and the aux records of lib/motion.cl's motion_prepare
 * (vx, vy, z, |v|) per pixel: velocity sanitised and clamped, depth sanitised (1 without a
 * depth pass).
 *
 *   rolling_shutter_tiles      per K x K tile: the velocities of the fastest pixel, of the
 *                              background (the farthest pixel with a depth pass, else the
 *                              slowest) and of the nearest pixel (depth pass only)
 *   rolling_shutter_neighbors  per tile: the same over its 3 x 3 neighbourhood
 *   rolling_shutter_gather     per output pixel p at its row time t = tx (x - xr) + ty (y - yr)
 *                              ((xr, yr) on the reference row): the surface at p at time t
 *                              came from q with q + v(q) t = p; found by
 *                              fixed-point iteration q <- p - v(q) t (nearest velocities) from
 *                              the starts p's own velocity, the fastest, the background's and
 *                              the nearest's; a start is valid when |q + v(q) t - p| <= TOL px;
 *                              the nearest valid one wins (same depth within SOFT_Z: the faster);
 *                              no valid one is a disocclusion, filled from the background beside
 *                              the occluder's trailing edge, p - v_o t (v_o: the occluder's
 *                              velocity at p - v_bg t), else the nearest pixel moving with the
 *                              background searched from there along the occluder's relative
 *                              motion (up to MAX_SEARCH px).
 * With CURVED (both halves of the vector pass) a point's displacement at time t is the circular
 * arc through its positions one frame before, at and after the frame time at a constant turn
 * rate (rs_path; lib/motion.cl's MB_ARC: the quadratic t (f + b) / 2 + t^2 (f - b) / 2 on a
 * straight path; f, b: forward and backward motion), in the fixed-point iteration, its test
 * and the disocclusion fill.
 * Positions are REAL (lib/precision.h: double for the reference level); no atomics.
 * Tiles lie on a grid of K x K pixels from the canvas's origin (the whole render's source
 * window) and positions and row times are the whole render's: a band of a tiled render passes
 * buffers holding canvas rows row0 <= y < row1 (CLFX_CANVAS_ROWS), reads clamp to them (the
 * canvas's edges where the band reaches them), and writes its rows band0 <= y < band1.
 */
#include "lib/arc.h"
#include "lib/common.h"
#include "lib/motion_gather.h"
#include "lib/precision.h"

#ifndef HAS_DEPTH
#define HAS_DEPTH 1
#endif
#ifndef ITERATIONS
#define ITERATIONS 3
#endif
#ifndef MAX_SEARCH
#define MAX_SEARCH 64
#endif
#ifndef CURVED
#define CURVED 0       /* 1: backward motion records too (auxb): paths are quadratics */
#endif

/* starts of the fixed-point iteration: own, fastest, background (, nearest with depth) */
#define NSTARTS (3 + HAS_DEPTH)
#define TOL 0.5f       /* px: a start converged when its forward map lands this close to p */
#define SOFT_Z 0.02f   /* relative depth difference below which two surfaces count as one */

/* --- tiles --------------------------------------------------------------------------------
 * A tile record is 3 float4: the fastest pixel (vx, vy, speed, 0), the background
 * (vx, vy, key, 0) with key = depth (HAS_DEPTH) or minus the speed, and the nearest pixel
 * (vx, vy, -depth, 0) (HAS_DEPTH only).  Ties keep the first pixel in scan order (strict
 * comparisons). */
#define RS_NONE (float4)(0.0f, 0.0f, -INFINITY, 0.0f)

inline float rs_bg_key(const float4 a)
{
#if HAS_DEPTH
  return a.z;
#else
  return -a.w;
#endif
}

/* Keep in *best the record (vx, vy, key) of largest key. */
inline void rs_keep(float4 *best, const float2 v, const float key)
{
  if(key > best->z) *best = (float4)(v, key, 0.0f);
}

kernel void rolling_shutter_tiles(global const float *aux, global float *tiles, const int pitch,
                                  const int width, const int height, const int row0,
                                  const int tiles_x, const int tiles_y, const int ty0,
                                  const int k)
{
  const int tx = get_global_id(0), ty = ty0 + get_global_id(1);
  if(tx >= tiles_x || ty >= tiles_y) return;
  CLFX_CANVAS_ROWS(aux, pitch, 4, row0);
  const int x1 = min(tx * k + k, width), y1 = min(ty * k + k, height);
  float4 fast = RS_NONE, back = RS_NONE, near = RS_NONE;
  for(int y = ty * k; y < y1; y++)
    for(int x = tx * k; x < x1; x++)
    {
      const float4 a = vload4((size_t)y * pitch + x, aux);
      rs_keep(&fast, a.xy, a.w);
      rs_keep(&back, a.xy, rs_bg_key(a));
      rs_keep(&near, a.xy, -a.z);
    }
  const size_t i = 3 * (size_t)(ty * tiles_x + tx);
  vstore4(fast, i, tiles);
  vstore4(back, i + 1, tiles);
  vstore4(near, i + 2, tiles);
}

kernel void rolling_shutter_neighbors(global const float *tiles, global float *nbr,
                                      const int tiles_x, const int tiles_y)
{
  const int tx = get_global_id(0), ty = get_global_id(1);
  if(tx >= tiles_x || ty >= tiles_y) return;
  float4 fast = RS_NONE, back = RS_NONE, near = RS_NONE;
  for(int dy = -1; dy <= 1; dy++)
    for(int dx = -1; dx <= 1; dx++)
    {
      const int x = tx + dx, y = ty + dy;
      if(x < 0 || y < 0 || x >= tiles_x || y >= tiles_y) continue;
      const size_t j = 3 * (size_t)(y * tiles_x + x);
      const float4 f = vload4(j, tiles), b = vload4(j + 1, tiles), n = vload4(j + 2, tiles);
      rs_keep(&fast, f.xy, f.z);
      rs_keep(&back, b.xy, b.z);
      rs_keep(&near, n.xy, n.z);
    }
  const size_t i = 3 * (size_t)(ty * tiles_x + tx);
  vstore4(fast, i, nbr);
  vstore4(back, i + 1, nbr);
  vstore4(near, i + 2, nbr);
}

/* --- gather ------------------------------------------------------------------------------ */
/* The aux record of the pixel containing q (clamped to the image). */
inline float4 rs_aux(global const float *aux, const int pitch, const int w, const int row0,
                     const int row1, const REAL2 q)
{
  const int x = clamp((int)floor(clamp(q.x, (REAL)(-1), (REAL)w)), 0, w - 1);
  const int y = clamp((int)floor(clamp(q.y, (REAL)(row0 - 1), (REAL)row1)), row0, row1 - 1);
  return vload4((size_t)y * pitch + x, aux);
}

/* Colour at continuous position q (pixel centres at +0.5), bilinear, reads clamped to the
 * image.  A weighted sum (no differences of colours: +-1e38 neighbours stay finite). */
inline float4 rs_colour(global const float *col, const int pitch, const int w, const int row0,
                        const int row1, const REAL2 q)
{
  const REAL u = clamp(q.x, (REAL)(-1), (REAL)(w + 1)) - (REAL)0.5;
  const REAL v = clamp(q.y, (REAL)(row0 - 1), (REAL)(row1 + 1)) - (REAL)0.5;
  const REAL fu = floor(u), fv = floor(v);
  const REAL ax = u - fu, ay = v - fv;
  const int xa = clamp((int)fu, 0, w - 1), xb = clamp((int)fu + 1, 0, w - 1);
  const int ya = clamp((int)fv, row0, row1 - 1), yb = clamp((int)fv + 1, row0, row1 - 1);
  const REAL4 c = TO_REAL4(vload4((size_t)ya * pitch + xa, col)) * ((1 - ax) * (1 - ay))
                + TO_REAL4(vload4((size_t)ya * pitch + xb, col)) * (ax * (1 - ay))
                + TO_REAL4(vload4((size_t)yb * pitch + xa, col)) * ((1 - ax) * ay)
                + TO_REAL4(vload4((size_t)yb * pitch + xb, col)) * (ax * ay);
  return TO_FLOAT4(c);
}

/* Displacement by time t of a point moving with forward f and backward b: the arc at a
 * constant turn rate w through -b, 0 and f (lib/arc.h's ARC_PATH, as lib/motion.cl's MB_ARC,
 * in REAL; the quadratic on a straight path). */
inline REAL2 rs_path(const REAL2 f, const REAL2 b, const REAL t)
{
  const REAL2 s = f + b, e = f - b;
  const REAL w = ARC_TURN(REAL, s.x, s.y, e.x, e.y);
  const int curved = w > (REAL)ARC_MIN_TURN;
  const REAL r = curved ? ARC_R(REAL, t, w) : t;
  return ARC_PATH(REAL, curved ? ARC_A(REAL, t, w) : t, r * r, s, e);
}

/* Displacement by time t of the point at q moving with forward f (CURVED: and backward b). */
inline REAL2 rs_disp(global const float *auxb, const int pitch, const int w, const int row0,
                     const int row1, const REAL2 q, const float2 f, const REAL t)
{
#if CURVED
  return rs_path(TO_REAL2(f), TO_REAL2(rs_aux(auxb, pitch, w, row0, row1, q).xy), t);
#else
  return TO_REAL2(f) * t;
#endif
}

/* Fixed-point iteration from the start velocity v0: q <- p - d(q, t) (d: v(q) t, or the
 * curved path).  Returns whether it converged; *q, *a: the final position and its aux
 * record. */
inline int rs_solve(global const float *aux, global const float *auxb, const int pitch,
                    const int w, const int row0, const int row1, const REAL2 p, const REAL t,
                    const float2 v0, REAL2 *q, float4 *a)
{
  REAL2 s = p - TO_REAL2(v0) * t;
  for(int i = 0; i < ITERATIONS; i++)
    s = p - rs_disp(auxb, pitch, w, row0, row1, s, rs_aux(aux, pitch, w, row0, row1, s).xy, t);
  const float4 r = rs_aux(aux, pitch, w, row0, row1, s);
  const REAL2 d = p - rs_disp(auxb, pitch, w, row0, row1, s, r.xy, t) - s;
  *q = s;
  *a = r;
  return dot(d, d) <= (REAL)(TOL * TOL);
}

/* Surface (z, s) is in front of surface (zb, sb): clearly nearer, or at the same depth and
 * faster (without a depth pass every z is 1: the faster wins). */
inline int rs_in_front(const float z, const float s, const float zb, const float sb)
{
  const int same = fabs(z - zb) <= SOFT_Z * fmin(z, zb);
  return same ? s > sb : z < zb;
}

/* The winning surface's pixel (at q, record a) is the antialiased rim left behind an
 * occluder: a 4-neighbour in front of it moves away from it (within 60 degrees of the
 * neighbour's direction) by a pixel or more by the time |t|.  Renderers write the velocity of
 * the surface at the pixel centre, so such a rim carries the background's motion but part of
 * the occluder's colour; kept, it stays behind as an outline of where the occluder was. */
inline int rs_trailing_rim(global const float *aux, const int pitch, const int w,
                           const int row0, const int row1, const REAL2 q, const float4 a,
                           const float tabs)
{
  for(int k = 0; k < 4; k++)
  {
    const float2 e = k == 0 ? (float2)(1.0f, 0.0f) : k == 1 ? (float2)(-1.0f, 0.0f)
                   : k == 2 ? (float2)(0.0f, 1.0f) : (float2)(0.0f, -1.0f);
    const float4 nb = rs_aux(aux, pitch, w, row0, row1, q + TO_REAL2(e));
    const float2 dv = nb.xy - a.xy;
    const float ln = length(dv);
    if(ln * tabs >= 1.0f && dot(e, dv) > 0.5f * ln && rs_in_front(nb.z, nb.w, a.z, a.w))
      return 1;
  }
  return 0;
}

kernel void rolling_shutter_gather(global const float *col, global const float *aux,
                                   global const float *auxb,
                                   global const float *nbr, global float *dst, const int pitch,
                                   const int width, const int row0, const int row1,
                                   const int band0, const int band1, const int tiles_x,
                                   const int k, const float tx, const float ty, const float xr,
                                   const float yr)
{
  const int x = get_global_id(0), y = band0 + get_global_id(1);
  if(x >= width || y >= band1) return;
  CLFX_CANVAS_ROWS(col, pitch, 4, row0);
  CLFX_CANVAS_ROWS(aux, pitch, 4, row0);
#if CURVED
  CLFX_CANVAS_ROWS(auxb, pitch, 4, row0);
#endif
  const REAL t = (REAL)tx * ((REAL)x - (REAL)xr) + (REAL)ty * ((REAL)y - (REAL)yr);
  const REAL2 p = (REAL2)((REAL)x + (REAL)0.5, (REAL)y + (REAL)0.5);
  const size_t ti = 3 * (size_t)((y / k) * tiles_x + x / k);
  const float2 vf = vload4(ti, nbr).xy, vb = vload4(ti + 1, nbr).xy;
  const float2 starts[NSTARTS] = {vload4((size_t)y * pitch + x, aux).xy, vf, vb
#if HAS_DEPTH
                                  , vload4(ti + 2, nbr).xy
#endif
                                 };

  int best = -1;
  REAL2 qb = p;
  float zb = 0.0f, sb = 0.0f;
  for(int c = 0; c < NSTARTS; c++)
  {
    /* a start equal to an earlier one ends where it did and cannot win (strict test) */
    int seen = 0;
    for(int e = 0; e < c; e++)
      seen |= all(starts[e] == starts[c]);
    if(seen) continue;
    REAL2 q;
    float4 a;
    if(rs_solve(aux, auxb, pitch, width, row0, row1, p, t, starts[c], &q, &a)
       && (best < 0 || rs_in_front(a.z, a.w, zb, sb)))
    {
      best = c; qb = q; zb = a.z; sb = a.w;
    }
  }
  if(best >= 0 && rs_trailing_rim(aux, pitch, width, row0, row1, qb,
                                   (float4)(rs_aux(aux, pitch, width, row0, row1, qb).xy, zb,
                                            sb),
                                   (float)fabs(t)))
    best = -1;                    /* an occluder's rim left behind: what it uncovered */
  if(best < 0)
  {
    /* disocclusion: the background point b = p - v_bg t was hidden at the frame time by an
     * occluder o (velocity v_o: the surface at b in the source, else the neighbourhood's
     * fastest).  As motion blur reveals a moving edge's background, the background beside
     * o's trailing edge stands in for it, translated with o's relative motion:
     * b - (v_o - v_bg) t = p - v_o t.  This keeps the background's texture (no streak of
     * one repeated pixel, no antialiased rim of o repeated behind it); where that point is
     * no background either, the nearest pixel moving with the background is searched along
     * the relative motion (away from o first). */
    const REAL2 q0 = p - TO_REAL2(vb) * t;
    const float tabs = (float)fabs(t);
    float2 vo = rs_aux(aux, pitch, width, row0, row1, q0).xy;
#if CURVED
    float2 bo = rs_aux(auxb, pitch, width, row0, row1, q0).xy;
#else
    float2 bo = vo;
#endif
    if(length(vo - vb) * tabs <= TOL) { vo = vf; bo = vf; }   /* the tile's: no backward */
    const REAL2 q1 = p - rs_path(TO_REAL2(vo), TO_REAL2(bo), t);
    qb = q1;
#if MAX_SEARCH > 0
    const float2 dv = vo - vb;
    const float len = length(dv);
    const REAL2 dir = len > 1e-6f ? TO_REAL2(dv / len) : (REAL2)(1, 0);
    const int reach = (int)min(ceil(len * tabs) + 1.0f, (float)MAX_SEARCH);
    int found = 0;
    for(int j = 0; j <= reach && !found; j++)
      for(int sgn = -1; sgn <= (j ? 1 : -1) && !found; sgn += 2)
      {
        const REAL2 q = q1 + dir * (REAL)(sgn * j);
        const float2 d = rs_aux(aux, pitch, width, row0, row1, q).xy - vb;
        if(length(d) * tabs <= TOL) { qb = q; found = 1; }
      }
#endif
  }
  vstore4(rs_colour(col, pitch, width, row0, row1, qb), (size_t)(y - band0) * pitch + x, dst);
}
