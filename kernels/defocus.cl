/* defocus.cl: the defocus effect (clfx/plugins/defocus.py) is a Gaussian blur; its kernels
 * are the shared blur library's (blur.cl, driven by clfx/blur.py: direct separable passes,
 * pyramid decimation / coarse blur / B-spline upsampling gathers, NaN/Inf sanitising).
 * Building this file builds them. */
#include "lib/blur.cl"
