/* fftconv.cl: device helpers of clfx/fx/fftconv.py (large-kernel convolution).
 *
 * REAL (lib/precision.h) is the FFT precision of the transform kernels (pack, multiply,
 * unpack) and the accumulator precision of the gathers (gather, direct): double in a program
 * built with fp64 (float64 transforms, the reference level's direct sums), float otherwise.
 * Work buffer of the in-place real-to-complex FFT: B planes of N1 rows x N2P reals
 * (N2P = N2 + 2, as pyvkfft's in-place r2c wants); after the forward transform each plane
 * holds N1 x (N2/2 + 1) complex values.
 *
 * Frame placement: grid (0, 0) holds the support origin (sx, sy) of the input; the PSF
 * spectrum was built with psf(c) at grid (0, 0), so the circular result at
 * ((o - s) mod N) is the linear convolution at output pixel o (clfx/fx/fftconv.py proves when
 * no wrap-around reaches the pixels we keep).
 */
#include "lib/common.h"
#include "lib/precision.h"

/* Largest colour channel of a pixel: the split test (bright pixels go to the exact gather). */
inline float fftconv_peak(float4 c)
{
  return fmax(c.x, fmax(c.y, c.z));
}

/* Copy channels [c0, c0 + nb) of the support rectangle of `src` into the work buffer, zero
 * elsewhere.  Non-finite values become 0 (the plugin counts them); pixels whose largest
 * channel exceeds `split` are left out (they are added exactly by fftconv_gather). */
kernel void fftconv_pack(global const float *src, const int pitch, const int channels,
                         const int sx, const int sy, const int sw, const int sh,
                         global REAL *work, const int n1, const int n2p,
                         const int c0, const int nb, const float split)
{
  const int gx = get_global_id(0), gy = get_global_id(1);
  if(gx >= n2p || gy >= n1) return;
  const size_t plane = (size_t)n1 * n2p;
  const size_t o = (size_t)gy * n2p + gx;
  float v[4] = {0.0f, 0.0f, 0.0f, 0.0f};
  if(gx < sw && gy < sh)
  {
    const size_t i = ((size_t)(sy + gy) * pitch + sx + gx) * channels;
    float4 c = (float4)(0.0f);
    if(channels == 1) c = (float4)(clfx_finite_or(src[i], 0.0f));
    else c = clfx_finite4_or_zero(vload4(0, src + i));
    if(channels == 1 ? c.x <= split : fftconv_peak(c) <= split)
    {
      v[0] = c.x; v[1] = c.y; v[2] = c.z; v[3] = c.w;
    }
  }
  for(int b = 0; b < nb; b++) work[b * plane + o] = TO_REAL(v[c0 + b]);
}

/* Pointwise product of the image spectra with the PSF spectrum (one plane shared by all
 * channels when spec_planes == 1).  The inverse transform applies the 1/N normalisation. */
kernel void fftconv_multiply(global REAL2 *work, global const REAL2 *spec, const int count,
                             const int nb, const int spec_planes, const int spec_c0)
{
  const int i = get_global_id(0);
  if(i >= count) return;
  const REAL2 k0 = spec[(spec_planes == 1 ? 0 : spec_c0) * (size_t)count + i];
  for(int b = 0; b < nb; b++)
  {
    const REAL2 k = spec_planes == 1 ? k0 : spec[(size_t)(spec_c0 + b) * count + i];
    const size_t j = (size_t)b * count + i;
    const REAL2 a = work[j];
    work[j] = (REAL2)(a.x * k.x - a.y * k.y, a.x * k.y + a.y * k.x);
  }
}

inline int fftconv_wrap(int v, int n)
{
  int m = v % n;
  return m < 0 ? m + n : m;
}

/* Copy the convolved planes into channels [c0, c0 + nb) of the output image.  (dx, dy) is
 * the output window's origin minus the support origin; pixels outside the effective
 * rectangle [ex0, ex1) x [ey0, ey1) (output coordinates) receive 0.  Channels the caller
 * does not convolve are zeroed by the first call (c0 == 0). */
