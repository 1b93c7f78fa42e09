"""Bench case of distortion: a calibrated-looking wide lens, and OpenCV's remap as the peer."""
from __future__ import annotations

import numpy as np

from clfx.bench.cases import Case
from clfx.core.camera import Camera
from clfx.plugins.distortion import build_map


def make(width, height, rng):
    """A calibrated-looking wide lens with tangential terms over an HDR image with edges."""
    src = rng.uniform(0.0, 1.0, (height, width, 4)).astype(np.float32)
    src[height // 3: height // 2, width // 3: width // 2, :3] = 1e4   # HDR block: ringing test
    src[..., 3] = 1.0
    return dict(source=src, depth=None, velocity=None,
                params=dict(k1=-0.12, k2=0.03, p1=0.001, p2=-0.0005, fit="fill", border="edge"),
                camera=Camera(focal_length=24.0, sensor_width=36.0))


def cv2_border(border: str):
    """OpenCV's border mode for a warp's ``border`` parameter."""
    import cv2

    return {"edge": cv2.BORDER_REPLICATE, "mirror": cv2.BORDER_REFLECT_101}.get(
        border, cv2.BORDER_CONSTANT)


def cv2_map(sx, sy):
    """cv2.remap's float32 maps from source points in clfx's source-window coordinates:
    OpenCV puts pixel centres at integers; points without a source read the border."""
    return (np.where(np.isfinite(sx), sx - 0.5, -1e6).astype(np.float32),
            np.where(np.isfinite(sy), sy - 0.5, -1e6).astype(np.float32))


def peers(case, params, ctx):
    """cv2.remap with the same (float64-inverted) map: bilinear, bicubic and Lanczos-4."""
    try:
        import cv2
    except ImportError:
        return {}
    src = np.ascontiguousarray(case["source"], np.float32)
    win = ctx.source.window
    sx, sy, _ = build_map(params, ctx.camera, ctx.display_window, win, ctx.pixel_aspect)
    map_x, map_y = cv2_map(sx - win.x0, sy - win.y0)
    border = cv2_border(params.border)
    cv2.setNumThreads(2)
    return {f"cv2.remap {name}": ((lambda flag=flag: cv2.remap(src, map_x, map_y, flag,
                                                               borderMode=border)), level)
            for name, flag, level in (("bilinear", cv2.INTER_LINEAR, "draft"),
                                      ("cubic", cv2.INTER_CUBIC, "preview"),
                                      ("lanczos4", cv2.INTER_LANCZOS4, "final"))}


CASE = Case(make=make, peers=peers)
