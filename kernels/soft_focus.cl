/* soft_focus.cl: diffusion filter (clfx/plugins/soft_focus.py): lib/scatter.h's soft knee
 * with a low threshold (every moderately bright pixel scatters), blended energy-conservingly:
 * out = c - amount h + amount tint (PSF * h).  soft_focus_highlights, soft_focus_mix; works on
 * display-referred input unchanged (boost 0: its threshold is below 1). */
#include "lib/scatter.h"

SCATTER_KERNELS(soft_focus)
