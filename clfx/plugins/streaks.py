"""Streaks: star-filter streaks and the diffraction spikes of a bladed aperture.

Model
-----
A streak comes from the light above its level: ``rgb * max(lum - t, 0) / lum`` with ``t`` the
larger of ``threshold`` and ``core`` times the peak luminance of the light the pixel belongs to
(the connected region of 32 px scene-analysis tiles brighter than ``threshold``).  So a candle
streaks from its bright core, not from its glow or the wax it lights, and the streak is as
wide as that core (``core = 0``: everything above ``threshold`` streaks, the former model).
``source_color`` mixes the streaking light towards its luminance (0: the streak's colour is
the tint alone, as the coatings of an anamorphic lens colour its streaks whatever the light).
These highlights are spread along ``n`` directions by a one-sided exponential line kernel
per direction,

    K_d(x) = sum_{k=0}^{4^N - 1} a_c^k  delta(x - k d),   a_c = 0.01^(1 / L_c),

so a streak has faded to 1% of its start after ``L_c`` pixels (``length`` times the frame
diagonal; ``color_shift`` makes red travel further than blue, or the reverse, so a streak
changes colour along its length as a diffraction streak does).  Each direction's kernel is
normalised to sum to ``intensity * tint_c / n``, so the added light equals ``intensity`` times
the highlights' energy.  Output = sanitised source + streaks; alpha is kept.

Star filter (``mode="star"``): ``streaks`` directions at ``angle + 360 i / streaks`` degrees,
counter-clockwise from +x (screen up is -y).  A scratched filter gives a streak
perpendicular to each scratch; ``streaks`` counts the rays, not the scratches.

Diffraction spikes (``mode="aperture"``): the far field of a straight blade edge is a line
perpendicular to it (the Fourier transform of a half plane), so an N-blade polygon aperture
(vertices at ``blade_rotation + 360 i / N``) makes spikes along its edge normals,
``blade_rotation + 180 (2i + 1) / N`` and their opposites: N spikes for even N (opposite
edges are parallel), 2N for odd N (Ritschel et al. 2009).  ``blades = 0`` takes the camera
block's blades and rotation; a round aperture has no spikes: the step does nothing and says
so on stderr (``ctx.warnings``).

Algorithm (Kawase 2003, "Frame buffer postprocessing effects in DOUBLE-S.T.E.A.L")
-----------------------------------------------------------------------------------
Per direction, N = ceil(log4(L' + 1)) passes; pass n has 4 taps at offsets ``s * 4^n * d``
(s = 0..3) with weights ``a_c^(s 4^n)``, where the step ``d`` is one whole pixel along the
ray's major axis (|d| = 1 / max(|cos|, |sin|) px, L' = L / |d| steps), so taps fall on
pixel columns (rows) and interpolate linearly between two pixels.  Every k in [0, 4^N) has
exactly one base-4 expansion, so the passes compose to exactly the truncated exponential
above: 4N taps per pixel instead of L.  Interpolated taps blur each pass by a sub-pixel
amount across the streak (not at all for rays at multiples of 45 degrees); the oracle
(``tests/reference/streaks.py``) computes exactly this composition in float64, and
``line_kernel_streaks`` there the exponential line kernel at the same tap positions (one
interpolated tap per step k).

Error against that exact line kernel, measured (float64, one ray, L = 60 px, 1e4 point):
identical energy; identical kernels at multiples of 45 degrees; at 30 degrees a relative L1
difference of 0.25 (0.27 with the snapped taps of draft/preview/final) and an rms width
across the ray of 0.47 px (0.45 snapped) against 0.35 px: the Kawase streak is a fraction
of a pixel wider, never longer or brighter.  At 1080p (one 30-degree ray, L = 100 px, 12
lights), max error / peak against the exact line kernel: reference 3.7e-2, final 4.7e-2,
preview 0.22, draft 0.47 (reduced resolution widens the ray).  Truncation at 4^N - 1 >= L'
drops at most 1% of the infinite exponential's energy (the kernel is renormalised).

Quality levels run the passes at 1/4 (draft), 1/2 (preview) or full (final, reference)
resolution (bright-pass box-averaged, steps scaled, bilinear upsample on compose); below
reference, passes whose step is >= 16 px round their taps to whole pixels (one load, half a
pixel of wander at most per pass).
References: M. Kawase, GDC 2003; T. Ritschel et al., "Temporal glare", Eurographics 2009.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clfx.core.camera import BLADES_WHY, NO_POLYGON
from clfx.core.plugin import ChoiceParam, Descriptor, FloatParam, IntParam, Level, RGBParam
from clfx.host import Plugin, register

TAPS = 4
"""Taps per pass; pass n steps 4^n pixels, so N passes cover 4^N - 1 pixels."""


@dataclass(frozen=True)
class StreaksLevel(Level):
    """A streaks quality level: the passes run at 1 / ``factor`` resolution; passes whose step
    is at least ``snap_from`` (working-resolution) pixels round each tap to a whole pixel (one
    load instead of an interpolated two; the ray wanders by at most half a pixel per snapped
    pass), 0 = always interpolate; ``fp64``: float64 tap sums."""

    factor: int = 1
    snap_from: int = 16


LEVELS = {
    "draft": StreaksLevel("Kawase passes at 1/4 resolution (box-averaged bright-pass, bilinear "
                          "upsample), taps of passes stepping >= 16 px snapped to whole pixels, "
                          "float32", factor=4),
    "preview": StreaksLevel("Kawase passes at 1/2 resolution, long-step taps snapped, float32",
                            factor=2),
    "final": StreaksLevel("Kawase passes at full resolution, long-step taps snapped, float32"),
    "reference": StreaksLevel("Kawase passes at full resolution, every tap interpolated, "
                              "float64 tap sums (exactly the oracle's composed kernel)",
                              fp64=True, snap_from=0),
}

MAX_MARGIN = 512
"""Largest zero margin (working-resolution pixels) given to the pass buffers; longer rays use
bounds-tested taps instead."""

LOCAL = (64, 1)
"""Work-group of the pass kernel (measured fastest on PoCL here: 16 vs 20 ms per pass)."""


def streak_angles(mode: str, streaks: int, angle: float, blades: int,
                  blade_rotation: float) -> list[float]:
    """Directions of the rays in degrees (counter-clockwise from +x, screen up = -y).

    ``mode="star"``: ``streaks`` rays from ``angle``.  ``mode="aperture"``: edge normals of a
    regular ``blades``-gon rotated by ``blade_rotation`` plus ``angle``, and their opposites
    (N for even N, 2N for odd N); empty for a round aperture (``blades < 3``).
    """
    if mode == "star":
        return [angle + 360.0 * i / streaks for i in range(streaks)]
    if blades < 3:
        return []
    normals = [blade_rotation + angle + 180.0 * (2 * i + 1) / blades for i in range(blades)]
    rays = normals + [a + 180.0 for a in normals]
    unique = []
    for a in rays:
        if all(abs((a - b + 180.0) % 360.0 - 180.0) > 1e-6 for b in unique):
            unique.append(a)
    return unique


def direction(angle_deg: float) -> tuple[float, float]:
    """Unit step (dx, dy) in image coordinates (+y down) for a screen angle."""
    t = math.radians(angle_deg)
    dx, dy = math.cos(t), -math.sin(t)
    # exact zeros for axis-aligned rays: no bilinear blur across them
    return (0.0 if abs(dx) < 1e-12 else dx, 0.0 if abs(dy) < 1e-12 else dy)


def grid_step(angle_deg: float) -> tuple[float, float, float]:
    """One tap step along a ray, (sx, sy, length px): a whole pixel along the ray's major
    axis, a fraction along the minor one.  Taps then fall on pixel columns (or rows), so a
    tap interpolates linearly between 2 pixels instead of 4 (half the loads, and no blur along
    the major axis)."""
    dx, dy = direction(angle_deg)
    major = max(abs(dx), abs(dy))
    return dx / major, dy / major, 1.0 / major


def channel_lengths(length_px: float, color_shift: float) -> np.ndarray:
    """Per-channel 1% length in pixels: red longer and blue shorter for color_shift > 0."""
    return length_px * (1.0 + 0.5 * color_shift * np.array([1.0, 0.0, -1.0]))


def pass_count(max_length_px: float) -> int:
    """Smallest N with 4^N - 1 >= L (so the truncated tail is below 1% of the start)."""
    return max(1, math.ceil(math.log(max(max_length_px, 1.0) + 1.0, TAPS)))


def pass_weights(lengths_px: np.ndarray, passes: int, gain: np.ndarray) -> list[np.ndarray]:
    """Per-pass tap weights, shape (passes, 4 taps, 4 channels); gain folded into pass 0.

    ``gain`` (3,) is divided by the truncated kernel's sum so each channel sums to ``gain``.
    """
    a = 0.01 ** (1.0 / np.maximum(lengths_px, 1e-3))        # per-channel decay per pixel
    support = TAPS ** passes
    total = np.where(a < 1.0, (1.0 - a ** support) / np.maximum(1.0 - a, 1e-300), support)
    out = []
    for n in range(passes):
        b = TAPS ** n
        w = np.zeros((TAPS, 4))
        for s in range(TAPS):
            w[s, :3] = a ** (s * b)
        if n == 0:
            w[:, :3] *= gain / total
        out.append(w)
    return out


@register
class Streaks(Plugin):
    descriptor = Descriptor(
        name="streaks", label="Streaks (star filter)", group="Glare", kernel="streaks.cl",
        summary="Star-filter streaks or aperture diffraction spikes from the highlights, "
                "by iterated 4-tap passes (Kawase).",
        spreads_light=True,
        params=(
            FloatParam("threshold", 1.0, min=0.0, max=1e6,
                       hint="Scene-linear luminance above which pixels streak."),
            FloatParam("intensity", 0.1, min=0.0, max=100.0,
                       hint="Light added to the streaks as a fraction of the highlights' energy."),
            ChoiceParam("mode", "star", choices=("star", "aperture"),
                        hint="star: `streaks` rays at `angle`; aperture: diffraction spikes of "
                             "the blade polygon (N spikes for even N, 2N for odd N)."),
            IntParam("streaks", 4, min=1, max=32, hint="Number of rays in star mode."),
            FloatParam("angle", 45.0, min=-360.0, max=360.0, units="deg",
                       hint="Angle of the first ray (star) or extra aperture rotation, degrees "
                            "counter-clockwise from +x."),
            IntParam("blades", 0, min=0, max=32, exclude=NO_POLYGON, exclude_why=BLADES_WHY,
                     hint="Aperture blades in aperture mode; 0 = the camera block's blades."),
            FloatParam("length", 0.08, min=0.0005, max=2.0,
                       hint="Distance at which a streak has faded to 1%, as a fraction of the "
                            "frame diagonal."),
            FloatParam("core", 0.5, min=0.0, max=1.0,
                       hint="Only the light above this fraction of its light's peak luminance "
                            "streaks (a light: a connected region above threshold): the bright "
                            "core of a flame, not its glow or what it lights (0: all above "
                            "threshold)."),
            RGBParam("tint", (1.0, 1.0, 1.0), max=100.0, hint="Colour multiplier of the streaks."),
            FloatParam("source_color", 1.0, min=0.0, max=1.0,
                       hint="How much of the light's own colour a streak keeps: 1 = the "
                            "light's colour times tint; 0 = its luminance times tint (the "
                            "coating colours the streak, as anamorphic streaks)."),
            FloatParam("color_shift", 0.0, min=-1.0, max=1.0,
                       hint="Colour change along the streak: > 0 red reaches further (x1.5 at 1) "
                            "and blue less far (x0.5); < 0 the reverse."),
        ),
        quality=LEVELS,
    )

    # geometry -------------------------------------------------------------------------
    def angles(self, p, ctx) -> list[float]:
        blades = p.blades or ctx.camera.blades
        rotation = ctx.camera.blade_rotation if p.mode == "aperture" else 0.0
        return streak_angles(p.mode, p.streaks, p.angle, blades, rotation)

    def length_px(self, p, ctx) -> float:
        return p.length * ctx.diagonal_px

    def spread_px(self, p, ctx, factor: int = 1) -> int:
        """How far light travels: the truncated kernel's support plus the bilinear footprint."""
        longest = float(channel_lengths(self.length_px(p, ctx), p.color_shift).max())
        reach = 0.0
        for a in self.angles(p, ctx) or [0.0]:
            step = grid_step(a)[2]
            reach = max(reach, (TAPS ** pass_count(longest / factor / step)) * step * factor)
        return int(math.ceil(reach)) + 2 * factor

    # cheap questions ------------------------------------------------------------------
    def is_identity(self, p, ctx):
        if p.intensity == 0.0:
            return "intensity is 0"
        if p.mode == "aperture" and not self.angles(p, ctx):
            ctx.warnings.append("streaks: mode=aperture with a round aperture (camera blades "
                                "0 and blades 0) makes no diffraction spikes; set "
                                "camera.blades or streaks.blades (>= 3), or mode=star")
            return "round aperture (blades 0): no diffraction spikes"
        if not ctx.analysis.any_above(p.threshold):
            return "no pixel above threshold"
        return None

    def region_of_definition(self, p, ctx):
        return ctx.source.window.grown(self.spread_px(p, ctx, LEVELS["final"].factor))

    def region_of_interest(self, p, ctx, window):
        return window.grown(self.spread_px(p, ctx, LEVELS["final"].factor))

    @staticmethod
    def peak_map(p, ctx):
        """Per analysis tile, the peak luminance of the light (connected bright region) it
        belongs to, float32 (tiles_y x tiles_x) over the source window."""
        m = ctx.analysis.region_peaks(p.threshold)
        m = np.minimum(np.nan_to_num(m, nan=0.0, posinf=0.0), np.finfo(np.float32).max)
        return np.ascontiguousarray(m, np.float32).ravel(), m.shape[1], m.shape[0]

    # render ---------------------------------------------------------------------------
    def render(self, rt, p, ctx):
        src = ctx.source
        lvl = self.level(ctx)
        factor, snap_from = lvl.factor, lvl.snap_from
        out_win = self.output_window(p, ctx)
        ox, oy = src.window.offset_in(out_win)
        lo_w, lo_h = -(-out_win.width // factor), -(-out_win.height // factor)
        i32, f32 = np.int32, np.float32
        defines = {"FACTOR": factor, "fp64": lvl.fp64, **ctx.luminance_defines}

        angles = self.angles(p, ctx)
        lengths = channel_lengths(self.length_px(p, ctx), p.color_shift) / factor
        gain = p.intensity * np.asarray(p.tint) / len(angles)
        plans = []
        for a in angles:
            sx, sy, step_len = grid_step(a)
            passes = pass_count(float(lengths.max()) / step_len)
            plans.append((sx, sy, passes, pass_weights(lengths / step_len, passes, gain)))
        # zero margin wide enough for every tap (no bounds tests), unless the rays are so long
        # that the margin would cost more than the tests
        reach = 3 * TAPS ** (max(n for _, _, n, _ in plans) - 1) + 2
        margin = -(-reach // 4) * 4
        checked = margin > MAX_MARGIN
        if checked:
            margin = 0
        wp = -(-lo_w // 4) * 4
        pitch = wp + 2 * margin
        org = margin * pitch + margin
        nbytes = pitch * (lo_h + 2 * margin) * 16
        work = [rt.buffer(nbytes) for _ in range(3)]      # ping, pong, total
        for buf in work:
            rt.cl.enqueue_fill_buffer(rt.queue, buf.buffer, np.float32(0.0), 0, nbytes)
        ping, pong, total = work
        defines["CHECKED"] = int(checked)

        peak, tiles_x, tiles_y = self.peak_map(p, ctx)
        bright_knl = rt.kernel("streaks.cl", "streaks_bright", PEAK_TILE=ctx.analysis.tile,
                               **defines)
        peak_buf = rt.to_device(peak)
        step_knl = rt.kernel("streaks.cl", "streaks_pass", ACCUM=0, **defines)
        accum_knl = rt.kernel("streaks.cl", "streaks_pass", ACCUM=1, **defines)
        for sx, sy, passes, weights in plans:
            # each ray starts from the bright pixels, extracted again into pong (cheaper than
            # a fourth frame-sized buffer; passes write inside the zero margins only)
            rt.launch(bright_knl, (wp, lo_h), src, i32(src.pitch), i32(src.width),
                      i32(src.height), pong, i32(org), i32(pitch), i32(wp), i32(lo_h),
                      i32(ox), i32(oy), f32(p.threshold), peak_buf, i32(tiles_x),
                      i32(tiles_y), f32(p.core), f32(p.source_color))
            cur = pong
            for n in range(passes):
                last = n == passes - 1
                dst = total if last else (ping if cur is not ping else pong)
                b = TAPS ** n
                snap = snap_from > 0 and b >= snap_from
                w = [w4.astype(np.float32) for w4 in weights[n]]
                rt.launch(accum_knl if last else step_knl, (wp // 4, lo_h), cur, dst, i32(org),
                          i32(pitch), i32(wp), i32(lo_w), i32(lo_h), f32(sx * b), f32(sy * b),
                          i32(snap), *w, local=LOCAL)
                cur = dst
        del work, ping, pong

        out = rt.image(out_win)
        rt.launch(rt.kernel("streaks.cl", "streaks_compose", FACTOR=factor,
                            **ctx.luminance_defines),
                  (out.pitch, out_win.height), src, i32(src.pitch), i32(src.width),
                  i32(src.height), i32(ox), i32(oy), total, i32(org), i32(pitch), i32(lo_w),
                  i32(lo_h), out, i32(out.pitch), i32(out_win.width), i32(out_win.height))
        bad = ctx.analysis.nonfinite_count
        if bad:
            ctx.notes.append(f"streaks: {bad} non-finite pixels set to 0")
        return out
