"""Drawing physically based lens-flare ghosts: from a ghost table and measured lights to the
entries and tile lists the lens-flare kernel gathers (host NumPy, float64).

Notes
-----
**What a ghost looks like.**  :mod:`clfx.fx.optics` gives, per ghost and wavelength, the
image of the limiting aperture on the sensor (centre on the line through the optical centre
and the light, radius, orientation), the clip discs cutting it and the fraction of the
light it carries.  Paraxially the ghost is uniformly lit.  Its edge is softened by:

- *Fresnel diffraction* at the aperture rim: the rim is seen out of focus (it is sharp only
  in the plane conjugate to the aperture), so its shadow on the sensor shows Fresnel's
  straight-edge pattern ``I(xi) = ((1/2 + C(xi))^2 + (1/2 + S(xi))^2) / 2`` with ``xi = -d /
  w``, ``w = sqrt(lambda |B m| / 2)`` (``GhostTable.edge_bm_mm``; C, S the Fresnel
  integrals; Born & Wolf sec. 8.7): a bright fringe (1.37 times the interior) just inside the
  geometric edge, ringing that fades inwards, a smooth fall outside.  This is the "brighter
  rim" of real ghosts at the scale of a few pixels (Lee & Eisemann 2013 precompute the same
  ringing for their aperture texture).
- the light's *extent*: an extended source of rms radius ``s`` maps to its ghost scaled by
  the ghost's centre factor ``c`` (the ghost of a light at ``x`` is centred at ``c x``), a
  Gaussian blur of the edge with standard deviation ``|c| s / sqrt(2)``;
- the *spectral* spread inside one colour channel: the channel's wavelengths give ghosts of
  slightly different sizes and positions (their weighted standard deviation blurs the edge;
  their means place the channel's edge, so the channels' edges differ: coloured fringes);
- *aberrations*, which the matrices leave out: third-order blur relative to the ghost grows
  as the square of the paraxial incidence angle; estimated as ``0.5 * incidence^2 *
  radius``.  Ghosts whose incidence exceeds ``0.5`` rad fade linearly to nothing at
  ``1.0`` rad: there the table is unreliable (``tests/fx/test_optics.py``) and the real
  ghost is spread into a faint caustic.

The edge profile is the Fresnel pattern of fringe width ``w`` convolved with the Gaussian of
those blurs (``sigma``, plus 0.3 px for the pixel's own footprint): a table ``G(q, t)`` over
``t = d / (w + sigma)`` (``d`` the signed distance to the edge, positive outside) and
``q = sigma / (w + sigma)``, tapered to exactly 1 and 0 beyond ``EDGE_REACH`` units.

**Brightness.**  A light whose pixels sum to ``F`` (per channel) entered the lens with
``F / T_p`` (``primary_transmission``); the ghost at wavelength ``lambda`` carries ``F *
energy / T_p`` (times the part clip discs leave, ``area_fraction``; times ``pi /
polygon_area`` for a ghost limited by a round lens rim when the stop is a polygon, since
``energy`` compares disc areas).  Channel ``c`` spreads over the wavelength samples with
``clfx.fx.spectral.channel_weights``: its ghost power is ``F_c * sum_lambda w_c(lambda) *
energy(lambda) / T_p(lambda)``.  The drawn radiance is that power over the soft shape's
area (the integral of its edge profile), so every ghost carries exactly its power, however
soft: dim ghosts by the physics (two coated reflections: 1e-4 to 1e-6 of the light), no
fudge factor; ``gain`` (default 1) multiplies them for looks that want more.

**Drawing.**  Each (light, ghost) becomes an entry; a ghost whose peak radiance stays below
the visible level is dropped.  Entries are drawn at a resolution their softness allows
(level ``k`` renders at ``1 / 2^k``; an edge of scale ``w + sigma >= 2^(k+1)`` pixels is
smooth at that level and is upsampled bilinearly), so heavily blurred ghosts cost little.
On each level a tile is, for each entry, outside it, on its edge (the entry goes into the
tile's list and is evaluated per pixel) or deep inside it and its clip discs (a constant,
summed per tile on the host): only edges cost per-pixel work.

References
----------
.. [1] S. Lee and E. Eisemann, "Practical real-time lens-flare rendering", EGSR 2013.
.. [2] M. Hullin et al., "Physically-based real-time lens flare rendering", SIGGRAPH 2011.
.. [3] M. Born and E. Wolf, "Principles of Optics", 7th ed., sec. 8.7 (Fresnel diffraction
   at a straight edge); S. A. Collins, "Lens-system diffraction integral written in terms of
   matrix optics", JOSA 60 (1970) 1168 (the ``B`` of a ray-transfer matrix in Fresnel's
   integral).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

EDGE_ROWS = 33
"""Rows of the edge-profile table: q = sigma / (w + sigma) from 0 to 1."""
EDGE_SAMPLES = 129
"""Samples of each row over t in [-EDGE_REACH, EDGE_REACH]."""
EDGE_REACH = 4.0
"""Beyond this many edge scales (w + sigma) a ghost is exactly 1 inside and 0 outside."""
EDGE_TAPER = 2.5
"""From here to EDGE_REACH the profile's deviation from the sharp edge tapers to 0."""
PIXEL_SIGMA = 0.3
"""Standard deviation (px) of a pixel's footprint (a unit box: 1 / sqrt(12))."""
ABERRATION_BLUR = 0.5
"""Edge blur per radius and squared paraxial incidence (third-order estimate)."""
FADE_FROM_RAD, FADE_TO_RAD = 0.5, 1.0
"""Ghosts fade out between these paraxial incidence angles."""
VEIL_FROM, VEIL_TO = 0.05, 0.1
"""Ghosts whose radius exceeds ``VEIL_FROM`` of the frame's diagonal fade (linearly) to
nothing at ``VEIL_TO``: paraxially a uniform polygon over the whole frame, in a real lens
vignetted by the barrel and smeared by aberrations into veiling glare (the glare effect).
At 0.1 / 0.2 (until issue 32) a ghost of a sun 0.1 of the diagonal wide laid a pink veil
disc round it and a candle's an orange veil beside CandleGlass's glass."""
PEAK = 1.4
FRESNEL_ASYMPTOTIC = 20.0
"""Beyond this argument Fresnel's integrals take their asymptotic form."""
"""Upper bound of the edge profile (Fresnel's first fringe: 1.37)."""

