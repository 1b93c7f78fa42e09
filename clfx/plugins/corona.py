"""Corona: spectral diffraction rings around strong lights, from the aperture's shape.

Model (Ritschel et al. 2009, "Temporal glare: real-time dynamic simulation of the scattering
in the human eye", Eurographics)
-----------------------------------------------------------------------------------------
The Fraunhofer far field of an aperture ``A`` is its Fourier transform, so a point light
images to ``I(u) = |FFT(A)|^2``.  The pattern scales with wavelength: at wavelength lambda a
feature at radius r_550 moves to ``r_550 * lambda / 550 nm`` (the dark rings of a round
aperture sit at 1.22, 2.23, 3.24 ... lambda / D), so white light gives rings that run
through the rainbow, blue inside, red outside.  The RGB PSF is

    PSF_c(x) = sum_lambda  w_c(lambda) * I(x / s_lambda) / s_lambda^2,   s_lambda ∝ lambda,

with ``w(lambda) = M * cmf(lambda) * d_lambda`` (CIE 1931 colour matching functions,
``clfx.fx.spectral``; samples at bin centres from 380 to 780 nm), i.e. an equal-energy spectrum,
``M`` the XYZ -> RGB of the reference basis, linear Rec.709 (pixels of another working space
are carried into it and back, ``clfx.kit.spectral.in_reference_basis``).
Spectral colours are outside the gamut, so each PSF pixel is brought into gamut keeping its
luminance (``clfx.fx.spectral.to_gamut``); then each channel is normalised to sum 1, so a
spectrally flat (white) light keeps its colour and energy (white balance) and only the
rings are coloured.  ``I`` is computed once per parameter set on the host (NumPy FFT of an
anti-aliased N-gon or disk, sampled so the 380 nm pattern has about one FFT bin per pixel;
bilinear resampling per wavelength, with pixel supersampling when the pattern is smaller than
a pixel) and cached.

Output = sanitised source - ``intensity`` * highlights + ``intensity`` * (highlights ⊛ PSF),
highlights being ``rgb * max(lum - threshold, 0) / lum``: the part of the light that the
droplets or the aperture diffract leaves its pixel and lands in the pattern (Babinet: the
undiffracted rest goes straight on), so the corona moves light and never adds any (the
frame's total is kept).  The highlights take each pixel's non-negative part (per channel,
``scatter_bright``): a negative component (a colour outside Rec.709, e.g. an ACEScg green
carried into the reference basis) is not diffracted and stays in place, so nothing is
clipped from the frame; this happens in the reference basis, hence the same for the same
light in any working space.  ``size`` is the radius of the first dark ring at 550 nm for a round
aperture (fraction of the frame diagonal; the same scale for polygons; the default 0.012,
26 px at 1080p, gives a small bright core and rings out to ~130 px around a street light: the
former 0.03 made a flat white core ~60 px wide and rings to ~240 px from a 7 px light,
issue 25; an atmospheric corona's few degrees needs ~0.03, as sunny-flare sets), ``extent`` how many of those radii the PSF keeps (a raised-cosine taper over its
outer quarter, then renormalised; the default 5 keeps three to four rings).  ``intensity``
defaults to 0.05: at 0.2 a fifth of a candle flame's light went into the Airy core and its
shoulders and an exposure for the room showed a flat white disc twice the flame's width
instead of a bright flame with a glow and faint coloured rings (issue 25).

The pattern is smooth at the scale of its rings, so below ``reference`` it is computed at a
reduced resolution ``1 / f`` (f a power of two, at most 16) that still gives the first dark
ring ``ring_px`` reduced pixels (final: 8): the highlights are splatted onto the coarse grid
with tent weights (each pixel's light keeps its centroid), the PSF is sampled at ``r0 / f``,
and the glow is upsampled bilinearly (energy per pixel divided by f^2): the pattern is blurred
by about f pixels, never moved.  The convolution is ``clfx.fx.fftconv.spread`` over the
bounding box of the tiles with highlights only (scene analysis), so one light costs a small
FFT; identity and regions are the glare family's (``clfx.kit.scatter.SpreadRegions``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clfx.core.camera import BLADES_WHY, NO_POLYGON
from clfx.core.plugin import Descriptor, FloatParam, IntParam
from clfx.fx import fftconv, spectral
from clfx.fx import psf as psflib
from clfx.core.rect import Rect
from clfx.host import Plugin, register
from clfx.kit.scatter import SpreadRegions
from clfx.kit.spectral import in_reference_basis


@dataclass(frozen=True)
class CoronaLevel(fftconv.SpreadLevel):
    """A corona quality level: ``wavelengths`` spectral samples from 380 to 780 nm (80 = 5 nm
    bins); the pattern is computed at ``1 / f`` resolution (f a power of two) while its first
    dark ring spans at least ``ring_px`` reduced pixels (``inf``: full resolution), and the
    convolution settings of ``clfx.fx.fftconv.spread``."""

    wavelengths: int = 40
    ring_px: float = 8.0


LEVELS = {
    # draft: the pattern's own reduction is the cheap step, so the convolution runs on its
    # grid (a plain float32 FFT, no exact bright pixels).  spread's draft halved it again
    # ("half"): with 4 px a ring that left 2, and the splat and upsampling tents (~f px)
    # blurred the rings into a plain white glow; at 4 px a ring without the halving the
    # first ring still drowned in them, at 6 it stands as at final
    "draft": fftconv.spread_level(
        CoronaLevel, "draft", "16 wavelengths; pattern at reduced resolution (>= 6 px per "
        "first-ring radius); plain float32 FFT on that grid", wavelengths=16, ring_px=6.0,
        method="fft"),
    "preview": fftconv.spread_level(
        CoronaLevel, "preview", "24 wavelengths; pattern at reduced resolution (>= 6 px per "
        "first-ring radius); float32 FFT with the brightest pixels gathered exactly",
        wavelengths=24, ring_px=6.0),
    "final": fftconv.spread_level(
        CoronaLevel, "final", "40 wavelengths (10 nm); pattern at reduced resolution (>= 8 px "
        "per first-ring radius, bilinear upsampling); float64 FFT", wavelengths=40),
    "reference": fftconv.spread_level(
        CoronaLevel, "reference", "80 wavelengths (5 nm); full resolution; float64 direct "
        "gather when small, else float64 FFT", wavelengths=80, ring_px=math.inf),
}

AIRY_FIRST_ZERO = 1.2196698912665045
"""First zero of the Airy pattern, in units of lambda / D (= 3.8317 / pi)."""

REFERENCE_NM = 550.0
"""Wavelength at which ``size`` is the first dark ring's radius."""

