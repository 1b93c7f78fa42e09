"""Glare: light scattered in the lens and the eye, spread by a large point spread function.

Model
-----
Per pixel (scene-linear RGB, luminance ``L`` Rec.709) the light that scatters is the soft-knee
highlight ``h = max(rgb, 0) * clamp(max(s, L - t) / L, 0, 1)``, ``s = clamp(L - t + k, 0,
2k)^2 / 4k`` (threshold ``t``, knee ``k``).  It is convolved with a normalised PSF
(``clfx.fx.psf``): Spencer et al. 1995's eye PSF (power-law falloff), a sum of Gaussians (bloom)
or a user kernel image, truncated at ``size`` x the frame diagonal.  Scene-linear frames keep
their energy: ``out = c - strength h + strength tint (PSF * h)``; with a white tint the total
light is unchanged away from the borders.

Display-referred (8-bit) input has no highlights above 1: luminance is first expanded by an
inverse tone curve ``e(L) = L / max(1 - L (1 - 1/B), 1/B)`` (``B`` = ``display_boost``: 1.0 maps
to B, hue kept), thresholded, spread and added (``out = c + strength tint (PSF * h)``).

Light spreads past the frame: the region of definition grows by the PSF radius, and light in
EXR overscan (data window larger than display window) contributes.  Only the bounding box of
the analysis tiles with highlights is transformed (``ctx.analysis.tiles_above``), and a frame
without any is an identity ("no pixel above threshold").  Non-finite input pixels are set
to 0 before the convolution and counted in ``ctx.notes``.

Quality levels: see ``clfx.fx.fftconv.spread`` (draft one pyramid level, preview float32 FFT
with bright pixels gathered exactly, final float64 FFT, reference float64 direct/FFT).

References
----------
Spencer, Shirley, Zimmerman, Greenberg 1995, "Physically-based glare effects for digital
images", SIGGRAPH.  Kawase 2003, "Frame buffer postprocessing effects in DOUBLE-S.T.E.A.L".
"""
from __future__ import annotations

import math
from collections import OrderedDict

import numpy as np

from clfx.fx import fftconv
from clfx.fx import psf as psflib
from clfx.core.camera import Camera
from clfx.core.plugin import ChoiceParam, Descriptor, FloatParam, RGBParam, StringParam
from clfx.host import Plugin, register
from clfx.core.rect import Rect

SPLIT_RATIO = 1e-3
"""preview: pixels above this fraction of the peak (and above 4 x threshold) are gathered
exactly instead of going through the float32 FFT."""

QUALITY = {
    "draft": "one pyramid level: 2x2-summed highlights, tent-resampled PSF, float32 FFT at half "
             "resolution, bilinear upsampling (light moves <= 0.5 px, core blurred ~1 px; "
             "PSFs <= 21x21 taps: direct float32)",
    "preview": "float32 r2c FFT with the HDR split: pixels above max(4 x threshold, 1e-3 x peak) "
               "(at most 64) are gathered exactly, the rest transformed; more than 64 falls "
               "back to float64 (PSFs <= 21x21 taps: direct float32)",
    "final": "float64 r2c FFT (1.0-1.3x the cost of float32 on PoCL, no float32 error floor; "
             "PSFs <= 21x21 taps: direct float32)",
    "reference": "float64: direct gather with float64 accumulation when output px x taps <= 4e7, "
                 "else float64 r2c FFT",
}


