/* shake.cl: the image motion of a camera turning about its centre (clfx/plugins/shake.py has
 * the model), as the two halves of a vector pass for the motion gather (lib/motion.cl):
 *
 *   shake_velocity   per pixel, the velocity (px/frame) of the straight line through the
 *                    positions the rotations at the shutter's opening and closing (t0, t1,
 *                    frames) carry its ray to: (P(M1 u) - P(M0 u)) / (t1 - t0), u = ((x -
 *                    cx) / fx, (y - cy) / fy, 1) at the pixel centre, P the pinhole
 *                    projection back to pixels.
 *
 * Each work-item handles 4 pixels of a row. */

/* P(m u) - (u.x, u.y) in pixels (a ray turned behind the camera stays where it is) */
inline float2 shake_moved(global const float *m, const float ux, const float uy,
                          const float fx, const float fy)
{
  const float qx = m[0] * ux + m[1] * uy + m[2];
  const float qy = m[3] * ux + m[4] * uy + m[5];
  const float qz = m[6] * ux + m[7] * uy + m[8];
  if(!(qz > 1e-6f)) return (float2)(0.0f);
  return (float2)((qx / qz - ux) * fx, (qy / qz - uy) * fy);
}

/* (x0, y0): the frame position of the buffers' first pixel; `m`: M0 then M1 (row-major 3x3,
 * from the frame time's camera to the one at the shutter's opening / closing); `inv_dt`:
 * 1 / (t1 - t0) */
kernel void shake_velocity(global float *vel, global const float *m, const int pitch,
                           const int width, const int height, const int x0, const int y0,
                           const float cx, const float cy, const float fx, const float fy,
                           const float inv_dt)
{
  const int qx = get_global_id(0), y = get_global_id(1);
  if(y >= height || qx * 4 >= pitch) return;
  const int i = y * pitch + qx * 4;
  const float uy = ((float)(y0 + y) + 0.5f - cy) / fy;
  float v[8];
  for(int k = 0; k < 4; k++)
  {
    const float ux = ((float)(x0 + qx * 4 + k) + 0.5f - cx) / fx;
    const float2 d = (shake_moved(m + 9, ux, uy, fx, fy) - shake_moved(m, ux, uy, fx, fy))
                     * inv_dt;
    v[2 * k] = d.x;
    v[2 * k + 1] = d.y;
  }
  vstore8(vload8(0, v), 0, vel + 2 * i);
}
