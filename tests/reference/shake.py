"""float64 NumPy oracle of clfx/plugins/shake.py, from what the effect claims
(docs/effects/shake.md), not from the plugin's code.

The camera turns about its centre; the scene does not move.  Its orientation at time ``s``
seconds is ``C(s) = R_y(yaw) R_x(pitch) R_z(roll)`` (camera axes +x right, +y down, +z
forward; ``R_y`` turns +z towards +x, ``R_x`` towards -y, ``R_z`` +x towards +y), each angle
``A_k sqrt(2/3) sum_i sin(2 pi f r_i s + phi_ki)`` with ``r = (0.57, 1, 1.73)``, ``A_k`` the
axis's RMS (degrees), ``f`` the frequency (Hz), ``s = (frame + t) / fps``, and phases
``phi_ki = 2 pi lowbias32(seed32 ^ lowbias32(3 k + i + 1)) / 2^32`` (axes yaw, pitch, roll =
k 0, 1, 2).  ``lowbias32`` is the 32-bit integer hash x ^= x >> 16; x *= 0x7feb352d;
x ^= x >> 15; x *= 0x846ca68b; x ^= x >> 16 (mod 2^32); ``seed32 = lowbias32(seed ^
lowbias32(look_seed ^ 0x7368616b))``.

A pixel ``p`` sees at time ``t`` (frames) what the frame-time image shows at ``P(K C(0)^T
C(t) K^-1 p)`` (``K``: ``f_px = focal_length x display width / sensor_width``, times the pixel
aspect in y, principal point the display window's centre; ``P`` the pinhole projection).  Its
value is the mean over the open shutter (``shutter_angle / 360`` of a frame, centred, opening
or closing) of the sharp image there, read bilinearly with clamp-to-edge at the data window,
pixel centres at +0.5, ``n`` instants by the midpoint rule: a turn occludes nothing, so this
is the truth the gather approximates.
"""
import math

import numpy as np

from tests.reference.camera_blur import shutter
from tests.reference.motion_blur import bilinear

RATIOS = (0.57, 1.0, 1.73)
SALT = 0x7368616B


def lowbias32(x: int) -> int:
    """The hash as the docstring states it, in NumPy's wrapping uint32 arithmetic."""
    h = np.array([x % 2 ** 32], np.uint32)
    with np.errstate(over="ignore"):
        for shift, mul in ((16, 0x7FEB352D), (15, 0x846CA68B)):
            h = (h ^ (h >> np.uint32(shift))) * np.uint32(mul)
        h = h ^ (h >> np.uint32(16))
    return int(h[0])


def angles(seconds, *, yaw, pitch, roll, frequency, seed, look_seed=0):
    """(yaw, pitch, roll) in radians at ``seconds``."""
    s32 = lowbias32((seed & 0xFFFFFFFF) ^ lowbias32((look_seed & 0xFFFFFFFF) ^ SALT))
    out = []
    for k, amp in enumerate((yaw, pitch, roll)):
        total = 0.0
        for i, r in enumerate(RATIOS):
            phi = 2.0 * math.pi * lowbias32(s32 ^ lowbias32(3 * k + i + 1)) / 2.0 ** 32
            total += math.sin(2.0 * math.pi * frequency * r * seconds + phi)
        out.append(math.radians(amp) * math.sqrt(2.0 / 3.0) * total)
    return out


def orientation(yaw, pitch, roll):
    ry = np.array([[math.cos(yaw), 0, math.sin(yaw)], [0, 1, 0],
                   [-math.sin(yaw), 0, math.cos(yaw)]])
    rx = np.array([[1, 0, 0], [0, math.cos(pitch), -math.sin(pitch)],
                   [0, math.sin(pitch), math.cos(pitch)]])
    rz = np.array([[math.cos(roll), -math.sin(roll), 0], [math.sin(roll), math.cos(roll), 0],
                   [0, 0, 1]])
    return ry @ rx @ rz


def _frame(src, camera, data_window, display_window, pixel_aspect):
    h, w = src.shape[:2]
    x0, y0 = (data_window or (0, 0, w, h))[:2]
    dx0, dy0, dx1, dy1 = display_window or (x0, y0, x0 + w, y0 + h)
    fx = camera.focal_length * (dx1 - dx0) / camera.sensor_width
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    return x0, y0, fx, fx * pixel_aspect, (dx0 + dx1) / 2, (dy0 + dy1) / 2, xs + x0, ys + y0


def velocity(src, *, camera, yaw=0.3, pitch=0.3, roll=0.15, frequency=2.0, fps=24.0, seed=0,
             frame=0, look_seed=0, data_window=None, display_window=None, pixel_aspect=1.0,
             **_):
    """The image velocity (px/frame, (h, w, 2)) at the frame time: where the content at each
    pixel moves, d/dt of ``P(K C(t)^T C(0) K^-1 p)`` (central differences, 1e-4 frame)."""
    x0, y0, fx, fy, cx, cy, xs, ys = _frame(np.asarray(src), camera, data_window,
                                            display_window, pixel_aspect)
    amps = dict(yaw=yaw, pitch=pitch, roll=roll, frequency=frequency, seed=seed,
                look_seed=look_seed)
    c0 = orientation(*angles(frame / fps, **amps))
    rays = np.stack([(xs - cx) / fx, (ys - cy) / fy, np.ones_like(xs)])
    pos = []
    for dt in (1e-4, -1e-4):
        q = np.tensordot(orientation(*angles((frame + dt) / fps, **amps)).T @ c0, rays, 1)
        pos.append(np.stack([q[0] / q[2] * fx, q[1] / q[2] * fy], -1))
    return (pos[0] - pos[1]) / 2e-4


def shake(src, *, camera, yaw=0.3, pitch=0.3, roll=0.15, frequency=2.0, fps=24.0, seed=0,
          shutter_angle=-1.0, shutter_offset="camera", frame=0, look_seed=0,
          data_window=None, display_window=None, pixel_aspect=1.0, n=512, **_):
    """Shake of ``src`` (h, w, c) covering ``data_window`` ((x0, y0, x1, y1), default at the
    origin) in a frame whose display window is ``display_window`` (default the data window),
    with the effect's parameters by name and ``camera`` (``shutter_angle``,
    ``shutter_offset``, ``focal_length``, ``sensor_width``)."""
    src = np.asarray(src, np.float64)
    src = np.where(np.isfinite(src), src, 0.0)
    x0, y0, fx, fy, cx, cy, xs, ys = _frame(src, camera, data_window, display_window,
                                            pixel_aspect)
    angle = camera.shutter_angle if shutter_angle < 0 else shutter_angle
    offset = camera.shutter_offset if shutter_offset == "camera" else shutter_offset
    t0, t1 = shutter(angle, offset)
    amps = dict(yaw=yaw, pitch=pitch, roll=roll, frequency=frequency, seed=seed,
                look_seed=look_seed)
    c0 = orientation(*angles(frame / fps, **amps))
    rays = np.stack([(xs - cx) / fx, (ys - cy) / fy, np.ones_like(xs)])
    acc = np.zeros(src.shape)
    for t in t0 + (np.arange(n) + 0.5) / n * (t1 - t0):
        m = c0.T @ orientation(*angles((frame + t) / fps, **amps))
        q = np.tensordot(m, rays, 1)
        acc += bilinear(src, q[0] / q[2] * fx + cx - x0, q[1] / q[2] * fy + cy - y0)
    return acc / n
