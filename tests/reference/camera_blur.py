"""float64 NumPy oracle of clfx/plugins/camera_blur.py, from what the effect claims: the
camera's own motion during the open shutter, read from the effect's parameters and the
camera block (docs/effects/camera_blur.md), not from the plugin's code.

The camera moves; the scene does not.  Over one frame (t in frames, 0 = the frame time):

- the shutter is open over ``s = angle / 360`` of a frame: ``[-s/2, s/2]`` centred,
  ``[0, s]`` opening at the frame time, ``[-s, 0]`` closing at it; the effect's
  ``shutter_angle`` (>= 0) and ``shutter_offset`` (not "camera") override the camera's;
- pan / tilt: the content moves ``length`` x the display window's diagonal per frame in the
  image direction ``direction`` (degrees, 0 = +x right, 90 = +y down);
- roll: the image turns ``roll`` degrees per frame (+x towards +y) and zoom: it scales by
  ``1 + zoom t``, both about ``center`` (a fraction of half the display window from its
  centre);
- trucking and dolly: the camera translates by ``truck`` (x right, y down) and ``dolly``
  (forward) scene units per frame.  A point of planar depth ``z`` seen at ``p`` (image
  plane, focal length ``f_px = focal_length x display width / sensor_width`` px) is at
  ``c + (f_px X - f_px T t) / (z - dolly t)`` at time t, ``X = (p - c) z / f_px``: the
  pinhole projection of the moved camera (exact, no linearisation).

A pixel's value is the mean over the open shutter of the sharp image at the point that the
camera's motion brings onto it (the inverse of the map above at each instant: a scene that
is one plane occludes nothing), read bilinearly with clamp-to-edge at the source (data)
window, pixel centres at +0.5, ``n`` instants by the midpoint rule.  Trucking and dolly need
one depth (a plane): where depths differ, parallax occludes and reveals, and that truth is
a renderer's (clfx.bench.cases.camera_blur's multisample truth), not this oracle's.
"""
import math

import numpy as np

from tests.reference.motion_blur import bilinear

OFFSETS = ("centered", "opening", "closing")


def shutter(angle_deg, offset):
    """(t0, t1): the open shutter in frames relative to the frame time."""
    if offset not in OFFSETS:
        raise ValueError(f"shutter offset {offset!r}")
    s = angle_deg / 360.0
    return {"centered": (-0.5 * s, 0.5 * s), "opening": (0.0, s), "closing": (-s, 0.0)}[offset]


def camera_blur(src, *, camera, length=0.0, direction=0.0, roll=0.0, zoom=0.0,
                truck=(0.0, 0.0), dolly=0.0, center=(0.0, 0.0), shutter_angle=-1.0,
                shutter_offset="camera", depth=None, data_window=None, display_window=None,
                n=1024, **_):
    """Camera blur of ``src`` (h, w, c) covering ``data_window`` ((x0, y0, x1, y1), default
    at the origin) in a frame whose display window is ``display_window`` (default the data
    window), with the effect's parameters (by their names) and ``camera`` (any object with
    ``shutter_angle``, ``shutter_offset``, ``focal_length``, ``sensor_width``).  ``depth``:
    planar depth, one value (a plane) wherever trucking or dolly is not 0."""
    src = np.asarray(src, np.float64)
    src = np.where(np.isfinite(src), src, 0.0)
    h, w = src.shape[:2]
    x0, y0 = (data_window or (0, 0, w, h))[:2]
    dx0, dy0, dx1, dy1 = display_window or (x0, y0, x0 + w, y0 + h)
    dw, dh = dx1 - dx0, dy1 - dy0
    cx = (dx0 + dx1) / 2 + center[0] * dw / 2
    cy = (dy0 + dy1) / 2 + center[1] * dh / 2
    diag = math.hypot(dw, dh)
    sx = length * diag * math.cos(math.radians(direction))
    sy = length * diag * math.sin(math.radians(direction))
    angle = camera.shutter_angle if shutter_angle < 0 else shutter_angle
    offset = camera.shutter_offset if shutter_offset == "camera" else shutter_offset
    t0, t1 = shutter(angle, offset)
    trucking = truck[0] != 0.0 or truck[1] != 0.0 or dolly != 0.0
    z = None
    if trucking:
        zs = np.unique(np.asarray(depth, np.float64))
        if zs.size != 1 or not math.isfinite(zs[0]):
            raise ValueError("the oracle's trucking needs one finite depth (a plane)")
        z = float(zs[0])
    f_px = camera.focal_length * dw / camera.sensor_width
    # output pixel centres in frame coordinates
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    xs, ys = xs + x0, ys + y0
    acc = np.zeros(src.shape)
    for t in t0 + (np.arange(n) + 0.5) / n * (t1 - t0):
        # undo the image-plane motion: shift, then scale and turn about the centre
        a, k = math.radians(roll) * t, 1.0 + zoom * t
        qx, qy = xs - cx - sx * t, ys - cy - sy * t
        px = (math.cos(a) * qx + math.sin(a) * qy) / k
        py = (-math.sin(a) * qx + math.cos(a) * qy) / k
        if trucking:   # undo the camera's translation: the plane's point seen there at t
            px = (px * (z - dolly * t) + f_px * truck[0] * t) / z
            py = (py * (z - dolly * t) + f_px * truck[1] * t) / z
        acc += bilinear(src, px + cx - x0, py + cy - y0)
    return acc / n
