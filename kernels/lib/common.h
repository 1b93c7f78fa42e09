/* common.h: helpers shared by every clfx kernel.
 *
 * Image layout (clfx/device/runtime.py DeviceImage): float32, CH channels per pixel, rows padded to
 * `pitch` pixels (a multiple of 4), pixel (x, y) at float index (y * pitch + x) * CH + c.
 * Coordinates are pixel indices inside the image's window; pixel centres sit at +0.5.
 *
 * Non-finite tests use the exponent bits, not isnan/isinf, so they survive any build flags
 * (notes/hard-cases.md case 4).
 *
 * Integer min/max/clamp of a vector take vector bounds, `clamp(i4, (int4)(0), (int4)(w - 1))`,
 * not scalars: Oclgrind 21.10 reads a scalar bound as a vector (lanes 1-3 garbage), so its
 * checks saw indices "clamped" outside the image (tests/test_oclgrind.py).
 */
#ifndef CLFX_COMMON_H
#define CLFX_COMMON_H

#ifdef CLFX_HAS_FP64
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#endif

#define CLFX_PI 3.14159265358979323846f

/* Software prefetch, on a CPU device only (the runtime defines CLFX_HOST_CPU there): a
 * work-item asks for data a later work-item of the same thread will read.  On a GPU, or a
 * compiler without the builtin, it is nothing. */
#if defined(CLFX_HOST_CPU) && defined(__has_builtin)
#if __has_builtin(__builtin_prefetch)
#define CLFX_CAN_PREFETCH 1
#define clfx_prefetch(p) __builtin_prefetch(p)
#endif
#endif
/* A rarely taken path kept out of line on a CPU device (resample.h's checked path,
 * fp_sample_grid): inlined four times into a hot kernel it crowds the instruction cache
 * (distortion's checked pixels, under 1 % of a frame, cost the draft 7 % inlined, 2-3 % out
 * of line).  Elsewhere the compiler decides. */
#if defined(CLFX_HOST_CPU) && defined(__has_attribute)
#if __has_attribute(noinline)
#define CLFX_COLD __attribute__((noinline))
#endif
#endif
#ifndef CLFX_COLD
#define CLFX_COLD
#endif

/* Always inlined where the compiler has the attribute: PoCL (LLVM 15) kept some vector helpers
 * out of line and passed their outputs through the stack (ca_cubic_bins, grain_white32;
 * `perf report --sort dso,sym` shows such a helper as its own symbol).  Elsewhere plain
 * inline: the compiler decides. */
#if defined(__has_attribute)
#if __has_attribute(always_inline)
#define CLFX_INLINE inline __attribute__((always_inline))
#endif
#endif
#ifndef CLFX_INLINE
#define CLFX_INLINE inline
#endif

/* A 16-lane shuffle of a and b (lanes of a then b) with constant indices: clang's builtin
 * where the compiler has it (one instruction; vector literals of mixed parts came out as ~7
 * shuffles on PoCL), else OpenCL's shuffle2 with the same indices as its mask. */
#if defined(__has_builtin)
#if __has_builtin(__builtin_shufflevector)
#define CLFX_SHUFFLE16(a, b, ...) __builtin_shufflevector(a, b, __VA_ARGS__)
#endif
#endif
#ifndef CLFX_SHUFFLE16
#define CLFX_SHUFFLE16(a, b, ...) shuffle2(a, b, (uint16)(__VA_ARGS__))
#endif

/* Streaming stores, where the host asks for them (CLFX_STREAM_STORES: an output of at least
 * half the device's global memory cache, on a CPU device: clfx.device.runtime
 * Runtime.streams_stores).  A whole 64-byte line written without first reading it in
 * (distortion draft at 1080p: 7 % faster; with vignette reading its output next, 8.1 ms
 * against 8.5).  They are weakly ordered: the work-group's last work-item calls
 * clfx_streaming_fence() last (a CPU device runs a work-group on one thread, in order; an
 * sfence per store cost 5x).  p: 64-byte aligned (buffers are aligned to the device's
 * CL_DEVICE_MEM_BASE_ADDR_ALIGN).  Elsewhere plain vstore16 and no fence. */
#if defined(CLFX_STREAM_STORES) && defined(CLFX_HOST_CPU) && defined(__has_builtin)
#if CLFX_STREAM_STORES && __has_builtin(__builtin_nontemporal_store) && \
    __has_builtin(__builtin_ia32_sfence)
#define CLFX_CAN_STREAM_STORE 1
#define clfx_store16_streaming(v, p)                                                        \
  __builtin_nontemporal_store((float16)(v), (global float16 *)(p))
#define clfx_streaming_fence()                                                              \
  do { if(get_local_id(0) == get_local_size(0) - 1 && get_local_id(1) == get_local_size(1) - 1 \
          && get_local_id(2) == get_local_size(2) - 1) __builtin_ia32_sfence(); } while(0)
#endif
#endif
#ifndef CLFX_CAN_STREAM_STORE
#define CLFX_CAN_STREAM_STORE 0
#define clfx_store16_streaming(v, p) vstore16((float16)(v), 0, (p))
#define clfx_streaming_fence() ((void)0)
#endif

#ifndef CLFX_CAN_PREFETCH
#define CLFX_CAN_PREFETCH 0
#define clfx_prefetch(p) ((void)0)
#endif

inline int clfx_is_finite(float v)
{
  return (as_uint(v) & 0x7f800000u) != 0x7f800000u;
}