MAX_GRID = 2048
"""Largest FFT grid for the far field (host NumPy); the sampling adapts to stay below it."""

MAX_RADIUS_DIAGONALS = 1.5
"""The PSF radius is capped at this many frame diagonals (farther light leaves the frame)."""


# -- the aperture and its far field -----------------------------------------------------
def aperture(m: int, diameter: float, blades: int, rotation_deg: float,
             supersample: int = 4) -> np.ndarray:
    """An anti-aliased aperture on an m x m grid: a disk (blades < 3) or a regular N-gon
    inscribed in a circle of ``diameter`` samples, vertex 0 at ``rotation_deg`` (CCW)."""
    r = diameter / 2.0
    n = int(math.ceil(r)) + 1
    sub = (np.arange(supersample) + 0.5) / supersample - 0.5
    coords = (np.arange(-n, n + 1)[:, None] + sub[None, :]).ravel()
    y, x = np.meshgrid(-coords, coords, indexing="ij")     # y up, as angles are CCW
    if blades < 3:
        inside = x * x + y * y <= r * r
    else:
        inside = np.ones_like(x, bool)
        apothem = r * math.cos(math.pi / blades)
        for i in range(blades):
            t = math.radians(rotation_deg) + math.pi * (2 * i + 1) / blades
            inside &= x * math.cos(t) + y * math.sin(t) <= apothem
    k = 2 * n + 1
    cov = inside.reshape(k, supersample, k, supersample).mean(axis=(1, 3))
    out = np.zeros((m, m))
    c = m // 2
    out[c - n:c + n + 1, c - n:c + n + 1] = cov
    return out


