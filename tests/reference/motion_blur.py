"""float64 NumPy oracles of clfx/plugins/motion_blur.py and clfx/plugins/camera_blur.py.

Every function averages the source, read bilinearly with clamp-to-edge at continuous
positions (pixel centres at +0.5), over ``n`` instants of the open shutter ``[t0, t1]``
(midpoint rule).  With ``n`` large this is the exact time integral of the bilinear image.

- ``line_blur``: one constant velocity (the exact box line blur; camera pan); ``interp =
  "cubic"`` reads through the clamped Catmull-Rom the gather uses on short blurs.
- ``naive_blur``: the naive baseline — each pixel blurred along its *own* velocity (no
  tiles, no depth, no scatter): what a per-pixel directional blur does.
- ``similarity_blur``: the camera's image-plane motion ``p(t) = c + (1 + zoom t) R(roll t)
  (p0 - c) + shift t`` inverted per instant (exact spin, zoom and pan gathers).
"""
import math

import numpy as np


def bilinear(src, px, py):
    """``src`` (h, w, c) read at continuous positions (pixel centres at +0.5), clamp-to-edge."""
    h, w = src.shape[:2]
    u, v = px - 0.5, py - 0.5
    u0, v0 = np.floor(u), np.floor(v)
    fu, fv = (u - u0)[..., None], (v - v0)[..., None]
    xa = np.clip(u0, 0, w - 1).astype(np.int64)
    xb = np.clip(u0 + 1, 0, w - 1).astype(np.int64)
    ya = np.clip(v0, 0, h - 1).astype(np.int64)
    yb = np.clip(v0 + 1, 0, h - 1).astype(np.int64)
    top = src[ya, xa] * (1 - fu) + src[ya, xb] * fu
    bot = src[yb, xa] * (1 - fu) + src[yb, xb] * fu
    return top * (1 - fv) + bot * fv


def _catmull_rom(a):
    a2, a3 = a * a, a * a * a
    return (-0.5 * a3 + a2 - 0.5 * a, 1.5 * a3 - 2.5 * a2 + 1.0,
            -1.5 * a3 + 2.0 * a2 + 0.5 * a, 0.5 * a3 - 0.5 * a2)


def cubic(src, px, py):
    """``src`` read through a Catmull-Rom (4 x 4 taps), clamp-to-edge, each channel clamped
    to the range of the 2 x 2 pixels around the position (no ringing)."""
    h, w = src.shape[:2]
    u, v = px - 0.5, py - 0.5
    u0, v0 = np.floor(u), np.floor(v)
    wx, wy = _catmull_rom(u - u0), _catmull_rom(v - v0)
    xs = [np.clip(u0 + i, 0, w - 1).astype(np.int64) for i in (-1, 0, 1, 2)]
    ys = [np.clip(v0 + j, 0, h - 1).astype(np.int64) for j in (-1, 0, 1, 2)]
    acc = 0.0
    for j in range(4):
        acc = acc + wy[j][..., None] * sum(wx[i][..., None] * src[ys[j], xs[i]] for i in range(4))
    inner = [src[ys[j], xs[i]] for j in (1, 2) for i in (1, 2)]
    return np.clip(acc, np.minimum.reduce(inner), np.maximum.reduce(inner))


def _times(t0, t1, n):
    return t0 + (np.arange(n) + 0.5) / n * (t1 - t0)


def _sanitise(src):
    src = np.asarray(src, np.float64)
    return np.where(np.isfinite(src), src, 0.0)


def line_blur(src, velocity, *, t0, t1, n=1024, interp="linear"):
    """Box line blur: mean over t of ``src(x - v t)`` for one velocity ``v`` (px/frame),
    read bilinearly (``interp="linear"``) or through :func:`cubic`."""
    src = _sanitise(src)
    h, w = src.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    acc = np.zeros(src.shape)
    read = cubic if interp == "cubic" else bilinear
    for t in _times(t0, t1, n):
        acc += read(src, xs - velocity[0] * t, ys - velocity[1] * t)
    return acc / n


def naive_blur(src, velocity, *, t0, t1, n=256):
    """Each pixel averaged along its own velocity over the shutter (no depth, no scatter)."""
    src = _sanitise(src)
    v = np.where(np.isfinite(velocity), np.asarray(velocity, np.float64), 0.0)
    h, w = src.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    acc = np.zeros(src.shape)
    for t in _times(t0, t1, n):
        acc += bilinear(src, xs - v[..., 0] * t, ys - v[..., 1] * t)
    return acc / n


def similarity_blur(src, *, t0, t1, center, shift=(0.0, 0.0), roll_deg=0.0, zoom=0.0,
                    n=1024):
    """Camera blur of a pan (``shift`` px/frame), roll (deg/frame about ``center``) and zoom
    (image scale grows by ``zoom`` per frame): at time t the frame shows the sharp image
    mapped by ``p -> c + (1 + zoom t) R(roll t) (p - c) + shift t``; average the inverse
    look-ups over the shutter."""
    src = _sanitise(src)
    h, w = src.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    cx, cy = center
    acc = np.zeros(src.shape)
    for t in _times(t0, t1, n):
        a = math.radians(roll_deg) * t
        k = 1.0 + zoom * t
        qx, qy = xs - cx - shift[0] * t, ys - cy - shift[1] * t
        # inverse rotation by a (y down: a positive angle turns +x towards +y), then scale
        rx = (math.cos(a) * qx + math.sin(a) * qy) / k
        ry = (-math.sin(a) * qx + math.cos(a) * qy) / k
        acc += bilinear(src, rx + cx, ry + cy)
    return acc / n
