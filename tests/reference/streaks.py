"""float64 NumPy oracle of clfx/plugins/streaks.py.

``streaks`` composes the Kawase passes in float64 (each pass: 4 interpolated taps at
s * 4^n * d, d one whole pixel along the ray's major axis, zero outside the image), i.e.
exactly the kernel the plugin converges to at full resolution.  ``line_kernel_streaks`` is the
exact exponential line kernel (one interpolated tap per step k) that the passes approximate;
the tests state the difference between the two.
"""
import math
from types import SimpleNamespace

import numpy as np

from tests.reference import REC709_Y, XYZ_TO_REC709, cie1931
from tests.reference.optics_trace import reflectance


def peak_level(lum, threshold, tile=32):
    """Per pixel, the peak luminance of its light: the 8-connected region of 32 x 32 tiles
    with a pixel above threshold that holds it (0 outside every region)."""
    from scipy import ndimage

    h, w = lum.shape
    ty, tx = -(-h // tile), -(-w // tile)
    m = np.zeros((ty, tx))
    for j in range(ty):
        for i in range(tx):
            m[j, i] = lum[j * tile:(j + 1) * tile, i * tile:(i + 1) * tile].max()
    labels, n = ndimage.label(m > threshold, structure=np.ones((3, 3)))
    peaks = np.zeros((ty, tx))
    for k in range(1, n + 1):
        peaks[labels == k] = m[labels == k].max()
    return np.kron(peaks, np.ones((tile, tile)))[:h, :w]


def highlights(src, threshold, core=0.0, source_color=1.0, core_power=0.0):
    """The light that streaks: above max(threshold, core x the peak near it), weighted by
    (lum / peak)^core_power, its colour mixed towards its luminance by 1 - source_color."""
    c = np.where(np.isfinite(src), src, 0.0).astype(np.float64)
    c = np.maximum(c, 0.0)
    lum = 0.2126 * c[..., 0] + 0.7152 * c[..., 1] + 0.0722 * c[..., 2]
    peak = peak_level(lum, threshold)
    level = np.where(peak > 0, np.maximum(threshold, core * peak), np.inf) if core > 0 \
        else threshold                       # with a core rule, light in no light's tile: none
    k = np.where(lum > level, (lum - np.where(np.isfinite(level), level, 0.0))
                 / np.where(lum > 0, lum, 1.0), 0.0)
    if core_power > 0:
        ratio = np.clip(lum / np.where(peak > 0, peak, 1.0), 0, 1)
        k = k * np.where(peak > 0, ratio, 1.0) ** core_power
    out = c * k[..., None]
    hl = 0.2126 * out[..., 0] + 0.7152 * out[..., 1] + 0.0722 * out[..., 2]
    out[..., :3] = hl[..., None] + (out[..., :3] - hl[..., None]) * source_color
    out[..., 3] = 0.0
    return out, c


def splat(points, img):
    """``img`` plus the points [(x, y, rgb)] splatted bilinearly (in place)."""
    h, w = img.shape[:2]
    for cx, cy, e in points:
        ix, iy = int(np.floor(cx)), int(np.floor(cy))
        for u in (ix, ix + 1):
            for v in (iy, iy + 1):
                if 0 <= u < w and 0 <= v < h:
                    img[v, u, :3] += e * max(1 - abs(cx - u), 0) * max(1 - abs(cy - v), 0)
    return img


def seed_list(src, threshold, core=0.0, source_color=1.0, core_power=0.0, radius=1,
              ring_share=0.1):
    """Each compact light's streaking light gathered into one point: a pixel with streaking
    light whose luminance is the highest within ``radius`` (Chebyshev; ties to the earlier
    pixel in raster order) and whose window's border ring has none above ``ring_share`` of
    its own takes the window's streaking light to its weighted centroid.  Returns the points
    [(x, y, rgb)], the streaking light of the pixels no point gathered (an image) and the
    sanitised source."""
    hl, c = highlights(src, threshold, core, source_color, core_power)
    h, w = c.shape[:2]
    lum = c[..., :3] @ np.array([0.2126, 0.7152, 0.0722])
    hlum = hl[..., :3] @ np.array([0.2126, 0.7152, 0.0722])
    points = []
    gathered = np.zeros((h, w), bool)
    order = np.arange(h * w).reshape(h, w)
    for y, x in zip(*np.nonzero((hl[..., :3] > 0).any(axis=2))):
        y0, y1, x0, x1 = max(y - radius, 0), min(y + radius + 1, h), max(x - radius, 0), \
            min(x + radius + 1, w)
        win, idx = lum[y0:y1, x0:x1], order[y0:y1, x0:x1]
        if (win > lum[y, x]).any() or ((win == lum[y, x]) & (idx < order[y, x])).any():
            continue
        ring = np.maximum(np.abs(np.arange(y0, y1) - y)[:, None],
                          np.abs(np.arange(x0, x1) - x)[None, :]) == radius
        if (hlum[y0:y1, x0:x1][ring] > ring_share * hlum[y, x]).any():
            continue                                    # an extended light
        gathered[y0:y1, x0:x1] = True
        e = hl[y0:y1, x0:x1, :3].reshape(-1, 3).sum(axis=0)
        wt = hlum[y0:y1, x0:x1]
        ys, xs = np.mgrid[y0:y1, x0:x1]
        points.append(((wt * xs).sum() / wt.sum(), (wt * ys).sum() / wt.sum(), e)
                      if wt.sum() > 0 else (x, y, e))
    out = np.zeros_like(hl)
    out[~gathered, :3] = hl[~gathered, :3]
    return points, out, c


def shifted(img, dx, dy):
    """img sampled at (x + dx, y + dy), bilinear, zero outside."""
    h, w = img.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    u, v = xs + dx, ys + dy
    u0, v0 = np.floor(u), np.floor(v)
    fu, fv = (u - u0)[..., None], (v - v0)[..., None]
    out = np.zeros_like(img)
    for ox, oy, wt in ((0, 0, (1 - fu) * (1 - fv)), (1, 0, fu * (1 - fv)),
                       (0, 1, (1 - fu) * fv), (1, 1, fu * fv)):
        xi, yi = (u0 + ox).astype(int), (v0 + oy).astype(int)
        ok = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
        out[ok] += wt[ok] * img[yi[ok], xi[ok]]
    return out


def aperture_spikes(blades, rotation):
    """Directions (degrees, counter-clockwise from +x, screen up) of the diffraction spikes
    of a regular aperture, from its geometry: the far field of a straight edge is a line
    through the light perpendicular to the edge, on both sides.  The polygon's vertices lie
    at ``rotation + 360 i / blades`` on the unit circle; each edge's direction is the
    difference of its two vertices, its spike the perpendicular of that; parallel edges
    (opposite sides of an even polygon) give the same spike.  None for a round aperture."""
    if blades < 3:
        return []
    vx = [math.cos(math.radians(rotation + 360.0 * i / blades)) for i in range(blades + 1)]
    vy = [math.sin(math.radians(rotation + 360.0 * i / blades)) for i in range(blades + 1)]
    found = set()
    for i in range(blades):
        ex, ey = vx[i + 1] - vx[i], vy[i + 1] - vy[i]
        for nx, ny in ((ey, -ex), (-ey, ex)):           # both perpendiculars
            found.add(round(math.degrees(math.atan2(ny, nx)) % 360.0, 9) % 360.0)
    return sorted(found)


def angles_of(mode, streaks, angle, blades, blade_rotation):
    """The rays' directions as the descriptor states them: a star filter's ``streaks`` rays
    evenly around from ``angle``; an anamorphic lens's one horizontal line turned by
    ``angle`` (its two halves); an aperture's spikes (:func:`aperture_spikes`), the polygon
    turned by the camera's blade rotation and ``angle``."""
    if mode == "star":
        return [angle + 360.0 * i / streaks for i in range(streaks)]
    if mode == "anamorphic":
        return [angle, angle + 180.0]
    return aperture_spikes(blades, blade_rotation + angle)


def _setup(lengths_frac, diagonal, color_shift, step_len, scale=(1.0, 1.0, 1.0)):
    """Per-channel decay per step, pass count and taps of the last pass: the support
    top x 4^(n - 1) is the smallest >= 2.5 L + 1 (where the exponential is 1e-5 of its start);
    a step is ``step_len`` px long; ``scale`` multiplies each channel's length."""
    L = lengths_frac * diagonal * (1 + 0.5 * color_shift * np.array([1.0, 0.0, -1.0]))
    L = L * np.asarray(scale)
    L = L / step_len
    a = 0.01 ** (1.0 / L)
    need = math.log(1e5) / math.log(100) * max(L.max(), 1.0) + 1
    n = 1
    while 4 ** n < need - 1e-9:
        n += 1
    top = 1
    while top * 4 ** (n - 1) < need - 1e-9:
        top += 1
    return a, n, top


COATING_DESIGNS = {
    "mgf2": ((1.38, 1.0),),
    "v-coat": ((1.38, 1.0), (1.63, 1.0)),
    "broadband": ((1.38, 1.0), (2.05, 2.0), (1.63, 1.0)),
    "broadband-hi": ((1.38, 1.0), (2.10, 2.0), (1.70, 1.0)),
}
"""Anti-reflection stacks, films from the air side as (index, quarter waves at the design
wavelength): one quarter wave of MgF2 (1.38); the V-coat MgF2 / Al2O3 (1.63); the
quarter-half-quarter broadband MgF2 / ZrO2 (2.05) / Al2O3, and with ZrO2 2.10 / a 1.70 film
(H. A. Macleod, *Thin-Film Optical Filters*, 4th ed., ch. 4).  tests/test_oracles.py checks
the effect's table (clfx.fx.optics.MULTILAYER_DESIGNS) against these."""

CROWN_GLASS_INDEX = 1.52
"""The substrate the streaks' coating is on (crown glass, n_d ~ 1.52)."""


def coating_tint(design_nm, design="v-coat", bins=80):
    """RGB (linear Rec.709, luminance 1) of white light reflected twice off the coating stack
    ``design`` designed at ``design_nm`` on crown glass at normal incidence.

    The stack's reflectance R(lambda) by the film-by-film Airy recursion of
    tests/reference/optics_trace.py; twice reflected: R^2.  Its colour: the CIE 1931 observer
    (tests.reference.cie1931) integrated over 380-780 nm by the midpoint rule on ``bins``
    equal bins (the effect's 80), into Rec.709 (XYZ_TO_REC709), each channel relative to an
    equal-energy white's (a grey reflector stays grey); then desaturated towards its own
    luminance just enough that no channel is negative, and scaled to luminance 1."""
    edges = np.linspace(380.0, 780.0, bins + 1)
    lam = 0.5 * (edges[:-1] + edges[1:])
    films = SimpleNamespace(layers=COATING_DESIGNS[design], wavelength_nm=design_nm)
    twice = reflectance(1.0, CROWN_GLASS_INDEX, 1.0, films, lam) ** 2
    xyz = cie1931(lam)
    rgb = XYZ_TO_REC709 @ (twice @ xyz) / (XYZ_TO_REC709 @ xyz.sum(axis=0))
    y = float(rgb @ REC709_Y)
    negative = rgb < 0
    if negative.any():      # mix(rgb, y, k) >= 0 in every channel: the least such k
        k = max(c / (c - y) for c in rgb[negative])
        rgb = (1.0 - k) * rgb + k * y
    rgb = np.maximum(rgb, 0.0)
    return rgb / float(rgb @ REC709_Y)


def _unit(angle):
    """Step of one whole pixel along the ray's major axis: (dx, dy, length)."""
    t = math.radians(angle)
    dx, dy = math.cos(t), -math.sin(t)
    dx, dy = (0.0 if abs(dx) < 1e-12 else dx, 0.0 if abs(dy) < 1e-12 else dy)
    major = max(abs(dx), abs(dy))
    return dx / major, dy / major, 1.0 / major


def _ray_grid_chain(points, ext, sx, sy, f, a, n, top, gain):
    """One ray (x-major: |sx| = 1 >= |sy|) on its ray-aligned working grid, reduced ``f``
    times in x (clfx/plugins/streaks.py `ray_grid`): the light gathered onto the grid, the
    Kawase passes there, upsampled along the ray to the canvas (float64).  ``points``: [(x,
    y, rgb)] canvas pixels; ``ext``: the rest of the streaking light (canvas image)."""
    h, w = ext.shape[:2]
    shear = float(np.float32(sy / sx))          # as the device holds it
    wl, mid, ex = -(-w // f) + 2, f // 2, f      # the grid has a working pixel each side
    lead = int(math.copysign(mid, sx))
    grid = np.zeros((h, wl, 4))
    # run of f canvas pixels along the ray's line through each working pixel's centre,
    # `lead` pixels ahead; each taken from the nearest row of that line
    X, Y = np.meshgrid(np.arange(wl), np.arange(h))
    for i in range(f):
        along = i - mid + lead
        off = int(np.floor(np.float32(shear) * np.float32(along) + np.float32(0.5)))
        xs, ys = X * f + mid + along - ex, Y + off
        ok = (xs >= 0) & (xs < w) & (ys >= 0) & (ys < h)
        grid[ok, :3] += ext[ys[ok], xs[ok], :3] / f
    for px, py, e in points:                     # moved `lead` back along the line
        gx, gy = (px + ex + 0.5 * (f % 2)) / f - 0.5 - lead / f, py - shear * lead
        for u in (math.floor(gx), math.floor(gx) + 1):
            cy = gy + shear * f * (u - gx)
            for v in (math.floor(cy), math.floor(cy) + 1):
                wt = max(1 - abs(gx - u), 0) * max(1 - abs(cy - v), 0)
                if 0 <= u < wl and 0 <= v < h and wt > 0:
                    grid[v, u, :3] += np.asarray(e) / f * wt
    cur = grid
    for p in range(n):
        b = 4 ** p
        nxt = np.zeros_like(cur)
        for s in range(top if p == n - 1 else 4):
            nxt[..., :3] += a ** (s * b) * shifted(cur, s * b * sx, s * b * f * sy)[..., :3]
        cur = nxt
    support = top * 4 ** (n - 1)
    cur[..., :3] *= gain / ((1 - a ** support) / (1 - a))
    # along the ray: linear between the two working columns around each pixel (clamped at
    # the grid's ends), in each at the row where the ray through the pixel crosses it
    out = np.zeros((h, w, 4))
    ys, xs = np.mgrid[0:h, 0:w]
    t = (xs + ex - mid) / f
    t0 = np.floor(t)
    for k, wk in ((0, 1 - (t - t0)), (1, t - t0)):
        u = np.clip(t0.astype(int) + k, 0, wl - 1)
        r = ys + shear * (u * f + mid - xs - ex)
        r0 = np.floor(r)
        for j, wv in ((0, 1 - (r - r0)), (1, r - r0)):
            v = r0.astype(int) + j
            ok = (v >= 0) & (v < h)
            out[ok, :3] += (wk * wv)[ok, None] * cur[v[ok], u[ok], :3]
    return out


def ray_grid_streak(points, ext, dx, dy, f, a, n, top, gain):
    """`_ray_grid_chain` for a ray of either major axis (a y-major ray is an x-major one of
    the transposed canvas: the grid is reduced in y)."""
    if abs(dx) >= abs(dy):
        return _ray_grid_chain(points, ext, dx, dy, f, a, n, top, gain)
    tp = [(py, px, e) for px, py, e in points]
    return _ray_grid_chain(tp, ext.transpose(1, 0, 2), dy, dx, f, a, n, top,
                           gain).transpose(1, 0, 2)


def streaks(src, *, threshold, intensity, mode, streaks, angle, blades, length, tint,
            color_shift, core=0.0, source_color=1.0, core_power=-1.0, coating_nm=740.0,
            coating="v-coat",
            diagonal=None, blade_rotation=0.0, pad=0, line_kernel=False, seed_radius=0.012,
            factor=1):
    """Output over the source grown by ``pad`` pixels on every side (float64).

    ``factor`` > 1: draft / preview, each ray on its ray-aligned working grid reduced
    ``factor`` times along its major axis (`ray_grid_streak`).

    mode "anamorphic": rays at angle and angle + 180, colour tint x coating_tint(coating_nm),
    two exponentials (1 % at 0.15 length with 70 % of the light, at length with 30 %),
    core_power -1 = 3 (else 0).  mode "aperture": three exponentials (1 % at 0.08, 0.3 and 1
    length with 6.8, 24.6 and 68.6 % of the light), each channel's length times its
    wavelength over 550 nm (610, 550, 465 nm)."""
    src = np.asarray(src, np.float64)
    h, w = src.shape[:2]
    diagonal = diagonal or math.hypot(w, h)
    if core_power < 0:
        core_power = 3.0 if mode == "anamorphic" else 0.0
    radius = max(1, round(seed_radius * diagonal))
    points, ext, clean = seed_list(src, threshold, core, source_color, core_power, radius)
    bright = np.pad(splat(points, ext.copy()), ((pad, pad), (pad, pad), (0, 0)))
    points = [(x + pad, y + pad, e) for x, y, e in points]
    ext = np.pad(ext, ((pad, pad), (pad, pad), (0, 0)))
    out = np.pad(clean, ((pad, pad), (pad, pad), (0, 0)))
    rays = angles_of(mode, streaks, angle, blades, blade_rotation)
    colour = np.asarray(tint, np.float64)
    parts = [(1.0, 1.0)]
    if mode == "anamorphic":
        colour = colour * coating_tint(coating_nm, coating)
        parts = [(0.15, 0.7), (1.0, 0.3)]
    scale = (1.0, 1.0, 1.0)
    if mode == "aperture":
        # three exponentials after 1 / (1 + 9 r / L)^2; lengths in proportion to 610, 550, 465 nm
        parts = [(0.08, 0.068), (0.3, 0.246), (1.0, 0.686)]
        scale = (610.0 / 550.0, 1.0, 465.0 / 550.0)
    for (fraction, share), ang in [(pt, ang) for pt in parts for ang in rays]:
        gain = intensity * share * colour / len(rays)
        dx, dy, step_len = _unit(ang)
        if factor > 1:
            a, n, top = _setup(fraction * length, diagonal, color_shift, step_len * factor,
                               scale)
            out += ray_grid_streak(points, ext, dx, dy, factor, a, n, top, gain)
            continue
        a, n, top = _setup(fraction * length, diagonal, color_shift, step_len, scale)
        support = top * 4 ** (n - 1)
        total = (1 - a ** support) / (1 - a)
        if line_kernel:
            acc = np.zeros_like(bright)
            for k in range(support):
                acc[..., :3] += a ** k * shifted(bright, k * dx, k * dy)[..., :3]
            cur = acc
        else:
            cur = bright
            for p in range(n):
                b = 4 ** p
                nxt = np.zeros_like(cur)
                for s in range(top if p == n - 1 else 4):
                    ox, oy = s * b * dx, s * b * dy
                    nxt[..., :3] += a ** (s * b) * shifted(cur, ox, oy)[..., :3]
                cur = nxt
        out[..., :3] += cur[..., :3] * (gain / total)
    return out


def line_kernel_streaks(src, **kw):
    """Same as ``streaks`` with the exact exponential line kernel (one bilinear tap per k)."""
    return streaks(src, line_kernel=True, **kw)
