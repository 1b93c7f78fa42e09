"""Lens flare: aperture-shaped ghosts along the line through each light and the image centre,
plus a halo.

Model
-----
Light sources are the bright connected regions of the scene analysis
(``ctx.analysis.light_sources(threshold, margin_px)``: tile-level, 8-connected, including
lights up to ``margin`` outside the display window when the data window has overscan).  Each
is refined on the device: over its bounding box, the highlight ``rgb * max(lum - t, 0) / lum``
is summed to the source's flux ``F`` (RGB, pixel sums) and its centre ``L`` is the centroid
weighted by ``max(lum - t, 0)``.  The ``max_sources`` most energetic sources flare.

A ghost is an out-of-focus image of the aperture formed by an even number of reflections
between lens surfaces; it lies on the line through the light and the optical centre ``c``
(the display window's centre): centre ``c + k (L - c)`` (k < 0: on the other side of the
centre, k > 1: beyond the light), radius ``size * diagonal``.  Its radiance is

    E = intensity * tint * F / area

(the ghost spreads the light it receives over its area, so large ghosts are dim; ``area`` is
the integral of the ghost's soft-edged coverage, so each ghost carries exactly
``intensity * tint * F``), shaped as the aperture: a regular N-gon (camera blades and
rotation; ``roundness`` blends to a disk) with a smooth edge ``softness * r`` wide (at least
1.5 px) and a radial profile ``1 - rim + rim rho^2`` (real ghosts are often brighter towards
their rim).  The halo is a Gaussian ring of radius ``halo_radius`` and width ``halo_width`` (fractions of the diagonal) around ``c``,
brightest on the light's side ((1 + cos)/2)^2, carrying ``halo_intensity * F`` in total.
Output = sanitised source + ghosts + halos; alpha kept.

Ghost table: ``ghosts`` = "k:size:r,g,b;..." overrides the default table (``ghost_count``
takes its first entries).  Defaults after the look of multi-coated zooms: a few small
greenish/magenta ghosts near the centre, larger faint ones beyond it.

Determinism: a per-pixel gather over the entries overlapping each 32 x 32 tile (the lists
are built on the host, in a fixed order); no atomics.  References: Hullin et al. 2011,
"Physically-based real-time lens flare rendering" (ghost formation); J. Chapman, "Pseudo lens
flare" (halo).
"""
from __future__ import annotations

import functools
import math

import numpy as np

from clfx.core.errors import ParamError
from clfx.core.plugin import Descriptor, FloatParam, IntParam, Level, StringParam
from clfx.host import Plugin, register
from clfx.core.rect import Rect

DEFAULT_GHOSTS = (
    # k (position), size (fraction of diagonal), tint (RGB)
    (-0.45, 0.030, (0.10, 0.45, 0.20)),
    (-0.85, 0.060, (0.35, 0.20, 0.45)),
    (0.35, 0.015, (0.45, 0.40, 0.15)),
    (-0.20, 0.012, (0.25, 0.35, 0.60)),
    (-1.30, 0.100, (0.20, 0.25, 0.45)),
    (0.65, 0.045, (0.40, 0.25, 0.15)),
    (-0.65, 0.020, (0.50, 0.30, 0.10)),
    (1.25, 0.070, (0.15, 0.35, 0.30)),
)
"""The default ghost table: with the default ``intensity`` 0.05 a ghost carries 0.5-2.5 % of
its light's flux (coated zooms show ghosts of ~1e-3..1e-2; a stronger look is the default)."""

TILE = 32
ENTRY = 12
FLOAT32_MAX = float(np.finfo(np.float32).max)

LEVELS = {  # one closed form at every level; fp64: the sources' flux and centroid sums
    "draft": Level("analytic ghosts, float32 per pixel (exact closed form; all levels equal)",
                   fp64=True),
    "preview": Level("analytic ghosts, float32 per pixel", fp64=True),
    "final": Level("analytic ghosts, float32 per pixel", fp64=True),
    "reference": Level("analytic ghosts, float32 per pixel; source measurement in float64 at "
                       "every level", fp64=True),
}