inline float clfx_finite_or(float v, float fallback)
{
  return clfx_is_finite(v) ? v : fallback;
}

/* Sanitising, one helper per width: non-finite lanes (NaN, +-Inf) become 0, finite ones stay
 * bit for bit; a vector select, no branches.  The _pixel forms zero a whole RGBA pixel that has
 * any non-finite channel (the glare family's rule: such a pixel neither lights nor spreads). */
inline float4 clfx_finite4_or_zero(float4 v)
{
  return select((float4)0.0f, v, (as_uint4(v) & 0x7f800000u) != (uint4)0x7f800000u);
}

inline float8 clfx_finite8_or_zero(float8 v)
{
  return select((float8)0.0f, v, (as_uint8(v) & 0x7f800000u) != (uint8)0x7f800000u);
}

inline float16 clfx_finite16_or_zero(float16 v)
{
  return select((float16)0.0f, v, (as_uint16(v) & 0x7f800000u) != (uint16)0x7f800000u);
}

inline float4 clfx_finite_pixel_or_zero(float4 c)
{
  return (clfx_is_finite(c.x) & clfx_is_finite(c.y) & clfx_is_finite(c.z) & clfx_is_finite(c.w))
         ? c : (float4)(0.0f);
}

/* 4 RGBA pixels (lanes s0123 the first pixel's, ...). */
inline float16 clfx_finite_pixels16_or_zero(float16 c)
{
  const int16 bad = (as_int16(c) & 0x7f800000) == 0x7f800000;
  const int4 p = bad.s048c | bad.s159d | bad.s26ae | bad.s37bf;
  return select(c, (float16)(0.0f), (int16)(p.xxxx, p.yyyy, p.zzzz, p.wwww));
}

/* The rows of a band of a tiled render: the buffer `p` (rows of `pitch` pixels of `ch` floats)
 * holds the canvas rows from `row0` on; from here on it is addressed in canvas rows, as in the
 * whole render (whose row0 is 0), so positions take the whole render's coordinates and only
 * the band's offset is in the addressing; only rows the buffer holds may be touched. */
#define CLFX_CANVAS_ROWS(p, pitch, ch, row0) ((p) -= (long)(row0) * (long)(pitch) * (ch))

/* Luminance of scene-linear RGB: the working space's Y row of RGB -> XYZ, given as build
 * defines (clfx.core.colour.luminance_defines); BT.709's weights by default. */
#ifndef CLFX_LUMA_R
#define CLFX_LUMA_R 0.2126f
#define CLFX_LUMA_G 0.7152f
#define CLFX_LUMA_B 0.0722f
#endif

inline float clfx_luminance(float4 c)
{
  return (CLFX_LUMA_R) * c.x + (CLFX_LUMA_G) * c.y + (CLFX_LUMA_B) * c.z;
}

/* any() / all() of an int4 mask (-1 / 0 lanes) as vector ORs / ANDs and one test: PoCL's
 * builtins test the lanes one by one, a branch each. */
inline int clfx_any4(int4 m)
{
  m |= m.s2301;
  return (m.s0 | m.s1) < 0;
}

inline int clfx_all4(int4 m)
{
  m &= m.s2301;
  return (m.s0 & m.s1) < 0;
}

inline int clfx_clampi(int v, int lo, int hi)
{
  return min(max(v, lo), hi);
}

/* Periodic mirror ("reflect-101" repeated) index: valid for any i, even far outside [0, n);
 * a kernel larger than the image stays in bounds (hard-cases.md case 11). */
inline int clfx_mirror(int i, int n)
{
  if(n <= 1) return 0;
  const int period = 2 * (n - 1);
  int m = i % period;
  if(m < 0) m += period;
  return m < n ? m : period - m;
}

inline float4 clfx_load4(global const float *img, int pitch, int x, int y)
{
  return vload4(y * pitch + x, img);
}

inline void clfx_store4(global float *img, int pitch, int x, int y, float4 v)
{
  vstore4(v, y * pitch + x, img);
}

/* Clamp-to-edge read of an RGBA image of size w x h. */
inline float4 clfx_load4_clamped(global const float *img, int pitch, int w, int h, int x, int y)
{
  return vload4(clfx_clampi(y, 0, h - 1) * pitch + clfx_clampi(x, 0, w - 1), img);
}

/* Integer hash (lowbias32, Chris Wellons): uniform, cheap, stateless.  CLFX_LOWBIAS32
 * updates a uint or a uintN in place (fastmath.h's clfx_hash16 is the 16-lane form). */
#define CLFX_LOWBIAS32(x) ((x) ^= (x) >> 16, (x) *= 0x7feb352du, (x) ^= (x) >> 15, \
                           (x) *= 0x846ca68bu, (x) ^= (x) >> 16)
inline uint clfx_hash(uint x) { CLFX_LOWBIAS32(x); return x; }

/* Hash of (seed, frame, x, y, channel) -> uniform float in (0, 1). */
inline float clfx_uniform(uint seed, int frame, int x, int y, int c)
{
  uint h = clfx_hash(seed ^ 0x9e3779b9u);
  h = clfx_hash(h ^ (uint)frame);
  h = clfx_hash(h ^ (uint)x);
  h = clfx_hash(h ^ ((uint)y * 0x85ebca6bu));
  h = clfx_hash(h ^ ((uint)c * 0xc2b2ae35u));
  return ((float)(h >> 8) + 0.5f) * (1.0f / 16777216.0f);
}

#endif