kernel void fftconv_unpack(global const REAL *work, const int n1, const int n2p, const int n2,
                           global float *dst, const int pitch, const int channels,
                           const int width, const int height, const int dx, const int dy,
                           const int ex0, const int ey0, const int ex1, const int ey1,
                           const int c0, const int nb)
{
  const int x = get_global_id(0), y = get_global_id(1);
  if(x >= pitch || y >= height) return;
  const size_t plane = (size_t)n1 * n2p;
  const int inside = x >= ex0 && x < ex1 && y >= ey0 && y < ey1;
  const size_t r = (size_t)fftconv_wrap(y + dy, n1) * n2p + fftconv_wrap(x + dx, n2);
  global float *d = dst + ((size_t)y * pitch + x) * channels;
  if(c0 == 0)
    for(int c = nb; c < channels; c++) d[c] = 0.0f;
  for(int b = 0; b < nb; b++)
    d[c0 + b] = inside ? TO_FLOAT(work[b * plane + r]) : 0.0f;
}

/* -- the exact part of the split: a few bright pixels, gathered ----------------------------- */

/* Count per support row the pixels whose largest channel exceeds `split`. */
kernel void fftconv_count_bright(global const float *src, const int pitch, const int channels,
                                 const int sx, const int sy, const int sw, const int sh,
                                 const float split, global int *counts)
{
  const int y = get_global_id(0);
  if(y >= sh) return;
  int n = 0;
  for(int x = 0; x < sw; x++)
  {
    const size_t i = ((size_t)(sy + y) * pitch + sx + x) * channels;
    const float4 c = channels == 1 ? (float4)(clfx_finite_or(src[i], 0.0f))
                                   : clfx_finite4_or_zero(vload4(0, src + i));
    n += fftconv_peak(c) > split;
  }
  counts[y] = n;
}

/* Write the bright pixels in row order at each row's offset (a host prefix sum of the
 * counts): positions (x, y relative to the support origin) and values. */
kernel void fftconv_compact_bright(global const float *src, const int pitch, const int channels,
                                   const int sx, const int sy, const int sw, const int sh,
                                   const float split, global const int *offsets,
                                   global int2 *pos, global float4 *val)
{
  const int y = get_global_id(0);
  if(y >= sh) return;
  int k = offsets[y];
  for(int x = 0; x < sw; x++)
  {
    const size_t i = ((size_t)(sy + y) * pitch + sx + x) * channels;
    const float4 c = channels == 1 ? (float4)(clfx_finite_or(src[i], 0.0f))
                                   : clfx_finite4_or_zero(vload4(0, src + i));
    if(fftconv_peak(c) > split)
    {
      pos[k] = (int2)(x, y);
      val[k] = c;
      k++;
    }
  }
}

/* Add the bright pixels' light to 4 output pixels per work-item, in a fixed order
 * (deterministic, no atomics).  The PSF planes are stored with 4 zero columns on each side
 * (row length kw + 8) so a 4-wide load never needs a bounds check.  (dx, dy): output
 * window origin minus support origin. */
kernel void fftconv_gather(global float *dst, const int pitch, const int channels,
                           const int height, const int dx, const int dy,
                           global const int2 *pos, global const float4 *val, const int count,
                           global const float *psf, const int kw, const int kh, const int kcx,
                           const int kcy, const int planes)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(qx * 4 >= pitch || y >= height) return;
  const int ox = qx * 4 + dx, oy = y + dy;   /* support coordinates of lane 0 */
  const int row = kw + 8;
  const size_t plane = (size_t)row * kh;
  REAL4 r = (REAL4)(0), g = (REAL4)(0), b = (REAL4)(0);
  for(int k = 0; k < count; k++)
  {
    const int2 p = pos[k];
    const int ky = oy - p.y + kcy;
    const int kx = ox - p.x + kcx;          /* kernel column of lane 0 */
    if(ky < 0 || ky >= kh || kx < -3 || kx >= kw) continue;
    const float4 v = val[k];
    const size_t base = (size_t)ky * row + (kx + 4);
    const REAL4 w0 = TO_REAL4(vload4(0, psf + base));
    r += TO_REAL(v.x) * w0;
    if(planes == 1)
    {
      g += TO_REAL(v.y) * w0;
      b += TO_REAL(v.z) * w0;
    }
    else
    {
      g += TO_REAL(v.y) * TO_REAL4(vload4(0, psf + plane + base));
      b += TO_REAL(v.z) * TO_REAL4(vload4(0, psf + 2 * plane + base));
    }
  }
  const float4 rf = TO_FLOAT4(r), gf = TO_FLOAT4(g), bf = TO_FLOAT4(b);
  const float rr[4] = {rf.x, rf.y, rf.z, rf.w}, gg[4] = {gf.x, gf.y, gf.z, gf.w},
              bb[4] = {bf.x, bf.y, bf.z, bf.w};
  for(int l = 0; l < 4; l++)
  {
    global float *d = dst + ((size_t)y * pitch + qx * 4 + l) * channels;
    d[0] += rr[l];
    if(channels >= 3) { d[1] += gg[l]; d[2] += bb[l]; }
  }
}