def parse_ghosts(spec: str, count: int) -> list[tuple[float, float, tuple[float, float, float]]]:
    """The ghost table: ``spec`` ("k:size:r,g,b;...") or the first ``count`` default ghosts."""
    if not spec.strip():
        return list(DEFAULT_GHOSTS[:count])
    out = []
    for i, item in enumerate(t for t in spec.split(";") if t.strip()):
        parts = item.split(":")
        try:
            k, size = float(parts[0]), float(parts[1])
            tint = (tuple(float(v) for v in parts[2].split(",")) if len(parts) > 2
                    else (1.0,) * 3)
        except (ValueError, IndexError):
            raise ParamError(f"lens_flare.ghosts: entry {i} {item!r} is not "
                             f"'k:size:r,g,b'") from None
        finite = all(map(math.isfinite, (k, size) + tint))
        if len(tint) != 3 or size <= 0 or min(tint) < 0 or not finite:
            raise ParamError(f"lens_flare.ghosts: entry {i} {item!r} needs size > 0 and 3 "
                             f"non-negative tint values")
        out.append((k, size, tint))
    return out


def aperture_normals(blades: int, rotation_deg: float) -> np.ndarray:
    """Unit edge normals (x right, y down) of a regular N-gon with vertex 0 at rotation."""
    if blades < 3:
        return np.zeros((1, 2), np.float32)
    t = math.radians(rotation_deg) + math.pi * (2 * np.arange(blades) + 1) / blades
    return np.stack([np.cos(t), -np.sin(t)], axis=1).astype(np.float32)


