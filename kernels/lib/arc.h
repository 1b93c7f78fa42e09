/* arc.h: the path of a point through its positions one frame before (-b), at (0) and one
 * frame after (f) the frame time, at a constant turn rate w: the one copy of the arc's
 * constants and factors, for lib/motion.cl (float4), rolling_shutter.cl (REAL) and, read from
 * this file, clfx/fx/motion.py (MIN_TURN, MAX_TURN, path, turn_rate).
 *
 *   d(t) = A(t) (f + b) / 2 + C(t) (f - b) / 2,  A = sin(w t) / sin(w),  C = R(t)^2,
 *   R = sin(w t / 2) / sin(w / 2);  on a straight path (w <= ARC_MIN_TURN) the quadratic
 *   A = t, C = t^2 (each caller picks the branch: select() on vectors, if on scalars).
 *
 * With s = f + b and e = f - b, a point turning at w about a centre has e perpendicular to s
 * and |e| / |s| = tan(w / 2); only e's part across s counts (a straight path that speeds up
 * or slows down has e along s: w = 0).  T: the type (float4, REAL). */
#ifndef CLFX_ARC_H
#define CLFX_ARC_H

#define ARC_MIN_TURN 1e-3f  /* rad/frame: below this the arc is the quadratic (float-exact) */
#define ARC_MAX_TURN 2.6f   /* rad/frame (149 deg): a faster turn is taken as this one */

#define ARC_TURN(T, sx, sy, ex, ey) \
  fmin((T)2 * atan2(fabs((sx) * (ey) - (sy) * (ex)), (sx) * (sx) + (sy) * (sy)), (T)ARC_MAX_TURN)
#define ARC_A(T, t, w) (sin((w) * (t)) / sin(w))
#define ARC_R(T, t, w) (sin((T)0.5 * (w) * (t)) / sin((T)0.5 * (w)))
/* d(t) from its factors A and C = R^2 and s = f + b, e = f - b (T: the factors' type) */
#define ARC_PATH(T, A, C, s, e) ((A) * (T)0.5 * (s) + (C) * (T)0.5 * (e))
/* time derivatives of A and C */
#define ARC_DA(T, t, w) ((w) * cos((w) * (t)) / sin(w))
#define ARC_DC(T, t, w) ((w) * sin((w) * (t)) / ((T)2 * sin((T)0.5 * (w)) * sin((T)0.5 * (w))))

#endif