/* -- direct convolution (small kernels, and the reference for small sizes) ------------------ */

/* Zero-padded, sanitised RGBA copy of the support for fftconv_direct: pad (px, py) pixels
 * before the support; everything outside the support is 0. */
kernel void fftconv_pad(global const float *src, const int pitch, const int channels,
                        const int sx, const int sy, const int sw, const int sh,
                        global float *dst, const int dpitch, const int dheight,
                        const int px, const int py)
{
  const int x = get_global_id(0), y = get_global_id(1);
  if(x >= dpitch || y >= dheight) return;
  const int ix = x - px, iy = y - py;
  float4 c = (float4)(0.0f);
  if(ix >= 0 && ix < sw && iy >= 0 && iy < sh)
  {
    const size_t i = ((size_t)(sy + iy) * pitch + sx + ix) * channels;
    c = channels == 1 ? (float4)(clfx_finite_or(src[i], 0.0f), 0.0f, 0.0f, 0.0f)
                      : clfx_finite4_or_zero(vload4(0, src + i));
  }
  vstore4(c, (size_t)y * dpitch + x, dst);
}

/* out(o) = sum_k in(o - k) psf(k + c), 4 output pixels per work-item, accumulated in REAL.
 * `pad` is fftconv_pad's buffer, whose origin sits at output origin - (kw - 1 - kcx, kh - 1
 * - kcy), so output pixel (x, y) reads padded pixel (x + kw - 1 - j, y + kh - 1 - i) for PSF
 * tap (i, j).  Weights are REAL (float64 for the reference).  Alpha is set to 0. */
kernel void fftconv_direct(global const float *pad, const int ppitch,
                           global float *dst, const int pitch, const int channels,
                           const int width, const int height,
                           const int ex0, const int ey0, const int ex1, const int ey1,
                           global const REAL *psf, const int kw, const int kh, const int planes)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(qx * 4 >= pitch || y >= height) return;
  const size_t plane = (size_t)kw * kh;
  REAL4 r = (REAL4)(0), g = (REAL4)(0), b = (REAL4)(0);
  for(int i = 0; i < kh; i++)
  {
    global const float *prow = pad + (size_t)(y + kh - 1 - i) * ppitch * 4;
    for(int j = 0; j < kw; j++)
    {
      const float16 c = vload16(0, prow + (size_t)(qx * 4 + kw - 1 - j) * 4);
      const size_t t = (size_t)i * kw + j;
      const REAL wr = psf[t];
      const REAL wg = planes == 1 ? wr : psf[plane + t];
      const REAL wb = planes == 1 ? wr : psf[2 * plane + t];
      r += wr * TO_REAL4((float4)(c.s0, c.s4, c.s8, c.sc));
      g += wg * TO_REAL4((float4)(c.s1, c.s5, c.s9, c.sd));
      b += wb * TO_REAL4((float4)(c.s2, c.s6, c.sa, c.se));
    }
  }
  const float4 rf = TO_FLOAT4(r), gf = TO_FLOAT4(g), bf = TO_FLOAT4(b);
  const float rr[4] = {rf.x, rf.y, rf.z, rf.w}, gg[4] = {gf.x, gf.y, gf.z, gf.w},
              bb[4] = {bf.x, bf.y, bf.z, bf.w};
  for(int l = 0; l < 4; l++)
  {
    const int x = qx * 4 + l;
    const int inside = x >= ex0 && x < ex1 && y >= ey0 && y < ey1;
    global float *d = dst + ((size_t)y * pitch + x) * channels;
    if(channels == 1) { d[0] = inside ? rr[l] : 0.0f; continue; }
    d[0] = inside ? rr[l] : 0.0f;
    if(channels >= 3)
    {
      d[1] = inside ? gg[l] : 0.0f;
      d[2] = inside ? bb[l] : 0.0f;
    }
    for(int c = 3; c < channels; c++) d[c] = 0.0f;
  }
}

