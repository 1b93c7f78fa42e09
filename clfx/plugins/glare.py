"""Glare: light scattered in the lens and the eye, spread by a large point spread function.

Model
-----
Per pixel (scene-linear RGB, luminance ``L`` Rec.709) the light that scatters is the
soft-knee highlight ``h = max(rgb, 0) * clamp(max(s, L - t) / L, 0, 1)``, ``s = clamp(L - t
+ k, 0, 2k)^2 / 4k`` (threshold ``t``, knee ``k``). It is convolved with a normalised PSF
(``clfx.fx.psf``): Spencer et al. 1995's eye PSF (power-law falloff), a sum of Gaussians
(bloom) or a user kernel image (``kernel_path``, read by the pipeline: ``ctx.read_image``),
with a support of radius ``size`` x the frame diagonal. The Spencer and Gaussian PSFs keep
their own tails down to 1e-5 of the PSF one pixel from the light and end smoothly inside the
support (``clfx.fx.psf.tail_fade``: a Gaussian roll-off where the tail would still be above
that at 0.9 x the radius, and a raised cosine from half the radius to 0 at it), so a point
light graded up shows no rim, step or square anywhere above 1e-4 of its glare. Scene-linear
frames keep their energy: ``out = c - strength h + strength tint (PSF * h)``; with a white
tint the total light is unchanged away from the borders.

Display-referred (8-bit) input has no highlights above 1: luminance is first expanded by an
inverse tone curve ``e(L) = L / max(1 - L (1 - 1/B), 1/B)`` (``B`` = ``display_boost``: 1.0 maps
to B, hue kept), thresholded, spread and added (``out = c + strength tint (PSF * h)``).

Light spreads past the frame: the region of definition grows by the PSF radius, and light in
EXR overscan (data window larger than display window) contributes.  Only the bounding box of
the analysis tiles with highlights is transformed (``ctx.analysis.tiles_above``), and a frame
without any is an identity ("no pixel above threshold").  Non-finite input pixels are set
to 0 before the convolution and counted in ``ctx.notes``.

The machinery (shared with bleed and soft focus) is ``clfx.kit.scatter.ScatterPlugin``; the
quality levels are ``clfx.fx.fftconv.LEVELS`` (draft one pyramid level, preview float32 FFT
with bright pixels gathered exactly, final float64 FFT, reference float64 direct/FFT).

References
----------
Spencer, Shirley, Zimmerman, Greenberg 1995, "Physically-based glare effects for digital
images", SIGGRAPH.  Kawase 2003, "Frame buffer postprocessing effects in DOUBLE-S.T.E.A.L".
"""
from __future__ import annotations

from clfx.core.errors import ParamError
from clfx.core.plugin import ChoiceParam, Descriptor, FloatParam, PathParam
from clfx.fx import fftconv
from clfx.fx import psf as psflib
from clfx.host import Plugin, register
from clfx.kit.scatter import ScatterPlugin, knee_param, tint_param


@register
class Glare(ScatterPlugin, Plugin):
    descriptor = Descriptor(
        name="glare", label="Glare", group="Lens", kernel="glare.cl",
        summary="Highlights scattered by a large point spread function (Spencer eye PSF, "
                "Gaussian bloom or a kernel image), HDR-safe FFT convolution.  The Spencer "
                "and Gaussian tails are below 1e-5 of the PSF one pixel out from 0.9 x size "
                "and end (raised cosine) at size x the diagonal.  At the defaults a "
                "uniform bright field scatters 0.36 % of its light into a black spot 2 % "
                "of the diagonal wide (ISO 9358's veiling glare index, the spot on axis): "
                "added to the taking lens's own veil, which published VGIs of modern "
                "multi-coated primes put at ~1-3 %, a plate stays within a real lens's "
                "range; strength 0.14 alone makes a 1 % VGI.",
        spreads_light=True,
        params=(
            FloatParam("strength", 0.05, min=0.0, max=1.0,
                       hint="Fraction of the highlight light that scatters (0 = off)."),
            FloatParam("threshold", 1.0, min=0.0, max=1e6,
                       hint="Scene-linear luminance where light starts to scatter."),
            knee_param(0.5),
            FloatParam("size", 0.15, min=0.0, max=2.0,
                       hint="PSF support radius as a fraction of the frame diagonal: the tail "
                            "fades below 1e-5 of the PSF one pixel out by 0.9 x size, 0 beyond."),
            ChoiceParam("psf", "spencer", choices=("spencer", "gaussians", "image"),
                        hint="Spencer et al. 1995 eye PSF, a sum of Gaussians, or a kernel image."),
            PathParam("kernel_path", "",
                      hint="Kernel image for psf 'image' (centred; larger side spans 2 x size)."),
            FloatParam("fov", 0.0, min=0.0, max=179.0,
                       hint="Horizontal field of view in degrees for the Spencer PSF; 0 = from the camera."),
            tint_param("scattered"),
            FloatParam("display_boost", 8.0, min=1.0, max=1000.0,
                       hint="Display-referred input only: value a white pixel is expanded to before spreading."),
        ),
        quality=fftconv.LEVELS,
    )

    def boost(self, p, ctx):
        return p.display_boost if ctx.display_referred else 0.0

    def build_psf(self, p, ctx, radius, reach=None):
        """The PSF ``p.psf`` at ``radius`` pixels (its rows and columns within ``reach``)."""
        if p.psf == "spencer":
            dpp = psflib.degrees_per_pixel(ctx.camera, ctx.width_px, p.fov)
            return psflib.spencer(radius, dpp, reach=reach)
        if p.psf == "gaussians":
            sig, w = psflib.bloom_sigmas(radius)
            return psflib.gaussians(radius, sig, w, reach)
        if not p.kernel_path:
            raise ParamError("glare.kernel_path: psf 'image' needs a kernel image path")
        return psflib.from_image(ctx.read_image(p.kernel_path), radius, reach)