class ScatterPlugin(Plugin):
    """Shared machinery of glare, bleed and soft_focus: threshold -> PSF spread -> mix.

    Subclasses set ``descriptor`` and implement :meth:`build_psf`; their kernel file defines
    ``<name>_highlights`` and ``<name>_mix`` (glare.cl's helpers).
    """

    def __init__(self):
        self._psf_cache: OrderedDict = OrderedDict()

    # -- parameters -> physics ------------------------------------------------------------
    def strength(self, p) -> float:
        return p.strength

    def boost(self, p, ctx) -> float:
        """Inverse tone curve gain for display-referred input (0: scene-linear)."""
        return 0.0

    def radius_px(self, p, ctx) -> int:
        return psflib.psf_radius_px(p.size, ctx.diagonal_px)

    def build_psf(self, p, ctx, radius: int) -> np.ndarray:
        raise NotImplementedError

    def psf(self, p, ctx) -> np.ndarray:
        """The PSF for this parameter set and frame size, cached on the instance."""
        r = self.radius_px(p, ctx)
        key = (p.hash_hex(), r, ctx.width_px, ctx.camera)
        k = self._psf_cache.get(key)
        if k is None:
            k = self.build_psf(p, ctx, r)
            self._psf_cache[key] = k
            while len(self._psf_cache) > 4:
                self._psf_cache.popitem(last=False)
        return k

    def raw_level(self, p, ctx) -> float:
        """Source luminance above which a pixel contributes (threshold - knee, in input units)."""
        level = max(p.threshold - p.knee, 0.0)
        b = self.boost(p, ctx)
        if b > 0.0:  # invert e(L) = L / (1 - L (1 - 1/B)) on [0, 1)
            level = level / (1.0 + level * (1.0 - 1.0 / b))
        return level

    # -- cheap questions ------------------------------------------------------------------
    def is_identity(self, p, ctx):
        if self.strength(p) == 0.0:
            return f"{self.descriptor.params[0].name} is 0"
        if self.radius_px(p, ctx) < 1:
            return "size is below one pixel"
        if not ctx.analysis.any_above(self.raw_level(p, ctx)):
            return "no pixel above threshold"
        return None

    def region_of_definition(self, p, ctx):
        return ctx.source.window.grown(self.radius_px(p, ctx))

    def region_of_interest(self, p, ctx, window):
        return window.grown(self.radius_px(p, ctx))

    def highlight_support(self, p, ctx) -> Rect:
        """Bounding box of the analysis tiles that hold a contributing pixel."""
        return ctx.analysis.highlight_bounds(self.raw_level(p, ctx))

    # -- render ---------------------------------------------------------------------------
    def render(self, rt, p, ctx):
        name = self.descriptor.name
        kfile = self.descriptor.kernel
        src = ctx.source
        k = self.psf(p, ctx)
        boost = self.boost(p, ctx)
        extra = (np.float32(boost),) if name == "glare" else ()
        nonfinite = ctx.analysis.nonfinite_count
        if nonfinite:
            ctx.notes.append(f"{name}: {nonfinite} non-finite pixel(s) set to 0 before the "
                             f"{k.shape[1]}x{k.shape[0]} PSF")
        h = rt.image(src.window, 4)
        f32, i32 = np.float32, np.int32
        rt.launch(rt.kernel(kfile, f"{name}_highlights"), (src.pitch // 4, max(src.height, 1)),
                  src, h, i32(src.pitch), i32(src.height), f32(p.threshold), f32(p.knee), *extra)
        out_window = self.output_window(p, ctx)
        split = max(4.0 * p.threshold, SPLIT_RATIO * ctx.analysis.peak_luminance)
        info = fftconv.ConvolveInfo()
        g = fftconv.spread(rt, h, k, ctx.quality, out_window=out_window,
                           support=self.highlight_support(p, ctx), split_level=split, info=info)
        for note in info.notes:
            ctx.notes.append(f"{name}: {note}")
        dst = rt.image(out_window, 4)
        from pyopencl import cltypes

        tint = cltypes.make_float4(*getattr(p, "tint", (1.0, 1.0, 1.0)), 0.0)
        dx, dy = out_window.offset_in(src.window)
        args = [src, i32(src.pitch), i32(src.width), i32(src.height), g, dst, i32(dst.pitch),
                i32(dst.height), i32(dx), i32(dy), f32(self.strength(p)), tint,
                f32(p.threshold), f32(p.knee)]
        if name == "glare":
            args += [f32(boost), i32(boost > 0.0)]
        rt.launch(rt.kernel(kfile, f"{name}_mix"), (dst.pitch // 4, max(dst.height, 1)), *args)
        return dst


def spencer_or_other_psf(p, ctx, radius: int) -> np.ndarray:
    """Glare's PSF choice (``p.psf``) at ``radius`` pixels."""
    if p.psf == "spencer":
        dpp = psflib.degrees_per_pixel(ctx.camera, ctx.width_px, p.fov)
        return psflib.spencer(radius, dpp)
    if p.psf == "gaussians":
        sig, w = psflib.bloom_sigmas(radius)
        return psflib.gaussians(radius, sig, w)
    if not p.kernel_path:
        from clfx.core.errors import ParamError

        raise ParamError("glare.kernel_path: psf 'image' needs a kernel image path")
    return psflib.from_image(p.kernel_path, radius)


@register
class Glare(ScatterPlugin):
    descriptor = Descriptor(
        name="glare", label="Glare", group="Lens", kernel="glare.cl",
        summary="Highlights scattered by a large point spread function (Spencer eye PSF, "
                "Gaussian bloom or a kernel image), HDR-safe FFT convolution.",
        spreads_light=True,
        params=(
            FloatParam("strength", 0.05, min=0.0, max=1.0,
                       hint="Fraction of the highlight light that scatters (0 = off)."),
            FloatParam("threshold", 1.0, min=0.0, max=1e6,
                       hint="Scene-linear luminance where light starts to scatter."),
            FloatParam("knee", 0.5, min=0.0, max=1e6,
                       hint="Width of the soft knee below the threshold, in luminance."),
            FloatParam("size", 0.15, min=0.0, max=2.0,
                       hint="PSF radius as a fraction of the frame diagonal."),
            ChoiceParam("psf", "spencer", choices=("spencer", "gaussians", "image"),
                        hint="Spencer et al. 1995 eye PSF, a sum of Gaussians, or a kernel image."),
            StringParam("kernel_path", "",
                        hint="Kernel image for psf 'image' (centred; larger side spans 2 x size)."),
            FloatParam("fov", 0.0, min=0.0, max=179.0,
                       hint="Horizontal field of view in degrees for the Spencer PSF; 0 = from the camera."),
            RGBParam("tint", (1.0, 1.0, 1.0), max=100.0,
                     hint="Colour of the scattered light (white keeps energy)."),
            FloatParam("display_boost", 8.0, min=1.0, max=1000.0,
                       hint="Display-referred input only: value a white pixel is expanded to before spreading."),
        ),
        quality=QUALITY,
    )

    def boost(self, p, ctx):
        return p.display_boost if ctx.display_referred else 0.0

    def build_psf(self, p, ctx, radius):
        return spencer_or_other_psf(p, ctx, radius)


def bench_case(width, height, rng):
    """A 1e5 sun, a few moderate lights and 1e-2 shadows; PSF 1025 px wide at 1080p."""
    src = np.empty((height, width, 4), np.float32)
    src[..., :3] = rng.uniform(0.005, 0.02, (height, width, 3))
    src[..., 3] = 1.0
    diag = math.hypot(width, height)
    yy, xx = np.mgrid[0:height, 0:width]
    sun = (xx - 0.62 * width) ** 2 + (yy - 0.38 * height) ** 2 <= (0.004 * diag) ** 2
    src[sun, :3] = 1e5
    for fx, fy, v in ((0.2, 0.7, 20.0), (0.8, 0.8, 5.0), (0.35, 0.25, 50.0)):
        lamp = (xx - fx * width) ** 2 + (yy - fy * height) ** 2 <= (0.006 * diag) ** 2
        src[lamp, :3] = v
    return dict(source=src, depth=None, velocity=None,
                params={"strength": 0.05, "threshold": 1.0, "size": 512.0 / math.hypot(1920, 1080)},
                camera=Camera())


def _soft_knee_highlight(rgb: np.ndarray, threshold: float, knee: float) -> np.ndarray:
    """Host copy of the soft-knee highlight (module docstring), for the benchmark's peers."""
    lum = rgb @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    x = np.clip(lum - threshold + knee, 0.0, 2.0 * knee)
    soft = x * x / (4.0 * knee) if knee > 0 else np.zeros_like(lum)
    safe = np.where(lum > 0, lum, 1.0)
    w = np.where(lum > 0, np.clip(np.maximum(soft, lum - threshold) / safe, 0.0, 1.0), 0.0)
    return (rgb * w[..., None]).astype(np.float32)


def bench_peers(case, params, ctx):
    """The same glare (same highlights, PSF and mix) with SciPy's float32 FFT convolution and
    with OpenCV's filter2D (DFT-based for large kernels, float64 inside)."""
    plugin = Glare()
    kernel = plugin.psf(params, ctx).astype(np.float32)
    src = np.nan_to_num(np.asarray(case["source"], np.float32), nan=0.0, posinf=0.0, neginf=0.0)
    rgb = np.maximum(src[..., :3], 0.0)
    hl = _soft_knee_highlight(rgb, params.threshold, params.knee)
    tint = np.asarray(params.tint, np.float32)

    def mix(spread):
        out = src.copy()
        out[..., :3] = src[..., :3] - params.strength * hl + params.strength * tint * spread
        return out

    peers = {}
    try:
        from scipy.signal import fftconvolve

        peers["scipy.signal.fftconvolve float32"] = lambda: mix(np.stack(
            [fftconvolve(hl[..., c], kernel, mode="same") for c in range(3)], axis=-1))
    except ImportError:
        pass
    try:
        import cv2

        cv2.setNumThreads(2)
        peers["cv2.filter2D"] = lambda: mix(cv2.filter2D(
            hl, -1, kernel, borderType=cv2.BORDER_CONSTANT))  # PSF symmetric: correlation = convolution
    except ImportError:
        pass
    return peers
