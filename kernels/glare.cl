/* glare.cl: highlight extraction and the final mix of glare (clfx/plugins/glare.py), from
 * lib/scatter.h (the model is written there): glare_highlights, glare_mix.  The convolution
 * itself runs in lib/fftconv.cl (clfx/fx/fftconv.py).  Display-referred input has boost > 0
 * and mixes additively. */
#include "lib/scatter.h"

SCATTER_KERNELS(glare)