def far_field(ap: np.ndarray) -> np.ndarray:
    """|FFT(aperture)|^2, centred at (m // 2, m // 2), normalised to sum 1."""
    f = np.fft.fftshift(np.abs(np.fft.fft2(np.fft.ifftshift(ap))) ** 2)
    return f / f.sum()


def _bilinear(img: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """img sampled at column u, row v (zero outside)."""
    h, w = img.shape
    u0, v0 = np.floor(u).astype(int), np.floor(v).astype(int)
    fu, fv = u - u0, v - v0
    out = np.zeros(u.shape)
    for dx, dy, wt in ((0, 0, (1 - fu) * (1 - fv)), (1, 0, fu * (1 - fv)),
                       (0, 1, (1 - fu) * fv), (1, 1, fu * fv)):
        xi, yi = u0 + dx, v0 + dy
        ok = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
        out[ok] += wt[ok] * img[yi[ok], xi[ok]]
    return out


class PSFGeometry:
    """Sampling of the far field for a first-ring radius ``r0_px`` and PSF radius ``radius``.

    ``bins_per_ring`` FFT bins span r0 at 550 nm; at 380 nm that is about one bin per pixel
    (at least 4 bins, at most 24); the grid is a power of two large enough that the pattern
    out to ``radius`` pixels at 380 nm does not wrap around.
    """

    def __init__(self, r0_px: float, radius: int):
        self.r0_px = r0_px
        self.radius = radius
        short = spectral.VISIBLE_NM[0] / REFERENCE_NM
        # at most so many bins per ring that the pattern out to `radius` fits MAX_GRID
        most = (MAX_GRID / 2 - 8) / 1.5 * short * r0_px / max(radius, 1)
        self.bins_per_ring = float(np.clip(r0_px * short, 4, max(4.0, min(24.0, most))))
        # the pattern out to `radius` px at 780 nm (largest) must not wrap around; the
        # aperture (0.3 m wide at 4 bins per ring) keeps its autocorrelation inside the grid
        px_per_bin_min = self.px_per_bin(spectral.VISIBLE_NM[0])
        need = 2 * (1.5 * radius / px_per_bin_min + 8)
        m = 64
        while m < need:
            m *= 2
        self.m = m
        self.diameter = AIRY_FIRST_ZERO * m / self.bins_per_ring

    def px_per_bin(self, wavelength_nm: float) -> float:
        return self.r0_px / self.bins_per_ring * wavelength_nm / REFERENCE_NM


def monochromatic_psf(field: np.ndarray, geom: PSFGeometry, wavelength_nm: float) -> np.ndarray:
    """The far field at one wavelength on the pixel grid (2R+1 square), energy per pixel.

    Supersampled (up to 8 x 8) when a pixel covers more than one FFT bin, so thin rings do
    not alias; a pattern smaller than a pixel is a near-delta either way.
    """
    s = geom.px_per_bin(wavelength_nm)
    ss = min(8, max(1, math.ceil(1.0 / s - 1e-9)))
    r = geom.radius
    sub = (np.arange(ss) + 0.5) / ss - 0.5
    offs = np.arange(-r, r + 1, dtype=np.float64)
    c = geom.m // 2
    acc = np.zeros((2 * r + 1, 2 * r + 1))
    for sy in sub:
        for sx in sub:
            v, u = np.meshgrid((offs + sy) / s + c, (offs + sx) / s + c, indexing="ij")
            acc += _bilinear(field, u, v)
    return acc / (ss * ss) / (s * s)


def psf_radius(r0_px: float, extent: float, max_radius: int | None = None) -> int:
    """PSF radius in pixels: ``extent`` first-ring radii at the red end (780 nm), capped."""
    r = max(1, int(math.ceil(extent * r0_px * spectral.VISIBLE_NM[1] / REFERENCE_NM)))
    return r if max_radius is None else max(1, min(r, int(max_radius)))


def spectral_psf(r0_px: float, extent: float, blades: int, rotation_deg: float,
                 n_wavelengths: int, max_radius: int | None = None,
                 rgb_to_xyz=None) -> np.ndarray:
    """The white-balanced RGB corona PSF, shape (2R+1, 2R+1, 3), each channel summing to 1.

    Parameters
    ----------
    r0_px : float
        First dark ring radius at 550 nm (round aperture), pixels.
    extent : float
        PSF radius in units of r0 at 550 nm (the red end reaches further; R = extent r0 780/550).
    blades, rotation_deg : int, float
        Aperture polygon (blades < 3: disk) and its rotation, degrees CCW.
    n_wavelengths : int
        Spectral samples from 380 to 780 nm (bin centres).
    max_radius : int, optional
        Cap on the PSF radius in pixels (light beyond the frame is not kept anyway).
    rgb_to_xyz : ndarray (3, 3), optional
        The working space's RGB -> XYZ matrix (None: linear Rec.709).
    """
    radius = psf_radius(r0_px, extent, max_radius)
    geom = PSFGeometry(r0_px, radius)
    field = far_field(aperture(geom.m, geom.diameter, blades, rotation_deg))
    lams = spectral.wavelengths(n_wavelengths)
    weights = spectral.spectral_rgb_weights(lams, rgb_to_xyz)
    rgb = np.zeros((2 * radius + 1, 2 * radius + 1, 3))
    for lam, w in zip(lams, weights):
        rgb += monochromatic_psf(field, geom, lam)[..., None] * w
    rgb = spectral.to_gamut(rgb, rgb_to_xyz) * psflib.radial_taper(radius)[..., None]
    return rgb / rgb.sum(axis=(0, 1))


@register
class Corona(SpreadRegions, Plugin):
    descriptor = Descriptor(
        name="corona", label="Corona (spectral diffraction)", group="Glare",
        kernel="corona.cl",
        summary="Rainbow diffraction rings around strong lights: |FFT(aperture)|^2 per "
                "wavelength, summed with the CIE 1931 colour matching functions.",
        spreads_light=True,
        params=(
            FloatParam("threshold", 2.0, min=0.0, max=1e6,
                       hint="Scene-linear luminance above which pixels diffract."),
            FloatParam("intensity", 0.05, min=0.0, max=1.0,
                       hint="Fraction of the highlights' light that diffracts into the pattern "
                            "(its core included); the rest stays put: light is moved, never "
                            "added."),
            FloatParam("size", 0.012, min=0.0002, max=0.2,
                       hint="Radius of the first dark ring at 550 nm, as a fraction of the "
                            "frame diagonal."),
            FloatParam("extent", 5.0, min=1.5, max=40.0,
                       hint="PSF radius in first-ring radii (more = more, fainter rings)."),
            IntParam("blades", 0, min=0, max=32, exclude=NO_POLYGON, exclude_why=BLADES_WHY,
                     hint="Aperture blades; 0 = the camera block's (a camera value of 0 means "
                          "a round aperture).  Rotation: the camera block's."),
        ),
        quality=LEVELS,
    )
    strength_param = "intensity"

    # PSF ------------------------------------------------------------------------------
    def factor(self, p, ctx) -> int:
        """The reduction of the pattern's resolution: the largest power of two leaving the
        first dark ring ``ring_px`` reduced pixels (at most 16)."""
        ring = ctx.size_px(p.size) / self.level(ctx).ring_px
        f = 1
        while f < 16 and 2 * f <= ring:
            f *= 2
        return f

    def psf(self, p, ctx, factor: int = 1) -> np.ndarray:
        """The RGB PSF for these parameters, frame size, camera and quality, sampled at
        ``1 / factor`` resolution (kept in the runtime's cache)."""
        blades = p.blades or ctx.camera.blades
        rotation = ctx.camera.blade_rotation
        n = self.level(ctx).wavelengths
        cap = -(-self.max_radius(ctx) // factor)
        r0 = ctx.size_px(p.size) / factor
        key = ("corona.psf", round(r0, 6), p.extent, blades, rotation, n, cap) + ctx.colour_key
        return ctx.runtime.cache.get(
            key, lambda: spectral_psf(r0, p.extent, blades, rotation, n, cap, ctx.rgb_to_xyz))

    @staticmethod
    def max_radius(ctx) -> int:
        diag = max(ctx.diagonal_px, ctx.source.window.diagonal)
        return int(math.ceil(MAX_RADIUS_DIAGONALS * diag)) + 1

    def radius_px(self, p, ctx) -> int:
        return psf_radius(ctx.size_px(p.size), p.extent, self.max_radius(ctx))

    # render ---------------------------------------------------------------------------
    def render(self, rt, p, ctx):
        # the spectral model is defined in linear Rec.709; other working spaces are carried
        # into it and back (clfx.kit.spectral.in_reference_basis)
        return in_reference_basis(rt, ctx, lambda c: self.render_reference(rt, p, c))

    def render_reference(self, rt, p, ctx):
        """The effect on pixels in the reference basis (linear Rec.709)."""
        src = ctx.source
        out_win = self.output_window(p, ctx)
        ox, oy = src.window.offset_in(out_win)
        f = self.factor(p, ctx)
        support = self.highlight_support(p, ctx)
        luma = ctx.luminance_defines     # Rec.709's: the luminance of the same light
        if f == 1:
            bright = src.like()
            rt.launch(rt.kernel("corona.cl", "corona_bright", **luma),
                      (src.pitch // 4, src.height), src, bright, src.pitch, src.height,
                      p.threshold)
            glow_win = out_win
        else:
            # the pattern at 1 / f resolution: reduced pixel (i, j) is centred on output pixel
            # coordinates (f (i - 1/2), f (j - 1/2)), one pixel of border on each side; the
            # highlights are splatted onto it with tent weights (their centroids kept)
            glow_win = Rect(0, 0, -(-out_win.width // f) + 2, -(-out_win.height // f) + 2)
            bright = rt.image(glow_win)
            rt.launch(rt.kernel("corona.cl", "corona_down", FACTOR=f, **luma),
                      (bright.pitch, bright.height), src, src.pitch, src.width, src.height, ox, oy,
                      bright, bright.pitch, bright.width, bright.height, p.threshold)
            if not support.empty:
                sx, sy = support.x0 - out_win.x0, support.y0 - out_win.y0
                support = Rect(sx // f, sy // f, -(-(sx + support.width) // f) + 2,
                               -(-(sy + support.height) // f) + 2)
        info = fftconv.ConvolveInfo()
        glow = fftconv.spread(rt, bright, self.psf(p, ctx, f), self.level(ctx),
                              out_window=glow_win, support=support,
                              split_level=max(p.threshold, 1.0) * 64.0 * f * f, info=info)
        out = rt.image(out_win)
        rt.launch(rt.kernel("corona.cl", "corona_compose", FACTOR=f, **luma),
                  (out.pitch, out.height), src, src.pitch, src.width, src.height, ox, oy, glow,
                  glow.pitch, glow.width, glow.height, out, out.pitch, out.width, out.height,
                  p.intensity, p.threshold)
        if f > 1:
            ctx.notes.append(f"corona: pattern at 1/{f} resolution")
        bad = ctx.analysis.nonfinite_count
        if bad:
            ctx.notes.append(f"corona: {bad} non-finite pixels set to 0")
        ctx.notes.extend(f"corona: {n}" for n in info.notes)
        return out
