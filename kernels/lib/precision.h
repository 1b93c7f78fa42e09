/* The one precision switch of every kernel.
 *
 * A program built with Runtime.kernel(..., fp64=True) on a device with cl_khr_fp64 gets
 * -DCLFX_FP64=1 (the `fp64` of the effect's quality Level); every other build gets float.
 * Kernels write their accumulators and precision-sensitive coordinates as REAL / REALn and
 * convert with TO_REALn (float -> REAL) and TO_FLOATn (REAL -> float); nothing else in the
 * kernels tests for double precision.
 */
#ifndef CLFX_PRECISION_H
#define CLFX_PRECISION_H

#if defined(CLFX_FP64) && CLFX_FP64
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#define REAL_IS_DOUBLE 1
#define REAL double
#define REAL2 double2
#define REAL4 double4
#define REAL8 double8
#define REAL16 double16
#define TO_REAL(v) ((double)(v))
#define TO_REAL2 convert_double2
#define TO_REAL4 convert_double4
#define TO_REAL8 convert_double8
#define TO_REAL16 convert_double16
#define TO_FLOAT(v) ((float)(v))
#define TO_FLOAT2 convert_float2
#define TO_FLOAT4 convert_float4
#define TO_FLOAT8 convert_float8
#define TO_FLOAT16 convert_float16
#else
#define REAL_IS_DOUBLE 0
#define REAL float
#define REAL2 float2
#define REAL4 float4
#define REAL8 float8
#define REAL16 float16
#define TO_REAL(v) (v)
#define TO_REAL2(v) (v)
#define TO_REAL4(v) (v)
#define TO_REAL8(v) (v)
#define TO_REAL16(v) (v)
#define TO_FLOAT(v) (v)
#define TO_FLOAT2(v) (v)
#define TO_FLOAT4(v) (v)
#define TO_FLOAT8(v) (v)
#define TO_FLOAT16(v) (v)
#endif

#endif /* CLFX_PRECISION_H */
