"""float64 NumPy oracle of clfx/plugins/glare.py (and the convolution of clfx/fx/fftconv.py)."""
import numpy as np

LUMA = np.array([0.2126, 0.7152, 0.0722])


def sanitise(src):
    """Non-finite pixels (any channel) become 0 in every channel."""
    src = np.asarray(src, np.float64)
    bad = ~np.isfinite(src).all(axis=-1)
    out = src.copy()
    out[bad] = 0.0
    return out


def highlight(src, threshold, knee, boost=0.0):
    """Soft-knee highlight h (RGB) of sanitised RGBA pixels; boost > 0 expands display values."""
    rgb = np.maximum(src[..., :3], 0.0)
    lum = rgb @ LUMA
    if boost > 0:
        e = lum / np.maximum(1 - lum * (1 - 1 / boost), 1 / boost)
        rgb = rgb * np.where(lum > 0, e / np.where(lum > 0, lum, 1), 0)[..., None]
        lum = e
    soft = np.zeros_like(lum)
    if knee > 0:
        x = np.clip(lum - threshold + knee, 0, 2 * knee)
        soft = x * x / (4 * knee)
    w = np.where(lum > 0, np.clip(np.maximum(soft, lum - threshold) / np.where(lum > 0, lum, 1), 0, 1), 0)
    return rgb * w[..., None]


def convolve(img, psf, in_origin, out_window):
    """out(o) = sum_i img(i) psf(o - i + c), c = (kh // 2, kw // 2), zero outside the input.

    img: (h, w, C) placed at frame position in_origin = (x0, y0); psf (kh, kw) or (kh, kw, C);
    out_window = (x0, y0, x1, y1).  Direct shift-and-add in float64 (FFT in float64 for big
    problems, accurate to ~1e-16 x total energy).
    """
    img = np.asarray(img, np.float64)
    psf = np.asarray(psf, np.float64)
    if psf.ndim == 2:
        psf = np.repeat(psf[..., None], img.shape[2], axis=2)
    h, w, ch = img.shape
    kh, kw = psf.shape[:2]
    cy, cx = kh // 2, kw // 2
    fh, fw = h + kh - 1, w + kw - 1          # full result, origin at in_origin - c
    if kh * kw <= 2500:
        full = np.zeros((fh, fw, ch))
        for j in range(kh):
            for i in range(kw):
                full[j:j + h, i:i + w] += img * psf[j, i]
    else:
        sh = (fh, fw)
        full = np.stack([np.fft.irfft2(np.fft.rfft2(img[..., c], sh) * np.fft.rfft2(psf[..., c], sh), sh)
                         for c in range(ch)], axis=2)
    ox0, oy0, ox1, oy1 = out_window
    out = np.zeros((oy1 - oy0, ox1 - ox0, ch))
    fx0, fy0 = in_origin[0] - cx, in_origin[1] - cy
    xa, xb = max(ox0, fx0), min(ox1, fx0 + fw)
    ya, yb = max(oy0, fy0), min(oy1, fy0 + fh)
    if xa < xb and ya < yb:
        out[ya - oy0:yb - oy0, xa - ox0:xb - ox0] = full[ya - fy0:yb - fy0, xa - fx0:xb - fx0]
    return out


def glare(src, psf, *, strength, threshold, knee, tint=(1.0, 1.0, 1.0), boost=0.0,
          data_window=None, out_window=None, **_ignored):
    """Glare/bleed/soft_focus output covering out_window (x0, y0, x1, y1)."""
    s = sanitise(src)
    h, w = s.shape[:2]
    dw = data_window or (0, 0, w, h)
    ow = out_window or dw
    hl = highlight(s, threshold, knee, boost)
    g = convolve(hl, psf, dw[:2], ow)
    out = np.zeros((ow[3] - ow[1], ow[2] - ow[0], 4))
    # the source placed in the output window
    xa, xb = max(ow[0], dw[0]), min(ow[2], dw[2])
    ya, yb = max(ow[1], dw[1]), min(ow[3], dw[3])
    c = np.zeros_like(out)
    hh = np.zeros(out.shape[:2] + (3,))
    c[ya - ow[1]:yb - ow[1], xa - ow[0]:xb - ow[0]] = s[ya - dw[1]:yb - dw[1], xa - dw[0]:xb - dw[0]]
    hh[ya - ow[1]:yb - ow[1], xa - ow[0]:xb - ow[0]] = hl[ya - dw[1]:yb - dw[1], xa - dw[0]:xb - dw[0]]
    out[..., :3] = c[..., :3] + strength * np.asarray(tint) * g
    if boost <= 0:
        out[..., :3] -= strength * hh
    out[..., 3] = c[..., 3]
    return out


def tail_fade(k, radius, floor=1e-5, start=0.5, roll=0.9):
    """A radially decreasing (2r + 1)^2 kernel ended inside its support (plain loops): if its
    value at floor(roll r) px on the axis is above ``floor`` x its value 1 px out, times
    exp(-(d / rho)^2) with rho making it exactly that; then times a raised cosine from start r
    to r (clfx.fx.psf.tail_fade)."""
    import math

    r = int(radius)
    if r < 2:
        return np.asarray(k, np.float64)
    k1, i0 = k[r, r + 1], int(math.floor(roll * r))
    ke = k[r, r + i0]
    rho = i0 / math.sqrt(math.log(ke / (floor * k1))) if ke > floor * k1 else math.inf
    out = np.zeros_like(k, dtype=np.float64)
    for j in range(-r, r + 1):
        for i in range(-r, r + 1):
            d = math.hypot(i, j)
            t = min(max((d / r - start) / (1.0 - start), 0.0), 1.0)
            env = math.exp(-(d / rho) ** 2) if math.isfinite(rho) else 1.0
            out[j + r, i + r] = k[j + r, i + r] * (0.5 + 0.5 * math.cos(math.pi * t)) * env
    return out
