"""float64 NumPy oracle of clfx/plugins/lens.py: lensfun's coordinates written out plainly,
the models inverted by plain bisection, each channel resampled with the shared filters
(tests/reference/distortion.py), then the pa vignetting polynomial."""
import math

import numpy as np

from tests.reference.distortion import bisect, sample


def dist_fwd(model, t):
    if model == "poly3":
        return lambda r: r * (1 - t[0] + t[0] * r * r)
    if model == "poly5":
        return lambda r: r * (1 + t[0] * r * r + t[1] * r ** 4)
    return lambda r: r * (t[0] * r ** 3 + t[1] * r * r + t[2] * r + 1 - t[0] - t[1] - t[2])


def tca_fwd(model, t, ch):
    if model == "linear":
        return lambda r: t[ch] * r
    return lambda r: r * (t[4 + ch] * r * r + t[2 + ch] * r + t[ch])


def lensfun_frame(w, h, *, crop, cal_crop, cal_aspect, center):
    """lensfun's normalisation of a w x h image: (scale, ccx, ccy, px, py) with normalised
    = (pixel - centre) * scale, and the pixel index grids (centres at integers)."""
    wp, hp = w - 1.0, h - 1.0
    size = min(wp, hp)
    c = cal_crop / crop * math.sqrt(cal_aspect ** 2 + 1) / math.sqrt((max(wp, hp) / size) ** 2 + 1)
    scale = 2 * c / size
    ccx, ccy = (wp / size * c + center[0]) / scale, (hp / size * c + center[1]) / scale
    px, py = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    return scale, ccx, ccy, px, py


def lens_points(w, h, *, crop, cal_crop, cal_aspect=1.5, center=(0.0, 0.0), distortion=None,
                tca=None):
    """{'red','green','blue'}: source points (centres at +0.5) of every output pixel."""
    scale, ccx, ccy, px, py = lensfun_frame(w, h, crop=crop, cal_crop=cal_crop,
                                            cal_aspect=cal_aspect, center=center)
    x, y = (px - ccx) * scale, (py - ccy) * scale
    if distortion:
        rd = np.hypot(x, y)
        ru = bisect(dist_fwd(*distortion), rd, 2 * rd.max() + 1)
        s = np.where(rd > 0, ru / np.where(rd > 0, rd, 1), 1.0)
        x, y = x * s, y * s
    out = {"green": (x, y)}
    for ch, name in ((0, "red"), (1, "blue")):
        if tca:
            rg = np.hypot(x, y)
            rc = bisect(tca_fwd(*tca, ch), rg, 2 * rg.max() + 1)
            s = np.where(rg > 0, rc / np.where(rg > 0, rg, 1), 1.0)
            out[name] = (x * s, y * s)
        else:
            out[name] = (x, y)
    return {k: (a / scale + ccx + 0.5, b / scale + ccy + 0.5) for k, (a, b) in out.items()}


def vignetting_factor(w, h, *, crop, cal_crop, cal_aspect=1.5, center=(0.0, 0.0), terms):
    scale, ccx, ccy, px, py = lensfun_frame(w, h, crop=crop, cal_crop=cal_crop,
                                            cal_aspect=cal_aspect, center=center)
    r = np.hypot(px - ccx, py - ccy) * scale / math.sqrt(cal_aspect ** 2 + 1)
    k1, k2, k3 = terms
    return np.maximum(1 + k1 * r ** 2 + k2 * r ** 4 + k3 * r ** 6, 0.0)


def lens(src, *, filter_name="lanczos3", border="edge", vignetting=None, **geom):
    src = np.asarray(src, np.float64)
    h, w = src.shape[:2]
    pts = lens_points(w, h, **geom)
    g = sample(src, *pts["green"], filter_name, border)
    out = g.copy()
    out[..., 0] = sample(src, *pts["red"], filter_name, border)[..., 0]
    out[..., 2] = sample(src, *pts["blue"], filter_name, border)[..., 2]
    if vignetting is not None:
        out[..., :3] *= vignetting_factor(w, h, terms=vignetting, **{k: geom[k] for k in
                                          ("crop", "cal_crop", "cal_aspect", "center")})[..., None]
    return out
