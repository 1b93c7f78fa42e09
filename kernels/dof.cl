/* dof.cl: gather depth of field with near/far fields (clfx/plugins/dof.py has the model).
 *
 * dof_prepare: per padded pixel, the sanitised premultiplied colour and the signed CoC
 *   radius in x pixels (< 0 in front of the focus plane), clamped to clamp_r.  The padded
 *   image (`pad` pixels each side, clamp-to-edge) lets the gather read without bounds tests.
 * dof_gather: each work-item gathers 4 horizontally adjacent pixels (one float16) over the
 *   same pattern of integer tap offsets, so every tap is a vload16 + vload4 and the weights
 *   are float4 vectors (PoCL does not vectorise one-pixel work-items).
 *
 * dof_upsample: bilinear upsampling of the half-resolution gather into the tiles marked half
 *   (the half-resolution input is the shared 2 x 2 box of lib/blur.cl, blur_box_down2).
 *
 * The tap pattern (rings, aperture shape, pixel aspect) comes from a host table per tile.
 * The gather accumulates in REAL (lib/precision.h: double at the reference level).
 */
#include "lib/common.h"
#include "lib/precision.h"

#define NEAR_EPS 0.25f   /* |radius| below this is in focus: never a near-field pixel */

inline float dof_coc_radius(float z, float k_half, float focus, float clamp_r)
{
  /* r = K/2 (1 - S/z): finite at z = +inf (-> K/2); z NaN, 0 or < 0 is invalid -> 0. */
  if(!(z > 0.0f)) return 0.0f;
  const float r = clfx_is_finite(z) ? k_half * (1.0f - focus / z) : k_half;
  return clamp(r, -clamp_r, clamp_r);
}

kernel void dof_prepare(global const float *src, global const float *depth, const int pitch,
                        const int width, const int height, global float *col,
                        global float *coc, const int ppitch, const int pheight,
                        const int pad, const float k_half, const float focus,
                        const float clamp_r)
{
  const int qx = get_global_id(0), py = get_global_id(1);
  if(py >= pheight || qx * 4 >= ppitch) return;
  const int sy = clfx_clampi(py - pad, 0, height - 1);
  for(int l = 0; l < 4; l++)
  {
    const int px = qx * 4 + l;
    const int sx = clfx_clampi(px - pad, 0, width - 1);
    const float4 c = clfx_finite4_or_zero(vload4(sy * pitch + sx, src));
    vstore4(c, py * ppitch + px, col);
    coc[py * ppitch + px] = dof_coc_radius(depth[sy * pitch + sx], k_half, focus, clamp_r);
  }
}

#define LANES(v) ((v).s0000111122223333)

/* Taps (host table, clfx/plugins/dof.py tap_table): 8 floats each: integer offset x, y;
 * distance in aperture units for a near tap (shape upright at o) and a far tap (shape at -o);
 * aperture area the tap stands for (px^2).  tile_info[t] = (first tap, tap count); count 0
 * means nothing within reach has a CoC of half a pixel: the tile is copied. */