/* -- one pyramid level (draft) ------------------------------------------------------------ */

/* 2 x 2 box sum of the support (energy kept): half-res pixel (i, j) holds full-res pixels
 * (2i, 2j) .. (2i + 1, 2j + 1) of the support. */
kernel void fftconv_down2(global const float *src, const int pitch, const int channels,
                          const int sx, const int sy, const int sw, const int sh,
                          global float *dst, const int dpitch, const int dwidth,
                          const int dheight)
{
  const int x = get_global_id(0), y = get_global_id(1);
  if(x >= dpitch || y >= dheight) return;
  float4 acc = (float4)(0.0f);
  if(x < dwidth)
    for(int v = 0; v < 2; v++)
      for(int u = 0; u < 2; u++)
      {
        const int ix = 2 * x + u, iy = 2 * y + v;
        if(ix >= sw || iy >= sh) continue;
        const size_t i = ((size_t)(sy + iy) * pitch + sx + ix) * channels;
        acc += channels == 1 ? (float4)(clfx_finite_or(src[i], 0.0f), 0.0f, 0.0f, 0.0f)
                             : clfx_finite4_or_zero(vload4(0, src + i));
      }
  vstore4(acc, (size_t)y * dpitch + x, dst);
}

/* Bilinear upsampling of the half-res result, divided by 4 (a half-res pixel carries the
 * light of 4 pixels): full-res pixel x (support coordinates) samples half-res u = (x - 0.5)/2,
 * since half-res pixel i is centred on full-res position 2i + 1.  (dx, dy): output origin
 * minus support origin; (hx, hy): the half-res window's origin (half-res support coords). */
kernel void fftconv_up2(global const float *lo, const int hpitch, const int hwidth,
                        const int hheight, const int hx, const int hy,
                        global float *dst, const int pitch, const int channels,
                        const int width, const int height, const int dx, const int dy,
                        const int ex0, const int ey0, const int ex1, const int ey1)
{
  const int x = get_global_id(0), y = get_global_id(1);
  if(x >= pitch || y >= height) return;
  const float u = ((float)(x + dx) - 0.5f) * 0.5f, v = ((float)(y + dy) - 0.5f) * 0.5f;
  const float fu = floor(u), fv = floor(v);
  const int i0 = (int)fu - hx, j0 = (int)fv - hy;
  const float a = u - fu, bb = v - fv;
  float4 c = (float4)(0.0f);
  const int inside = x >= ex0 && x < ex1 && y >= ey0 && y < ey1;
  if(inside)
  {
    const int i1 = min(i0 + 1, hwidth - 1), j1 = min(j0 + 1, hheight - 1);
    const int ia = max(i0, 0), ja = max(j0, 0);
    const float4 p00 = vload4((size_t)ja * hpitch + ia, lo);
    const float4 p10 = vload4((size_t)ja * hpitch + i1, lo);
    const float4 p01 = vload4((size_t)j1 * hpitch + ia, lo);
    const float4 p11 = vload4((size_t)j1 * hpitch + i1, lo);
    c = 0.25f * ((1.0f - bb) * ((1.0f - a) * p00 + a * p10) + bb * ((1.0f - a) * p01 + a * p11));
  }
  global float *d = dst + ((size_t)y * pitch + x) * channels;
  if(channels == 1) { d[0] = c.x; return; }
  d[0] = c.x;
  if(channels >= 3) { d[1] = c.y; d[2] = c.z; }
  for(int k = 3; k < channels; k++) d[k] = 0.0f;
}
