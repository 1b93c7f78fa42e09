/* camera_blur.cl: blur from camera motion during the shutter (clfx/plugins/camera_blur.py).
 *
 *   camera_blur_similarity  pan + roll + zoom without trucking: every pixel averages the sharp
 *                           image along its exact path p(t) = c + (1 + zoom t) R(roll t)(p0 - c)
 *                           + shift t, inverted per instant (linear, spin and radial gathers
 *                           in one; exact because a rotating/zooming camera changes no
 *                           occlusion)
 *   camera_blur_velocity    the same motion plus trucking/dolly as a velocity field (px/frame)
 *                           for the motion reconstruction (lib/motion.cl): near things move
 *                           more (f / z)
 * Each work-item handles 4 pixels of a row.
 */
#include "lib/motion_gather.h"
#include "lib/precision.h"

/* Sum over the n instants t0 + (i + jit) dt of the sharp image at the 4 lanes' positions at
 * time t (relative to the centre: qx0, qy0), each sample times `scale`. */
inline REAL16 cb_path_sum(global const float *col, const int pitch, const int width,
                          const int row0, const int row1, const int x0, const int y0,
                          const float cx,
                          const float cy, const float4 qx0, const float qy0, const float sx,
                          const float sy, const float roll, const float zoom, const float t0,
                          const float dt, const float4 jit, const int n, const float scale)
{
  REAL16 acc = (REAL16)(0);
  for(int i = 0; i < n; i++)
  {
    const float4 t = t0 + ((float)i + jit) * dt;
    const float4 qx = qx0 - sx * t, qy = qy0 - sy * t;
    float4 c;
    const float4 s = sincos(roll * t, &c);
    const float4 inv_k = 1.0f / fmax(1.0f + zoom * t, 1e-3f);
    /* inverse rotation, then inverse scale, back to window coordinates */
    const float4 rx = (c * qx + s * qy) * inv_k + cx - (float)x0;
    const float4 ry = (-s * qx + c * qy) * inv_k + cy - (float)y0;
    const float16 v = mg_fetch4_scaled(col, pitch, width, row0, row1, rx, ry, scale);
    acc += TO_REAL16(v);
  }
  return acc;
}

/* (x0, y0): the window's origin in the frame (the whole render's: positions are the whole
 * render's in every band of a tiled render); `col` holds its rows row0 <= y < row1
 * (CLFX_CANVAS_ROWS), `dst` the rows band0 <= y < band1 that this launch computes (from its
 * first row); (cx, cy): the motion's centre in the frame; roll in radians per frame (+ turns
 * +x towards +y); zoom: scale growth per frame.  `col` holds finite colours (the host
 * sanitises NaN/Inf first); a float32 sum of huge ones that overflows is taken again with
 * every sample halved and divided by n first, so the output stays finite. */
kernel void camera_blur_similarity(global const float *col, global float *dst, const int pitch,
                                   const int width, const int row0, const int row1,
                                   const int band0, const int band1, const int x0,
                                   const int y0, const float cx, const float cy,
                                   const float sx, const float sy, const float roll,
                                   const float zoom, const float t0, const float t1,
                                   const int n, const int frame)
{
  const int qx = get_global_id(0), y = band0 + get_global_id(1);
  if(y >= band1 || qx * 4 >= pitch) return;
  CLFX_CANVAS_ROWS(col, pitch, 4, row0);
  const float4 lane = (float4)(qx * 4) + (float4)(0.0f, 1.0f, 2.0f, 3.0f);
  const float fy = (float)y;
  const float4 qx0 = lane + 0.5f + (float)x0 - cx;         /* relative to the centre */
  const float qy0 = fy + 0.5f + (float)y0 - cy;
  const float dt = (t1 - t0) / (float)n;
  const float4 jit = mg_jitter(lane, fy, frame);
  float16 out = TO_FLOAT16(cb_path_sum(col, pitch, width, row0, row1, x0, y0, cx, cy, qx0,
                                       qy0, sx, sy, roll, zoom, t0, dt, jit, n, 1.0f) / (REAL)n);
  if(any((as_int16(out) & 0x7f800000) == 0x7f800000))
  {
    const float16 half_mean = TO_FLOAT16(cb_path_sum(col, pitch, width, row0, row1, x0, y0,
                                                     cx, cy, qx0, qy0, sx, sy, roll, zoom, t0,
                                                     dt, jit, n, 0.5f / (float)n));
    out = clamp(2.0f * half_mean, -FLT_MAX, FLT_MAX);
  }
  vstore16(out, 0, dst + ((y - band0) * pitch + qx * 4) * 4);
}

/* Velocity (px/frame) of the camera motion at each pixel of the rows from `row0` on (the
 * buffers' first row; (x0, y0): the whole render's origin, as in camera_blur_similarity); depth
 * (if HAS_DEPTH) scales the trucking terms: lateral -f_px * truck / z, dolly
 * (p - c) * dolly / (z - dolly). */
kernel void camera_blur_velocity(global const float *depth, global float *vel, const int pitch,
                                 const int width, const int height, const int row0,
                                 const int x0, const int y0,
                                 const float cx, const float cy, const float sx,
                                 const float sy, const float roll, const float zoom,
                                 const float truck_px_x, const float truck_px_y,
                                 const float dolly, const float chord)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= height || qx * 4 >= pitch) return;
  const int i = y * pitch + qx * 4;
  const float4 px = (float4)(qx * 4) + (float4)(0.0f, 1.0f, 2.0f, 3.0f) + 0.5f + (float)x0 - cx;
  const float py = (float)(row0 + y) + 0.5f + (float)y0 - cy;
  float4 vx, vy;
  if(chord != 0.0f)
  {
    /* chord = +-1: the chords of (1 + zoom t) R(roll t)(p - c) to t = +-1, as the forward and
     * backward halves of a vector pass: the motion gather's path through them is then the arc
     * at the roll's turn rate (lib/motion.cl MB_ARC), exact for a roll without zoom */
    const float c = cos(chord * roll), s = sin(chord * roll), m = 1.0f + chord * zoom;
    vx = sx + chord * (m * (c * px - s * py) - px);
    vy = sy + chord * (m * (s * px + c * py) - py);
  }
  else                                         /* the tangent: d/dt at t = 0 */
  {
    vx = sx + zoom * px - roll * py;           /* d/dt of R(roll t)(p - c): roll x perp */
    vy = sy + zoom * py + roll * px;
  }
#if HAS_DEPTH
  const float4 z = vload4(0, depth + i);
  const int4 valid = (z > 0.0f) & ((as_int4(z) & 0x7f800000) != 0x7f800000);  /* inf: 0 */
  const float4 iz = select((float4)(0.0f), 1.0f / z, valid);
  /* a point nearer than the dolly step would pass the camera: cap its expansion at 1/frame */
  const float4 dz = select((float4)(0.0f), fmin(dolly * iz / fmax(1.0f - dolly * iz, 1e-3f),
                                                1.0f), valid);
  vx += -truck_px_x * iz + px * dz;
  vy += -truck_px_y * iz + py * dz;
#endif
  vstore8((float8)(vx.x, vy.x, vx.y, vy.y, vx.z, vy.z, vx.w, vy.w), 0, vel + 2 * i);
}
