/* distortion.cl: Brown-Conrady lens distortion as a gather through a precomputed map
 * (clfx/plugins/distortion.py has the model; kernels/lib/footprint_warp.h the kernels,
 * kernels/lib/resample.h the filters): distortion_footprint (draft / preview / final) and
 * distortion_ewa_f64 (reference), the kernels every warp through an analytic map shares
 * (clfx.kit.warp.FootprintWarp). */
#include "lib/footprint_warp.h"

#if !REAL_IS_DOUBLE
FOOTPRINT_WARP_KERNELS(distortion)
#else
EWA_WARP_KERNELS(distortion)
#endif