def smooth_edge(rho, edge):
    """Ghost coverage: 1 inside rho <= 1 - edge, smoothstep down to 0 at rho = 1."""
    s = np.clip((1.0 - rho) / edge, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


@functools.lru_cache(maxsize=256)
def ghost_area(blades: int, rotation_deg: float, roundness: float, edge: float,
               rim: float = 0.0) -> float:
    """Integral of a ghost's coverage in units of r^2 (r = circumradius).

    The normalised distance rho is a gauge (rho(t p) = t rho(p)), so the area of rho <= t is
    t^2 A1 with A1 = 1/2 integral of g(phi)^-2 dphi, g = rho on the unit circle; the soft edge then
    weighs the ring at t by w(t) (1 - rim + rim t^2) 2t dt.
    """
    phi = (np.arange(7200) + 0.5) * (2 * math.pi / 7200)
    g = np.ones_like(phi)
    if blades >= 3:
        n = aperture_normals(blades, rotation_deg).astype(np.float64)
        poly = (np.cos(phi)[:, None] * n[:, 0] - np.sin(phi)[:, None] * n[:, 1]).max(axis=1)
        poly /= math.cos(math.pi / blades)
        g = poly + (1.0 - poly) * roundness
    a1 = 0.5 * np.mean(g ** -2.0) * 2 * math.pi
    t = (np.arange(4000) + 0.5) / 4000
    return float(a1 * np.mean(smooth_edge(t, edge) * (1 - rim + rim * t * t) * 2 * t))


def flare_entries(sources, p, centre, diagonal, blades=0, rotation_deg=0.0) -> np.ndarray:
    """Entries (ghosts then halo per source), shape (n, ENTRY), from measured sources.

    ``sources``: list of (x, y, (F_r, F_g, F_b)) in frame pixels.  A radiance beyond the
    float32 range saturates at its largest value (the kernel saturates its sums too), so a
    finite frame gives a finite flare.
    """
    cx, cy = centre
    rows = []
    table = parse_ghosts(p.ghosts, p.ghost_count)
    for lx, ly, flux in sources:
        flux = np.asarray(flux, np.float64)
        for k, size, tint in table:
            r = size * diagonal
            edge = max(p.softness, 1.5 / max(r, 1e-6))
            area = ghost_area(blades, rotation_deg, p.roundness, edge, p.rim) * r * r
            e = np.minimum(p.intensity * np.asarray(tint) * flux / area, FLOAT32_MAX)
            rows.append([cx + k * (lx - cx), cy + k * (ly - cy), r, 1.0 / edge, *e, 0, 0, 0, 0, 0])
        if p.halo_intensity > 0:
            rh, sigma = p.halo_radius * diagonal, max(p.halo_width * diagonal, 0.5)
            norm = 2 * math.pi * rh * sigma * math.sqrt(2 * math.pi) * 0.375 + 1e-300
            e = np.minimum(p.halo_intensity * flux / norm, FLOAT32_MAX)
            d = math.hypot(lx - cx, ly - cy)
            ux, uy = ((lx - cx) / d, (ly - cy) / d) if d > 1e-6 else (0.0, 0.0)
            rows.append([cx, cy, rh, 1.0 / sigma, *e, 1, ux, uy, 0, 0])
    return np.asarray(rows, np.float64).reshape(-1, ENTRY)


def entry_reach(e: np.ndarray) -> float:
    """Radius (px) beyond which an entry contributes nothing (ghost) or < 1e-4 (halo)."""
    return e[2] + (4.3 / e[3] if e[7] == 1 else 0.0) + 2.0


def tile_lists(entries: np.ndarray, window: Rect):
    """CSR lists of the entries overlapping each TILE x TILE tile of ``window`` (fixed order)."""
    tx, ty = max(1, -(-window.width // TILE)), max(1, -(-window.height // TILE))
    # r is a ghost's circumradius, so it bounds the polygon and the disk alike
    lists = [[] for _ in range(tx * ty)]
    for i, e in enumerate(entries):
        reach = entry_reach(e)
        x0 = int(math.floor((e[0] - reach - window.x0) / TILE))
        x1 = int(math.floor((e[0] + reach - window.x0) / TILE))
        y0 = int(math.floor((e[1] - reach - window.y0) / TILE))
        y1 = int(math.floor((e[1] + reach - window.y0) / TILE))
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, tx - 1), min(y1, ty - 1)
        if e[7] == 1:  # halo: skip tiles entirely inside the ring's hole
            inner = e[2] - 4.3 / e[3]
        for yy in range(y0, y1 + 1):
            for xx in range(x0, x1 + 1):
                if e[7] == 1 and inner > 0:
                    tx0, ty0 = window.x0 + xx * TILE - e[0], window.y0 + yy * TILE - e[1]
                    far_x = max(abs(tx0), abs(tx0 + TILE))
                    far_y = max(abs(ty0), abs(ty0 + TILE))
                    if math.hypot(far_x, far_y) < inner:
                        continue
                lists[yy * tx + xx].append(i)
    start = np.zeros(tx * ty + 1, np.int32)
    start[1:] = np.cumsum([len(t) for t in lists])
    flat = np.fromiter((i for t in lists for i in t), np.int32, count=int(start[-1]))
    return tx, start, flat if flat.size else np.zeros(1, np.int32)


@register
class LensFlare(Plugin):
    descriptor = Descriptor(
        name="lens_flare", label="Lens flare", group="Lens", kernel="lens_flare.cl",
        summary="Aperture-shaped ghosts along the line through each light and the image "
                "centre, plus a halo; lights just outside the frame flare too.",
        spreads_light=True,
        params=(
            FloatParam("threshold", 5.0, min=0.0, max=1e6,
                       hint="Scene-linear luminance above which a region is a light source."),
            FloatParam("intensity", 0.05, min=0.0, max=1000.0,
                       hint="Ghost brightness: fraction of a light's flux times the ghost tint, "
                            "spread over the ghost's area."),
            IntParam("ghost_count", 6, min=0, max=len(DEFAULT_GHOSTS),
                     hint="How many ghosts of the default table to use (when `ghosts` is empty)."),
            StringParam("ghosts", "",
                        hint="Ghost table 'k:size:r,g,b;...': position factor along light-centre "
                             "line (0 = centre, 1 = light), radius (fraction of diagonal), tint."),
            FloatParam("softness", 0.15, min=0.0, max=1.0,
                       hint="Ghost edge width as a fraction of its radius."),
            FloatParam("rim", 0.4, min=0.0, max=1.0,
                       hint="Ghost brightness profile: 0 = flat, 1 = dark centre rising to a "
                            "bright rim (1 - rim + rim * rho^2)."),
            FloatParam("roundness", 0.0, min=0.0, max=1.0,
                       hint="0 = the aperture polygon, 1 = a disk."),
            IntParam("blades", 0, min=0, max=32,
                     hint="Ghost polygon sides; 0 = the camera block's blades (0 there = round)."),
            FloatParam("rotation", 0.0, min=-360.0, max=360.0, units="deg",
                       hint="Added to the camera's blade rotation, degrees counter-clockwise."),
            FloatParam("halo_radius", 0.3, min=0.0, max=2.0,
                       hint="Halo ring radius around the centre, fraction of the diagonal."),
            FloatParam("halo_width", 0.02, min=0.0005, max=1.0,
                       hint="Halo ring Gaussian width (sigma), fraction of the diagonal."),
            FloatParam("halo_intensity", 0.005, min=0.0, max=100.0,
                       hint="Fraction of a light's flux in its halo (0 = no halo)."),
            IntParam("max_sources", 8, min=1, max=64,
                     hint="At most this many lights flare (the most energetic)."),
            FloatParam("margin", 0.1, min=0.0, max=2.0,
                       hint="Lights up to this far outside the display window (fraction of the "
                            "diagonal, where the data window has overscan) still flare."),
        ),
        quality=LEVELS,
    )

    # sources --------------------------------------------------------------------------
    def candidate_sources(self, p, ctx):
        margin = int(math.ceil(p.margin * ctx.diagonal_px))
        return ctx.analysis.light_sources(p.threshold, margin_px=margin)[:p.max_sources]

    def measure(self, rt, p, ctx, candidates):
        """(x, y, flux RGB) per source in frame pixels, refined on the device."""
        src = ctx.source
        boxes = []
        for s in candidates:
            b = s.bbox.intersect(src.window)
            boxes.append([b.x0 - src.window.x0, b.y0 - src.window.y0,
                          b.x1 - src.window.x0, b.y1 - src.window.y0])
        n = len(boxes)
        out = rt.buffer(8 * 4 * n)
        knl = rt.kernel("lens_flare.cl", "lens_flare_measure", fp64=self.level(ctx).fp64)
        rt.launch(knl, (n,), src, np.int32(src.pitch),
                  rt.to_device(np.asarray(boxes, np.int32).ravel()), np.int32(n),
                  np.float32(p.threshold), out)
        m = rt.from_device(out, np.float32, 8 * n).reshape(n, 8).astype(np.float64)
        return [(src.window.x0 + r[4], src.window.y0 + r[5], tuple(r[:3])) for r in m if r[3] > 0]

    # cheap questions ------------------------------------------------------------------
    def is_identity(self, p, ctx):
        if p.intensity == 0.0 and p.halo_intensity == 0.0:
            return "intensity and halo_intensity are 0"
        if not parse_ghosts(p.ghosts, p.ghost_count) and p.halo_intensity == 0.0:
            return "no ghosts and no halo"
        if not ctx.analysis.any_above(p.threshold):
            return "no pixel above threshold"
        if not self.candidate_sources(p, ctx):
            return "no light source in or near view"
        return None

    def region_of_definition(self, p, ctx):
        # ghosts land anywhere on the display (and beyond, but only the display is kept)
        return ctx.source.window.union(ctx.display_window)

    # render ---------------------------------------------------------------------------
    def render(self, rt, p, ctx):
        src = ctx.source
        out_win = self.output_window(p, ctx)
        sources = self.measure(rt, p, ctx, self.candidate_sources(p, ctx))
        blades = p.blades or ctx.camera.blades
        normals = aperture_normals(blades, ctx.camera.blade_rotation + p.rotation)
        entries = flare_entries(sources, p, ctx.display_window.center, ctx.diagonal_px,
                                blades, ctx.camera.blade_rotation + p.rotation)
        tiles_x, start, flat = tile_lists(entries, out_win)
        ent = entries.astype(np.float32).ravel() if entries.size else np.zeros(ENTRY, np.float32)
        out = rt.image(out_win)
        ox, oy = src.window.offset_in(out_win)
        i32 = np.int32
        knl = rt.kernel("lens_flare.cl", "lens_flare_render", TILE=TILE,
                        BLADES=blades if blades >= 3 else 0)
        rt.launch(knl, (out.pitch // 4, out.height), src, i32(src.pitch), i32(src.width),
                  i32(src.height), i32(ox), i32(oy), out, i32(out.pitch), i32(out.width),
                  i32(out.height), i32(out_win.x0), i32(out_win.y0), i32(tiles_x),
                  rt.to_device(start), rt.to_device(flat), rt.to_device(ent),
                  rt.to_device(normals.ravel()), np.float32(p.roundness), np.float32(p.rim))
        ctx.notes.append(f"lens_flare: {len(sources)} light source(s)")
        bad = ctx.analysis.nonfinite_count
        if bad:
            ctx.notes.append(f"lens_flare: {bad} non-finite pixels set to 0")
        return out
