/* motion_blur.cl: the motion_blur effect (clfx/plugins/motion_blur.py) is the shared motion
 * reconstruction of clfx/fx/motion.py, whose kernels are kernels/lib/motion.cl (prepare,
 * tile classification, depth-aware gather).  Building this file builds them. */
#include "lib/motion.cl"
