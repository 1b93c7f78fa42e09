/* keystone.cl: the perspective of a tilted camera as a gather through a precomputed map
 * (clfx/plugins/keystone.py has the model; kernels/lib/footprint_warp.h the kernels,
 * kernels/lib/resample.h the filters): keystone_footprint (draft / preview / final) and
 * keystone_ewa_f64 (reference), the kernels every warp through an analytic map shares
 * (clfx.kit.warp.FootprintWarp). */
#include "lib/footprint_warp.h"

#if !REAL_IS_DOUBLE
FOOTPRINT_WARP_KERNELS(keystone)
#else
EWA_WARP_KERNELS(keystone)
#endif