kernel void dof_gather(global const float *col, global const float *coc, const int ppitch,
                       const int pad, global float *dst, const int pitch,
                       const int width, const int height, global const float *taps,
                       global const int *tile_info, const int tiles_x, const int tile)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  const int x = qx * 4;
  if(y >= height || x >= width) return;
  const int t = (y / tile) * tiles_x + x / tile;
  const int first = tile_info[2 * t], count = tile_info[2 * t + 1];
  const int base = (y + pad) * ppitch + x + pad;
  if(count == 0)
  {  /* the sanitised source */
    vstore16(vload16(0, col + base * 4), 0, dst + (y * pitch + x) * 4);
    return;
  }
  const float16 c0 = vload16(0, col + base * 4);
  const float4 r0 = vload4(0, coc + base);
  const int4 p_near = r0 < -NEAR_EPS;
  const float4 ar0 = fabs(r0);
  const float4 r0_far = fmax(r0, 0.0f);

  REAL16 fn = (REAL16)(0), ff = (REAL16)(0);
  REAL4 wn_sum = (REAL4)(0), wf_sum = (REAL4)(0), alpha = (REAL4)(0);
  for(int i = first; i < first + count; i++)
  {
    const float8 tp = vload8(i, taps);
    const int at = base + (int)tp.s1 * ppitch + (int)tp.s0;
    const float d_near = tp.s2, d_far = tp.s3, area = tp.s4;
    const float16 c = vload16(0, col + at * 4);
    const float4 rq = vload4(0, coc + at);
    const float4 arq = fabs(rq);
    const int4 q_near = rq < -NEAR_EPS;
    /* near field: scatter-as-gather, the tap's light spread over its own CoC area */
    const float4 cov_n = clamp(arq - d_near + 0.5f, 0.0f, 1.0f);
    const float4 wn = select((float4)(0.0f), cov_n / fmax(CLFX_PI * arq * arq, 1.0f), q_near);
    /* far field: a tap behind p spreads at most p's own radius (p occludes it); for a
       near p the far field is the background hidden behind it, estimated from the
       visible background within p's radius */
    const float4 rf = select(select(arq, fmin(arq, r0_far), rq > r0), fmax(arq, ar0), p_near);
    const float4 cov_f = clamp(rf - d_far + 0.5f, 0.0f, 1.0f);
    const float4 wf = select(cov_f / fmax(CLFX_PI * rf * rf, 1.0f), (float4)(0.0f), q_near);
    fn += TO_REAL16(c * LANES(wn));
    ff += TO_REAL16(c * LANES(wf));
    wn_sum += TO_REAL4(wn);
    wf_sum += TO_REAL4(wf);
    alpha += TO_REAL4(wn * area);
  }
  /* normalise each field; every tap rejected -> the centre pixel (no 0/0) */
  const REAL4 tiny = (REAL4)(1e-20);
  const REAL4 a = clamp(alpha, (REAL4)(0), (REAL4)(1));
  const REAL4 inv_n = select((REAL4)(0), (REAL4)(1) / wn_sum, wn_sum > tiny);
  const REAL4 inv_f = select((REAL4)(0), (REAL4)(1) / wf_sum, wf_sum > tiny);
  const REAL16 centre = TO_REAL16(c0);
  const REAL16 near = select(centre, fn * LANES(inv_n), LANES(wn_sum > tiny));
  REAL16 far = select(near, ff * LANES(inv_f), LANES(wf_sum > tiny));
  const REAL16 mix_a = LANES(select(a, (REAL4)(1), wf_sum <= tiny));
  const REAL16 out = far + (near - far) * mix_a;
  /* rows are padded to 4 pixels: the lanes past the width land in the padding */
  vstore16(TO_FLOAT16(out), 0, dst + (y * pitch + x) * 4);
}

/* Bilinear upsampling of the half-resolution result into the tiles marked half (flag 1). */
kernel void dof_upsample(global const float *hres, const int hpitch, const int hwidth,
                         const int hheight, global float *dst, const int pitch,
                         const int width, const int height, global const int *tile_half,
                         const int tiles_x, const int tile)
{
  const int x = get_global_id(0), y = get_global_id(1);
  if(x >= width || y >= height) return;
  if(!tile_half[(y / tile) * tiles_x + x / tile]) return;
  const float hx = clamp(0.5f * ((float)x + 0.5f) - 0.5f, 0.0f, (float)(hwidth - 1));
  const float hy = clamp(0.5f * ((float)y + 0.5f) - 0.5f, 0.0f, (float)(hheight - 1));
  const int x0 = (int)hx, y0 = (int)hy;
  const int x1 = min(x0 + 1, hwidth - 1), y1 = min(y0 + 1, hheight - 1);
  const float fx = hx - (float)x0, fy = hy - (float)y0;
  const float4 a = mix(vload4(y0 * hpitch + x0, hres), vload4(y0 * hpitch + x1, hres), fx);
  const float4 b = mix(vload4(y1 * hpitch + x0, hres), vload4(y1 * hpitch + x1, hres), fx);
  vstore4(mix(a, b, fy), y * pitch + x, dst);
}