ENTRY = 24
"""Floats per kernel entry (see :func:`plan_entries`)."""


# -- the edge profile ---------------------------------------------------------------------
def fresnel_integrals(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fresnel's C(x) and S(x) (integrals of cos and sin of pi t^2 / 2 from 0 to x)."""
    x = np.asarray(x, np.float64)
    a = np.abs(x)
    top = min(float(a.max(initial=0.0)), FRESNEL_ASYMPTOTIC)
    t = np.linspace(0.0, top, max(2, int(top / 2e-4) + 2))
    ct, st = np.cos(0.5 * np.pi * t * t), np.sin(0.5 * np.pi * t * t)
    dt = t[1] - t[0]
    c = np.concatenate([[0.0], np.cumsum(0.5 * (ct[1:] + ct[:-1]) * dt)])
    s = np.concatenate([[0.0], np.cumsum(0.5 * (st[1:] + st[:-1]) * dt)])
    far = a > FRESNEL_ASYMPTOTIC               # C, S -> 1/2 + (sin, -cos)(pi x^2 / 2) / (pi x)
    with np.errstate(divide="ignore", invalid="ignore"):
        ph = 0.5 * np.pi * a * a
        ca = np.where(far, 0.5 + np.sin(ph) / (np.pi * a), np.interp(a, t, c))
        sa = np.where(far, 0.5 - np.cos(ph) / (np.pi * a), np.interp(a, t, s))
    return np.sign(x) * ca, np.sign(x) * sa


def fresnel_edge(xi: np.ndarray) -> np.ndarray:
    """Irradiance behind a straight edge (1 far on the lit side, ``xi > 0``)."""
    c, s = fresnel_integrals(xi)
    return 0.5 * ((0.5 + c) ** 2 + (0.5 + s) ** 2)


def edge_q_values(rows: int = EDGE_ROWS) -> np.ndarray:
    return np.linspace(0.0, 1.0, rows)


def edge_t_values(samples: int = EDGE_SAMPLES) -> np.ndarray:
    return np.linspace(-EDGE_REACH, EDGE_REACH, samples)


def edge_table(rows: int = EDGE_ROWS, samples: int = EDGE_SAMPLES) -> np.ndarray:
    """``G(q, t)``, shape (rows, samples): the edge profile of a ghost (module notes).

    ``t = d / (w + sigma)`` with ``d`` the signed distance to the geometric edge (px,
    positive outside), ``q = sigma / (w + sigma)``: row 0 is pure Fresnel diffraction, the
    last row a Gaussian-blurred step.  The deviation from the sharp step tapers (raised
    cosine) to 0 between ``EDGE_TAPER`` and ``EDGE_REACH``.
    """
    t = edge_t_values(samples)
    step = 0.01
    d = np.arange(-EDGE_REACH - 6.0, EDGE_REACH + 6.0 + step / 2, step)
    sharp = (d < 0.0).astype(np.float64) + 0.5 * (d == 0.0)
    out = np.empty((rows, samples))
    for k, q in enumerate(edge_q_values(rows)):
        w, sigma = 1.0 - q, q
        prof = fresnel_edge(-d / w) if w > 1e-3 else sharp
        if sigma > 1e-3:
            half = int(math.ceil(5.0 * sigma / step))
            g = np.exp(-0.5 * (np.arange(-half, half + 1) * step / sigma) ** 2)
            g /= g.sum()
            pad = np.concatenate([np.ones(half), prof, np.zeros(half)])
            prof = np.convolve(pad, g, mode="valid")
        out[k] = np.interp(t, d, prof)
    step_t = (t < 0.0).astype(np.float64) + 0.5 * (t == 0.0)
    a = np.clip((np.abs(t) - EDGE_TAPER) / (EDGE_REACH - EDGE_TAPER), 0.0, 1.0)
    taper = 0.5 + 0.5 * np.cos(np.pi * a)
    return step_t + (out - step_t) * taper


def edge_value(table: np.ndarray, row, t) -> np.ndarray:
    """``table[row]`` at ``t`` (linear interpolation; 1 below, 0 above the sampled range)."""
    samples = table.shape[1]
    x = np.clip((np.asarray(t, np.float64) + EDGE_REACH) * ((samples - 1) / (2 * EDGE_REACH)),
                0.0, samples - 1.0)
    i = np.minimum(np.floor(x).astype(np.int64), samples - 2)
    f = x - i
    row = np.asarray(row, np.int64)
    return table[row, i] * (1.0 - f) + table[row, i + 1] * f


AREA_RATIOS = np.geomspace(1e-2, 1e4, 97)
"""Apothem / edge scale ratios of the soft-area table."""


def area_table(edge: np.ndarray) -> np.ndarray:
    """``A(q, a)``, shape (rows, len(AREA_RATIOS)): the soft shape's area over its sharp
    area, for apothem ``a`` edge scales.  The gauge of a convex shape scales its area as
    ``tau^2``, so ``A = integral of G(q, a (tau - 1)) d(tau^2)`` for a disc and a regular
    polygon alike."""
    out = np.empty((edge.shape[0], AREA_RATIOS.size))
    rows = np.arange(edge.shape[0])[:, None]
    for j, a in enumerate(AREA_RATIOS):
        top = 1.0 + EDGE_REACH / a
        tau = np.linspace(0.0, top, 1501)
        f = edge_value(edge, rows, a * (tau[None, :] - 1.0)) * 2.0 * tau[None, :]
        out[:, j] = np.sum(0.5 * (f[:, 1:] + f[:, :-1]), axis=1) * (tau[1] - tau[0])
    return out


def soft_area(areas: np.ndarray, row, ratio) -> np.ndarray:
    """Interpolate :func:`area_table` at rows ``row`` and apothem / scale ``ratio``; below
    the table the shape is a blur of fixed area, ``A ~ ratio^-2``."""
    ratio = np.asarray(ratio, np.float64)
    x = np.log(np.clip(ratio, AREA_RATIOS[0], AREA_RATIOS[-1]))
    lx = np.log(AREA_RATIOS)
    j = np.clip(np.searchsorted(lx, x) - 1, 0, lx.size - 2)
    f = (x - lx[j]) / (lx[j + 1] - lx[j])
    row = np.asarray(row, np.int64)
    la = np.log(areas[row, j]) * (1.0 - f) + np.log(areas[row, j + 1]) * f
    small = np.where(ratio < AREA_RATIOS[0], (AREA_RATIOS[0] / np.maximum(ratio, 1e-300)) ** 2,
                     1.0)
    return np.exp(la) * small


def polygon_area_factor(blades: int) -> float:
    """Area of a regular ``blades``-gon over its circumradius squared (pi for a disc)."""
    if blades < 3:
        return math.pi
    return 0.5 * blades * math.sin(2.0 * math.pi / blades)


def aperture_normals(blades: int, rotation_deg: float) -> np.ndarray:
    """Unit edge normals (x right, y down) of a regular N-gon with vertex 0 at rotation."""
    if blades < 3:
        return np.zeros((1, 2))
    t = math.radians(rotation_deg) + math.pi * (2 * np.arange(blades) + 1) / blades
    return np.stack([np.cos(t), -np.sin(t)], axis=1)


# -- lights to entries ----------------------------------------------------------------------
@dataclass(frozen=True)
class Light:
    """A measured light: centroid (frame px), flux per channel (pixel sums), rms radius and
    ``gain``, a factor of its own on ``Optics.gain`` (how much of the gain it takes)."""

    x: float
    y: float
    flux: tuple[float, float, float]
    rms_px: float = 0.0
    gain: float = 1.0


@dataclass(frozen=True)
class Optics:
    """What the drawing needs besides the ghost table: frame geometry and the aperture."""

    centre_px: tuple[float, float]     # the optical centre (display window centre)
    px_per_mm: float                   # display width px / sensor width mm
    blades: int                        # aperture polygon (< 3: round)
    stop_index: int                    # the prescription's aperture stop
    gain: float = 1.0
    diagonal_px: float = math.inf      # the frame's diagonal (ghosts beyond VEIL_FROM fade)


def fade(incidence_rad) -> np.ndarray:
    """1 up to FADE_FROM_RAD, linearly to 0 at FADE_TO_RAD."""
    return np.clip((FADE_TO_RAD - np.asarray(incidence_rad)) / (FADE_TO_RAD - FADE_FROM_RAD),
                   0.0, 1.0)


def veil_fade(radius_over_diagonal) -> np.ndarray:
    """1 up to VEIL_FROM, linearly to 0 at VEIL_TO (ghost radius over the frame diagonal)."""
    return np.clip((VEIL_TO - np.asarray(radius_over_diagonal)) / (VEIL_TO - VEIL_FROM),
                   0.0, 1.0)


def ghost_power(table, optics: Optics) -> np.ndarray:
    """(G, W): ghost power per unit flux of the imaged light, faded by incidence."""
    power = table.energy / table.primary_transmission[None, :]
    if optics.blades >= 3:   # energy compares disc areas; a polygon stop passes less
        rim = table.limiter != optics.stop_index
        power = np.where(rim[:, None], power * math.pi / polygon_area_factor(optics.blades),
                         power)
    return optics.gain * power * fade(table.incidence_rad)


def cull(table, lights: list[Light], optics: Optics, level: float) -> np.ndarray:
    """Indices of the ghosts some light makes brighter than ``level`` (unclipped, unblurred
    peak: an upper bound of what is drawn)."""
    if not lights or len(table) == 0:
        return np.zeros(0, np.int64)
    area = polygon_area_factor(optics.blades if optics.blades >= 3 else 0) * \
        (table.radius_mm * optics.px_per_mm) ** 2
    per_flux = (ghost_power(table, optics) / np.maximum(area, 1e-12)).max(axis=1)   # (G,)
    brightest = max(max(lt.flux) * lt.gain for lt in lights)
    return np.nonzero(per_flux * brightest * PEAK >= level)[0]


def plan_entries(table, lights: list[Light], optics: Optics, weights: np.ndarray,
                 edge: np.ndarray, areas: np.ndarray, *, level: float = 0.0,
                 max_level: int = 4, level_scale: float = 2.0):
    """The kernel's entries for every (light, ghost) brighter than ``level``.

    Parameters
    ----------
    table : GhostTable
        Ghosts at the wavelengths ``weights`` rows describe (already culled if wanted).
    lights : list of Light
    optics : Optics
    weights : ndarray (W, 3)
        ``clfx.fx.spectral.channel_weights`` of the table's wavelengths.
    edge, areas : ndarray
        :func:`edge_table` and :func:`area_table`.
    level : float
        Visible level: entries whose peak radiance stays below it are dropped.
    max_level, level_scale : int, float
        An entry whose edge scale is at least ``level_scale * 2^k`` px is drawn at level
        ``k`` (resolution ``1 / 2^k``), up to ``max_level``; ``level_scale = inf``: all at
        full resolution.

    Returns
    -------
    entries : ndarray (n, ENTRY) float64
        ``x, y`` centre (frame px; the green channel's), ``ux, uy`` unit axis (optical
        centre to light), ``dR, dG, dB`` channel centre offsets along the axis (px),
        ``aR, aG, aB`` apothems (polygon) or radii (disc) px, ``1/sR, 1/sG, 1/sB`` inverse
        edge scales, ``ER, EG, EB`` radiance, shape (0 disc, +1 upright polygon, -1 inverted),
        edge-table row, inner clip (offset along the axis, radius; radius 0 = none), outer
        clip (offset, radius), circumradius factor (1 / cos(pi / N); 1 for a disc), 0.
    levels : ndarray (n,) int
    ghosts : ndarray (n,) int
        The table row of each entry (for tests and notes).
    """
    empty = (np.zeros((0, ENTRY)), np.zeros(0, np.int64), np.zeros(0, np.int64))
    if not lights or len(table) == 0:
        return empty
    lam = table.wavelengths_nm
    nw = lam.size
    mid = nw // 2
    cx, cy = optics.centre_px
    k = optics.px_per_mm
    vx = np.array([lt.x - cx for lt in lights])
    vy = np.array([lt.y - cy for lt in lights])
    dist = np.hypot(vx, vy)
    ux = np.where(dist > 1e-9, vx / np.maximum(dist, 1e-300), 1.0)
    uy = np.where(dist > 1e-9, vy / np.maximum(dist, 1e-300), 0.0)
    flux = np.array([np.asarray(lt.flux, np.float64) * lt.gain for lt in lights])   # (L, 3)
    rms = np.array([lt.rms_px for lt in lights], np.float64)          # (L,)
    # clip discs and hidden ghosts at the middle wavelength (the clipping varies little
    # across the spectrum; 1 / W of the work); centres at every wavelength
    layout = table.at_wavelength(mid).for_light(dist / k)             # (L, G, 1)
    centre_mm = table.centre[None] * (dist / k)[:, None, None]        # (L, G, W)
    power = ghost_power(table, optics)[None] * layout.area_fraction   # (L, G, W)
    power = np.where(layout.visible, power, 0.0)
    wl = weights.T[None, None]                                        # (1, 1, 3, W)
    pw = power[:, :, None, :] * wl                                    # (L, G, 3, W)
    pc = pw.sum(axis=-1)                                              # (L, G, 3)
    with np.errstate(invalid="ignore", divide="ignore"):
        om = np.where(pc[..., None] > 0, pw / pc[..., None], wl * np.ones_like(pw))
        om = om / om.sum(axis=-1, keepdims=True)

    def mean(v):                                                      # (L|1, G, W) -> (L, G, 3)
        return np.einsum("lgcw,lgw->lgc", om, np.broadcast_to(v, power.shape))

    radius = table.radius_mm[None] * k                                # (1, G, W) px
    centre = centre_mm * k                                            # (L, G, W) px along axis
    r_c = mean(radius)
    c_c = mean(centre)
    var = (mean(radius ** 2) - r_c ** 2) + 0.5 * (mean(centre ** 2) - c_c ** 2)
    sig_spec2 = np.maximum(var, 0.0)
    lam_mm = mean(lam[None, None, :] * 1e-6)
    bm = mean(table.edge_bm_mm[None])
    w_f = np.sqrt(lam_mm * bm / 2.0) * k                              # (L, G, 3) px
    cf = np.abs(table.centre[None, :, mid])                           # (1, G)
    sig_src2 = (cf * rms[:, None] / math.sqrt(2.0)) ** 2              # (L, G)
    inc = table.incidence_rad[None, :, mid]                           # (1, G)
    sig_ab = ABERRATION_BLUR * inc[..., None] ** 2 * r_c
    sigma = np.sqrt(sig_spec2 + sig_src2[..., None] + sig_ab ** 2 + PIXEL_SIGMA ** 2)
    scale = w_f + sigma
    q = sigma[..., 1] / scale[..., 1]
    row = np.rint(q * (edge.shape[0] - 1)).astype(np.int64)            # (L, G)

    polygon = (optics.blades >= 3) & (table.limiter == optics.stop_index)   # (G,)
    cosn = math.cos(math.pi / optics.blades) if optics.blades >= 3 else 1.0
    apo = r_c * np.where(polygon, cosn, 1.0)[None, :, None]
    shape_area = np.where(polygon, polygon_area_factor(optics.blades), math.pi)[None, :, None] \
        * r_c ** 2
    area = shape_area * soft_area(areas, row[..., None], apo / np.maximum(scale, 1e-12))
    af = np.broadcast_to(layout.area_fraction, power.shape[:2] + (3,))
    radiance = flux[:, None, :] * pc / np.maximum(area * af, 1e-300)
    radiance = np.where((af > 0) & np.isfinite(radiance), radiance, 0.0)
    radiance = radiance * veil_fade(r_c.max(axis=-1) / optics.diagonal_px)[..., None]
    peak = radiance.max(axis=-1) * PEAK
    keep = (peak >= level) & (peak > 0) & (r_c[..., 1] > 0)
    li, gi = np.nonzero(keep)
    if li.size == 0:
        return empty
    n = li.size
    e = np.zeros((n, ENTRY))
    cg = c_c[li, gi, 1]
    e[:, 0] = cx + cg * ux[li]
    e[:, 1] = cy + cg * uy[li]
    e[:, 2], e[:, 3] = ux[li], uy[li]
    e[:, 4:7] = c_c[li, gi] - cg[:, None]
    e[:, 7:10] = apo[li, gi]
    e[:, 10:13] = 1.0 / scale[li, gi]
    e[:, 13:16] = np.minimum(radiance[li, gi], np.finfo(np.float32).max)
    orient = table.orientation[gi, mid]
    e[:, 16] = np.where(polygon[gi], orient, 0.0)
    e[:, 17] = row[li, gi]
    base = layout.centre_mm[li, gi, 0]
    for col, cc, rr in ((18, layout.inner_centre_mm, layout.inner_radius_mm),
                        (20, layout.outer_centre_mm, layout.outer_radius_mm)):
        r = rr[li, gi, 0]
        cut = np.isfinite(r)
        e[:, col] = np.where(cut, (cc[li, gi, 0] - base) * k, 0.0)
        e[:, col + 1] = np.where(cut, r * k, 0.0)
    e[:, 22] = np.where(polygon[gi], 1.0 / cosn, 1.0)
    s_max = scale[li, gi].max(axis=1)
    with np.errstate(divide="ignore"):
        lvl = np.floor(np.log2(np.maximum(s_max / level_scale, 1e-300)))
    levels = np.clip(np.where(np.isfinite(lvl), lvl, 0), 0, max_level).astype(np.int64)
    return e, levels, gi


# -- tiles ----------------------------------------------------------------------------------
def entry_discs(e: np.ndarray):
    """Per entry: the bounding disc of what it draws (centre, radius) and the disc deep
    inside which it is constant (centre, radius; <= 0: none), in frame px, plus its clip
    discs as (centre x, centre y, radius, reach) for the inner and outer clips."""
    reach = EDGE_REACH / e[:, 10:13].min(axis=1)                    # largest edge scale
    off = np.abs(e[:, 4:7]).max(axis=1)
    outer = (e[:, 7:10] * e[:, 22:23]).max(axis=1) + off + reach
    inner = e[:, 7:10].min(axis=1) - off - reach
    clips = []
    for col in (18, 20):
        r = e[:, col + 1]
        clips.append((e[:, 0] + e[:, col] * e[:, 2], e[:, 1] + e[:, col] * e[:, 3], r, reach))
    return outer, inner, clips


def _chord(cx, cy, r, y_near, y_far):
    """Half-widths of a disc's chords at the band's nearest and farthest rows (NaN: none)."""
    with np.errstate(invalid="ignore"):
        near = np.sqrt(r * r - (y_near - cy) ** 2)
        far = np.sqrt(r * r - (y_far - cy) ** 2)
    return near, far


@dataclass
class TileLevel:
    """One resolution level: its tile lists (CSR) and per-tile constants."""

    factor: int
    width: int            # level pixels
    height: int
    tiles_x: int
    tiles_y: int
    start: np.ndarray     # (tiles + 1,) int32
    items: np.ndarray     # (n,) int32 entry indices
    constant: np.ndarray  # (tiles_y, tiles_x, 4) float32 RGB(0) deep-inside sums


def tile_plan(entries: np.ndarray, levels: np.ndarray, x0: float, y0: float, width: int,
              height: int, tile: int, max_level: int) -> list[TileLevel]:
    """Per level ``k`` (factor ``2^k``) over the window at (x0, y0) of width x height full
    pixels: which entries each tile must evaluate (they cross its edge) and the constant the
    others add (the tile lies deep inside them and their clip discs).

    Tile ``(i, j)`` of level ``k`` covers level pixels ``[tile i, tile (i+1))``, i.e. frame
    x from ``x0 + f tile i`` (``f = 2^k``).  Per entry and tile row the overlapping and the
    deep-inside tile spans come from chords of discs (the entry's bounding disc, its inner
    disc and its clip discs), so the work is entries x rows, not entries x tiles.
    """
    out = []
    for k in range(max_level + 1):
        f = 2 ** k
        w, h = -(-width // f), -(-height // f)
        tx, ty = max(1, -(-w // tile)), max(1, -(-h // tile))
        sel = np.nonzero(levels == k)[0]
        const = np.zeros((ty, tx + 1, 3))
        pairs_t, pairs_e = [], []
        if sel.size:
            e = entries[sel]
            outer, inner, clips = entry_discs(e)
            span = f * tile
            ya = y0 + np.arange(ty) * span                     # (ty,) band top (frame px)
            yb = ya + span
            cx, cy = e[:, 0:1], e[:, 1:2]                      # (n, 1)

            def x_range(ccx, ccy, r, grow):
                """Tiles a disc (radius r + grow) may touch per row: (lo, hi) inclusive."""
                rr = r + grow
                yn = np.clip(ccy, ya[None], yb[None])
                near, _ = _chord(ccx, ccy, rr, yn, yn)
                lo = np.floor((ccx - near - x0) / span)
                hi = np.floor((ccx + near - x0) / span)
                return np.where(np.isnan(near), np.inf, lo), np.where(np.isnan(near), -np.inf, hi)

            def x_inside(ccx, ccy, r):
                """Tiles entirely inside a disc of radius r per row: (lo, hi) inclusive."""
                yf = np.where(np.abs(ya[None] - ccy) > np.abs(yb[None] - ccy), ya[None], yb[None])
                _, far = _chord(ccx, ccy, r, yf, yf)
                lo = np.ceil((ccx - far - x0) / span)
                hi = np.floor((ccx + far - x0) / span) - 1
                bad = np.isnan(far) | (r <= 0)
                return np.where(bad, np.inf, lo), np.where(bad, -np.inf, hi)

            lo, hi = x_range(cx, cy, outer[:, None], 0.0)
            ilo, ihi = x_inside(cx, cy, inner[:, None])
            for ccx, ccy, r, reach in clips:
                cut = (r > 0)[:, None]
                clo, chi = x_range(ccx[:, None], ccy[:, None], r[:, None], reach[:, None])
                lo = np.where(cut, np.maximum(lo, clo), lo)
                hi = np.where(cut, np.minimum(hi, chi), hi)
                jlo, jhi = x_inside(ccx[:, None], ccy[:, None], (r - reach)[:, None])
                ilo = np.where(cut, np.maximum(ilo, jlo), ilo)
                ihi = np.where(cut, np.minimum(ihi, jhi), ihi)
            lo, hi = np.maximum(lo, 0), np.minimum(hi, tx - 1)
            ilo, ihi = np.maximum(ilo, lo), np.minimum(ihi, hi)
            has_in = ilo <= ihi
            # constants: difference array per row
            ent, row = np.nonzero(has_in)
            rad = e[ent, 13:16]
            np.add.at(const, (row, ilo[ent, row].astype(np.int64)), rad)
            np.add.at(const, (row, ihi[ent, row].astype(np.int64) + 1), -rad)
            # edge spans: [lo, ilo - 1] and [ihi + 1, hi] (all of [lo, hi] without interior)
            a_lo, a_hi = lo, np.where(has_in, ilo - 1, hi)
            b_lo, b_hi = np.where(has_in, ihi + 1, np.inf), np.where(has_in, hi, -np.inf)
            for s_lo, s_hi in ((a_lo, a_hi), (b_lo, b_hi)):
                ent, row = np.nonzero(s_lo <= s_hi)
                if ent.size == 0:
                    continue
                first = s_lo[ent, row].astype(np.int64)
                count = (s_hi[ent, row] - s_lo[ent, row]).astype(np.int64) + 1
                idx = np.repeat(np.arange(ent.size), count)
                offs = np.arange(idx.size) - np.repeat(np.cumsum(count) - count, count)
                pairs_t.append(row[idx] * tx + first[idx] + offs)
                pairs_e.append(sel[ent[idx]])
        const = np.cumsum(const, axis=1)[:, :tx]
        c4 = np.zeros((ty, tx, 4), np.float32)
        c4[..., :3] = np.minimum(np.maximum(const, 0.0), np.finfo(np.float32).max)
        if pairs_t:
            t_all = np.concatenate(pairs_t)
            e_all = np.concatenate(pairs_e)
            order = np.lexsort((e_all, t_all))      # by tile, then entry: a fixed sum order
            t_all, e_all = t_all[order], e_all[order]
            start = np.searchsorted(t_all, np.arange(tx * ty + 1)).astype(np.int32)
            items = e_all.astype(np.int32)
        else:
            start = np.zeros(tx * ty + 1, np.int32)
            items = np.zeros(1, np.int32)
        out.append(TileLevel(f, w, h, tx, ty, start, items if items.size else
                             np.zeros(1, np.int32), c4))
    return out
