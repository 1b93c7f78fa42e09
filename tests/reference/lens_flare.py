"""float64 NumPy oracle of clfx/plugins/lens_flare.py: plain tile labelling (scipy.ndimage),
per-source flux and centroid, and every ghost and halo evaluated at every pixel.  Luminance is
the working space's: the Y row of ``rgb_to_xyz`` (None: BT.709's weights)."""
import math

import numpy as np
from scipy import ndimage

from tests.reference.corona import luminance_weights




def _highlight(src, threshold, rgb_to_xyz=None):
    c = np.maximum(np.where(np.isfinite(src), src, 0.0).astype(np.float64), 0.0)
    wr, wg, wb = luminance_weights(rgb_to_xyz)
    lum = wr * c[..., 0] + wg * c[..., 1] + wb * c[..., 2]
    k = np.where(lum > threshold, (lum - threshold) / np.where(lum > 0, lum, 1.0), 0.0)
    return c[..., :3] * k[..., None], np.maximum(lum - threshold, 0.0), c, lum


def sources(src, threshold, *, origin=(0, 0), display=None, margin_px=0, max_sources=8,
            tile=32, rgb_to_xyz=None):
    """[(x, y, flux)] in frame pixels: 8-connected regions of tiles with a pixel above
    threshold, refined over each region's bounding box."""
    src = np.asarray(src, np.float64)
    h, w = src.shape[:2]
    hl, wt, clean, lum = _highlight(src, threshold, rgb_to_xyz)
    finite = np.isfinite(src).all(axis=2)
    ty, tx = -(-h // tile), -(-w // tile)
    tmax = np.zeros((ty, tx))
    tsum = np.zeros((ty, tx))
    for j in range(ty):
        for i in range(tx):
            blk = lum[j * tile:(j + 1) * tile, i * tile:(i + 1) * tile]
            ok = finite[j * tile:(j + 1) * tile, i * tile:(i + 1) * tile]
            tmax[j, i] = blk[ok].max() if ok.any() else 0.0
            tsum[j, i] = blk[ok].sum() / blk.size
    labels, n = ndimage.label(tmax > threshold, structure=np.ones((3, 3)))
    out = []
    for lab in range(1, n + 1):
        ys, xs = np.nonzero(labels == lab)
        x0, x1 = xs.min() * tile, min(w, (xs.max() + 1) * tile)
        y0, y1 = ys.min() * tile, min(h, (ys.max() + 1) * tile)
        if display is not None:
            dx0, dy0, dx1, dy1 = display
            if (origin[0] + x1 <= dx0 - margin_px or origin[0] + x0 >= dx1 + margin_px
                    or origin[1] + y1 <= dy0 - margin_px or origin[1] + y0 >= dy1 + margin_px):
                continue
        energy = tsum[ys, xs].sum()
        wsum = wt[y0:y1, x0:x1].sum()
        if wsum <= 0:
            continue
        yy, xx = np.mgrid[y0:y1, x0:x1] + 0.5
        cx = (wt[y0:y1, x0:x1] * xx).sum() / wsum + origin[0]
        cy = (wt[y0:y1, x0:x1] * yy).sum() / wsum + origin[1]
        out.append((energy, cx, cy, hl[y0:y1, x0:x1].sum(axis=(0, 1))))
    out.sort(key=lambda s: -s[0])
    return [(x, y, f) for _, x, y, f in out[:max_sources]]


def _edge(rho, edge):
    s = np.clip((1 - rho) / edge, 0, 1)
    return s * s * (3 - 2 * s)


def _rho(dx, dy, blades, rotation, roundness):
    circle = np.hypot(dx, dy)
    if blades < 3:
        return circle
    t = math.radians(rotation) + math.pi * (2 * np.arange(blades) + 1) / blades
    poly = np.max([dx * math.cos(a) - dy * math.sin(a) for a in t], axis=0)
    poly = poly / math.cos(math.pi / blades)
    return poly + (circle - poly) * roundness


def _area(blades, rotation, roundness, edge, rim, n=1200):
    """Coverage integral in units of r^2 by brute force on an n x n grid over [-1, 1]^2."""
    u = (np.arange(n) + 0.5) / n * 2 - 1
    dx, dy = np.meshgrid(u, u)
    rho = _rho(dx, dy, blades, rotation, roundness)
    return float((_edge(rho, edge) * (1 - rim + rim * rho ** 2)).sum() * (2.0 / n) ** 2)


def lens_flare(src, lights, table, *, intensity, softness, roundness, rim, blades, rotation,
               halo_radius, halo_width, halo_intensity, origin=(0, 0), display=None, **_):
    """Output over the source window (frame origin ``origin``); ``display`` = (x0, y0, x1, y1)."""
    src = np.asarray(src, np.float64)
    h, w = src.shape[:2]
    display = display or (0, 0, w, h)
    cx, cy = (display[0] + display[2]) / 2, (display[1] + display[3]) / 2
    diag = math.hypot(display[2] - display[0], display[3] - display[1])
    _, _, clean, _ = _highlight(src, 0.0)
    out = clean.copy()
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    px, py = xx + origin[0] + 0.5, yy + origin[1] + 0.5
    for lx, ly, flux in lights:
        for k, size, tint, soft, g_rim in table:
            soft = softness if soft is None else soft
            g_rim = rim if g_rim is None else g_rim
            r = size * diag
            gx, gy = cx + k * (lx - cx), cy + k * (ly - cy)
            dx, dy = px - gx, py - gy
            circle = np.hypot(dx, dy) / r
            if blades >= 3:
                t = math.radians(rotation) + math.pi * (2 * np.arange(blades) + 1) / blades
                proj = max_proj = None
                for a in t:
                    proj = dx * math.cos(a) - dy * math.sin(a)
                    max_proj = proj if max_proj is None else np.maximum(max_proj, proj)
                poly = max_proj / (r * math.cos(math.pi / blades))
                rho = poly + (circle - poly) * roundness
            else:
                rho = circle
            edge = max(soft, 1.5 / r)
            wgt = _edge(rho, edge) * (1 - g_rim + g_rim * rho ** 2)
            area = _area(blades, rotation, roundness, edge, g_rim) * r * r
            out[..., :3] += wgt[..., None] * intensity * np.asarray(tint) * flux / area
        if halo_intensity > 0:
            rh, sigma = halo_radius * diag, max(halo_width * diag, 0.5)
            d = np.hypot(px - cx, py - cy)
            dl = math.hypot(lx - cx, ly - cy)
            ux, uy = ((lx - cx) / dl, (ly - cy) / dl) if dl > 1e-6 else (0.0, 0.0)
            m = 0.5 + 0.5 * ((px - cx) * ux + (py - cy) * uy) / np.maximum(d, 1e-6)
            ring = np.exp(-0.5 * ((d - rh) / sigma) ** 2) * m * m
            norm = 2 * math.pi * rh * sigma * math.sqrt(2 * math.pi) * 0.375
            out[..., :3] += ring[..., None] * halo_intensity * flux / norm
    return out


# -- the physical model ----------------------------------------------------------------------
def lights(src, threshold, *, origin=(0, 0), tile=32, rgb_to_xyz=None):
    """[(x, y, flux RGB, rms radius)] of the physical model: per 8-connected region of tiles
    with a pixel above threshold, the sum of its pixels above threshold (whole values), their
    luminance-weighted centroid and rms radius about it (frame px)."""
    src = np.asarray(src, np.float64)
    h, w = src.shape[:2]
    clean = np.maximum(np.where(np.isfinite(src), src, 0.0), 0.0)
    wr, wg, wb = luminance_weights(rgb_to_xyz)
    lum = wr * clean[..., 0] + wg * clean[..., 1] + wb * clean[..., 2]
    ty, tx = -(-h // tile), -(-w // tile)
    tmax = np.zeros((ty, tx))
    for j in range(ty):
        for i in range(tx):
            tmax[j, i] = lum[j * tile:(j + 1) * tile, i * tile:(i + 1) * tile].max()
    labels, n = ndimage.label(tmax > threshold, structure=np.ones((3, 3)))
    out = []
    for lab in range(1, n + 1):
        ys, xs = np.nonzero(labels == lab)
        x0, x1 = xs.min() * tile, min(w, (xs.max() + 1) * tile)
        y0, y1 = ys.min() * tile, min(h, (ys.max() + 1) * tile)
        wt = np.where(lum[y0:y1, x0:x1] > threshold, lum[y0:y1, x0:x1], 0.0)
        flux = (clean[y0:y1, x0:x1, :3] * (wt > 0)[..., None]).sum(axis=(0, 1))
        yy, xx = np.mgrid[y0:y1, x0:x1] + 0.5
        mx, my = (wt * xx).sum() / wt.sum(), (wt * yy).sum() / wt.sum()
        rms = math.sqrt(max((wt * ((xx - mx) ** 2 + (yy - my) ** 2)).sum() / wt.sum(), 0.0))
        out.append((wt.sum(), mx + origin[0], my + origin[1], flux, rms))
    out.sort(key=lambda s: -s[0])
    return [(x, y, f, r) for _, x, y, f, r in out]


def edge(table, row, t, reach):
    """The edge profile of clfx.fx.flare (its float64 table, sampled over t in [-reach,
    reach], both given by the test), linear in t, 1 / 0 beyond."""
    n = table.shape[1]
    x = np.clip((np.asarray(t) + reach) * (n - 1) / (2 * reach), 0, n - 1)
    i = np.minimum(np.floor(x).astype(int), n - 2)
    f = x - i
    return table[int(row), i] * (1 - f) + table[int(row), i + 1] * f


def physical_ghosts(shape, entries, normals, table, *, reach, origin=(0, 0)):
    """The ghost layer (h, w, 3) of ``entries`` (clfx.fx.flare.plan_entries) evaluated at
    every pixel centre in float64: per channel the signed distance to the channel's edge
    (a disc, or the polygon's largest normal projection shifted along the axis by its
    nearest face), the edge profile, the clip discs' profiles, times the radiance."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    px, py = xx + origin[0] + 0.5, yy + origin[1] + 0.5
    out = np.zeros((h, w, 3))
    for e in np.asarray(entries, np.float64):
        dx, dy = px - e[0], py - e[1]
        ux, uy = e[2], e[3]
        row = e[17]
        if e[16] != 0:
            proj = np.stack([e[16] * (dx * n[0] + dy * n[1]) for n in normals])
            best = np.argmax(proj, axis=0)
            nu = np.array([e[16] * (n[0] * ux + n[1] * uy) for n in normals])[best]
            pm = proj.max(axis=0)
            dist = [pm - e[4 + c] * nu - e[7 + c] for c in range(3)]
        else:
            dist = [np.hypot(dx - e[4 + c] * ux, dy - e[4 + c] * uy) - e[7 + c] for c in range(3)]
        clip = np.ones((h, w))
        for col in (18, 20):
            if e[col + 1] > 0:
                d = np.hypot(dx - e[col] * ux, dy - e[col] * uy) - e[col + 1]
                clip = clip * edge(table, row, d * e[11], reach)
        for c in range(3):
            out[..., c] += e[13 + c] * clip * edge(table, row, dist[c] * e[10 + c], reach)
    return out
