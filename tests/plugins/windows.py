"""Tight data windows through the effects that move pixels: an element rendered in its own
bounding box must give the pixels it gives placed in a full-frame data window."""
import numpy as np

from clfx.core.rect import Rect
from tests.effects import render_effect


def placed(src, data: Rect, display: Rect):
    """``src`` (covering ``data``) in a transparent frame the size of ``display``."""
    full = np.zeros((display.height, display.width, src.shape[2]), np.float32)
    full[data.y0 - display.y0:data.y1 - display.y0, data.x0 - display.x0:data.x1 - display.x0] = src
    return full


def on(img, window: Rect, target: Rect):
    """``img`` (covering ``window``) on ``target``: transparent outside ``window``."""
    out = np.zeros((target.height, target.width, img.shape[2]), img.dtype)
    sub = window.intersect(target)
    out[sub.y0 - target.y0:sub.y1 - target.y0, sub.x0 - target.x0:sub.x1 - target.x0] = \
        img[sub.y0 - window.y0:sub.y1 - window.y0, sub.x0 - window.x0:sub.x1 - window.x0]
    return out


def tight_and_full(rt, plugin, p, src, data: Rect, display: Rect, **kw):
    """``(tight, full, tight_window)``: the effect on the element in its own data window and
    on the element placed in a full-frame data window, both on the union of their windows
    (the tight render transparent outside its window)."""
    t, tw = render_effect(rt, plugin, p, src, data_window=data, display_window=display,
                          keep_rod=True, **kw)
    f, fw = render_effect(rt, plugin, p, placed(src, data, display), display_window=display,
                          keep_rod=True, **kw)
    both = tw.union(fw)
    return on(t, tw, both), on(f, fw, both), tw


def element(rng, data: Rect):
    """A bright RGBA element (a disc on transparent black, touching its box's edges: a
    window's edge that a warp could smear) filling ``data``."""
    h, w = data.height, data.width
    ys, xs = np.mgrid[0:h, 0:w] + 0.5
    disc = (((xs - w / 2) / (w / 2)) ** 2 + ((ys - h / 2) / (h / 2)) ** 2 <= 1.0)
    src = rng.uniform(0.2, 4.0, (h, w, 4)).astype(np.float32)
    src[..., 3] = 1.0
    src[0, :] = src[-1, :] = 1.0       # opaque rows along the box's edges
    src[:, 0] = src[:, -1] = 1.0
    return np.where((disc | (xs < 1) | (xs > w - 1) | (ys < 1) | (ys > h - 1))[..., None],
                    src, 0.0).astype(np.float32)
