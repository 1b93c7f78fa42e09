"""Lens flare: aperture-shaped ghosts along the line through each light and the image centre:
from a lens prescription (physical, the default) or from a table of ghosts (artistic).

Physical model (``model="physical"``)
-------------------------------------
``lens`` names a prescription (``presets/lenses/<name>.yaml``, or a YAML file: surfaces,
glasses, clear apertures, the stop, coatings), read through ``ctx.read_lens``.  Every ghost
that two reflections between its surfaces make is found by paraxial ray-transfer matrices
per wavelength (``clfx.fx.optics``: Lee & Eisemann 2013, Hullin et al. 2011), at the camera
block's f-number; the aperture is the camera's (``blades``, ``blade_rotation``).  A light is
every pixel above ``threshold`` in a connected bright region (scene analysis), its flux
``F`` the sum of those pixels (RGB), its position their luminance-weighted centroid, its
extent their rms radius.  Each ghost is the aperture polygon (or the round rim of a lens
limiting it) imaged through its matrix, cut by the clip discs of the other apertures on its
path, with per-wavelength sizes and positions (``final``: 7 wavelengths, ``clfx.fx.spectral``
weights per channel in linear Rec.709, the reference basis other working spaces are carried
into and back, ``clfx.kit.spectral.in_reference_basis``: coloured fringes), a
Fresnel-diffraction rim and edges blurred by the light's extent and the lens's aberrations,
and the brightness of its two coated reflections:
``F * energy / T_p`` over its area (``clfx.fx.flare``), times ``gain`` (default
``DEFAULT_GAIN`` = 50: the light a plate's recorded highlights leave out; 1 = the recorded
flux alone) up to ``light_level``: a light recorded at peak ``P`` takes ``min(gain,
max(GAIN_FLOOR, light_level / P))`` (``DEFAULT_LIGHT_LEVEL``: an unclipped sun or HDR flame
is not brightened as a clipped lamp is; 0 = every light the whole gain).
``coatings`` "multi" (the default) gives each glass-air surface its own
multilayer stack (``MULTI_COATINGS``: three-layer broadband and two-layer V-coats, each
surface tuned differently; reflectance per wavelength by the transfer-matrix method,
``clfx.fx.optics.thin_film_reflectance``), so ghosts differ in tint as a multi-coated
lens's do: green, magenta, amber, cyan, blue; "lens" keeps the prescription's coatings as
written (the shipped lenses: one MgF2 film, every ghost the same violet).  Ghosts larger
than 0.1 of the diagonal (radius) fade out by 0.2 of it (``clfx.fx.flare.VEIL_FROM``):
their paraxial shape is an artefact (real ones are vignetted and smeared into veiling glare,
the glare effect's business), not a polygon over the whole frame.  Ghosts fainter than ``cull`` times the frame's median tile luminance are not
drawn.  A light's flux takes each pixel's non-negative part per channel (in the reference
basis: a colour outside Rec.709 makes ghosts of its in-gamut part, the same in any working
space).  ``intensity``, ``ghost_count``, ``ghosts``, ``softness``, ``rim``, ``roundness``
and the halo belong to the artistic model.  The camera's focal length does not change the ghosts:
the prescription is its own lens (the light's position on the sensor is what matters, in mm
through the camera's ``sensor_width``).

Artistic model (``model="artistic"``)
-------------------------------------
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
their rim); softness and rim are per ghost (the table's, else the parameters').  The halo is a Gaussian ring of radius ``halo_radius`` and width ``halo_width`` (fractions of the diagonal) around ``c``,
brightest on the light's side ((1 + cos)/2)^2, carrying ``halo_intensity * F`` in total.
Output = sanitised source + ghosts + halos; alpha kept.

Ghost table: ``ghosts`` = "k:size:r,g,b[:softness[:rim]];..." overrides the default table
(``ghost_count`` takes its first entries).  Defaults after the look of multi-coated zooms:
ghosts that differ in size, sharpness, rim and tint (green, magenta, amber, blue, teal),
small crisp ones near the centre, larger soft ones beyond it, none mirroring another.

Determinism: a per-pixel gather over the entries overlapping each 32 x 32 tile (the lists
are built on the host, in a fixed order); no atomics.  References: Hullin et al. 2011,
"Physically-based real-time lens flare rendering" (ghost formation); J. Chapman, "Pseudo lens
flare" (halo).
"""
from __future__ import annotations

import functools
import math

import numpy as np

import json
from dataclasses import dataclass

from clfx.core.errors import ParamError
from clfx.core.camera import BLADES_WHY, NO_POLYGON
from clfx.core.plugin import ChoiceParam, Descriptor, FloatParam, IntParam, Level, StringParam
from clfx.core.rect import Rect
from clfx.fx import flare, optics, spectral
from clfx.host import Plugin, StepPlan, read_only, register
from clfx.kit.spectral import in_reference_basis

DEFAULT_GHOSTS = (
    # k (position), size (fraction of diagonal), tint (RGB), softness (edge / radius), rim
    (-0.42, 0.022, (0.10, 0.50, 0.18), 0.06, 0.7),    # small sharp green ring
    (-0.95, 0.075, (0.42, 0.14, 0.38), 0.45, 0.2),    # large soft magenta
    (0.31, 0.011, (0.55, 0.38, 0.07), 0.10, 0.5),     # tiny amber spot
    (-0.18, 0.040, (0.14, 0.28, 0.58), 0.70, 0.0),    # soft blue blob near the centre
    (-1.45, 0.130, (0.30, 0.32, 0.14), 0.35, 0.85),   # big faint olive ring beyond the centre
    (0.72, 0.028, (0.50, 0.22, 0.10), 0.25, 0.3),     # orange between light and centre
    (-0.66, 0.016, (0.55, 0.12, 0.45), 0.05, 0.9),    # crisp magenta ring
    (1.22, 0.055, (0.12, 0.40, 0.34), 0.55, 0.4),     # teal beyond the light
)
"""The default ghost table: with the default ``intensity`` 0.05 a ghost carries 0.5-2.5 % of
its light's flux (coated zooms show ghosts of ~1e-3..1e-2; a stronger look is the default).
Like a real zoom's ghosts they differ in size (0.011-0.13 of the diagonal), sharpness (edge
0.05-0.7 of the radius: a ghost focused near the sensor is crisp, others are blurs), rim
(0: flat, 0.9: a ring) and coating tint (green, magenta, amber, blue, olive, teal), at
positions that do not mirror each other about the centre."""

DEFAULT_GAIN = 50.0
"""The physical model's default ``gain``: the light a clipped highlight left out.  The
ghosts of two coated reflections carry R1 R2 of a light's flux: 1e-5-2.5e-5 for multilayer
coatings (0.3-0.5 % per surface), ~2e-4 single MgF2 (1.3-1.5 %), 1.6e-3 uncoated glass (4 %,
Fresnel).  A clipped lamp recorded at 20 is really ~1e3 times diffuse white (a frosted bulb
~5e4 cd/m^2 against a lit interior's white of 50-100 cd/m^2), so it takes 50: a 3 x 3 px
light 2000 times a flat background gives a brightest ghost of 0.1-0.5 times that background
and several at 0.5-3 % of it (f/2.8, the three shipped lenses multi-coated,
``tests/plugins/test_lens_flare.py``), faint as a modern lens's ghosts of a lamp are.  Until
issue 32 the default was 500 (ghosts 10 times brighter, an orange veil round a candle).
``gain: 1`` is the recorded flux alone."""

DEFAULT_LIGHT_LEVEL = 1e3
"""The physical model's default ``light_level`` (diffuse white = 1): a lamp is ~1e3 times
diffuse white, so ``gain`` stands for light a plate left out only up to this level: a light
recorded at peak ``P`` takes ``min(gain, max(GAIN_FLOOR, light_level / P))``.  A clipped
lamp at 20 takes the whole default gain (50); CandleGlass's flame, recorded unclipped at 212
in an HDR merge, 4.7; a sun recorded at 1e5 ``GAIN_FLOOR``."""

GAIN_FLOOR = 3.0
"""The least gain a light takes however bright it was recorded (when ``gain`` is larger):
what real ghosts gain over the paraxial two-reflection energy at oblique incidence (Fresnel
reflectance grows off-axis) and from worn or imperfect coatings (estimate).  At 3 the
sunny-day sun's brightest ghost peaks at ~1.7e-5 of the sun's peak (1.7 times diffuse white:
plain against dark ground, faint against the sky; at 30, until issue 32, 17 times).  On
CandleGlass (480 px wide) the flame, recorded at 205 and so taking 1e3 / 205 = 4.9, now puts
0.05 % of its light outside itself, its brightest ghost 6e-5 of its peak (0.9 % and 6e-4 at
the gain of 47 before, an orange veil beside the glass)."""


def light_gain(gain: float, light_level: float, peak: float) -> float:
    """The part of ``gain`` a light recorded at peak luminance ``peak`` takes: ``min(gain,
    max(GAIN_FLOOR, light_level / P)) / gain`` (1 where ``light_level`` is 0 or ``gain``
    is 0)."""
    if light_level <= 0.0 or gain <= 0.0 or not peak > 0.0:
        return 1.0
    return min(gain, max(GAIN_FLOOR, light_level / peak)) / gain


TILE = 32
ENTRY = 12
FLOAT32_MAX = float(np.finfo(np.float32).max)

PHYSICAL_TILE = 16
"""Tile of the physical ghosts' lists (level pixels): edges cost work only in their tiles."""


@dataclass(frozen=True)
class FlarePlan(StepPlan):
    """lens_flare's plan for one step of a frame: the physical model's visible ghosts
    ``(entries, levels, table rows, lights)`` (`LensFlare.ghost_plan`; `NO_GHOSTS` without
    a light), None for the artistic model."""

    ghosts: tuple | None = None


NO_GHOSTS = (*read_only(np.zeros((0, flare.ENTRY)), np.zeros(0, np.int64),
                        np.zeros(0, np.intp)), ())
"""The physical model's ghosts of a frame without a light (`LensFlare.ghost_plan`'s types):
a render that is called anyway draws none, without reading the lens or its ghost table."""


@dataclass(frozen=True)
class FlareLevel(Level):
    """A lens-flare quality level.  Physical model: ``wavelengths`` spectral samples (3: the
    Rec.709 primaries' dominant wavelengths, else evenly from 420 to 680 nm, spread over the
    channels by Rec.709's primaries: the reference basis),
    and the edge scale ``level_scale * 2^k`` (px) from which a ghost is drawn at ``1 / 2^k``
    resolution (``inf``: all at full resolution), up to ``1 / 2^max_level``.  The artistic
    model is one closed form at every level.  fp64: the lights' flux and centroid sums."""

    wavelengths: int = 7
    level_scale: float = 2.0
    max_level: int = 4


LEVELS = {
    "draft": FlareLevel("physical: 3 wavelengths (RGB), ghosts with edges of >= 1 px drawn at "
                        "reduced resolution; artistic: analytic ghosts (all levels equal)",
                        fp64=True, wavelengths=3, level_scale=1.0),
    # 6, not 5: five even samples of 420-680 nm integrate the colour matching functions
    # worse than draft's three primaries (bench 320x180 rel. RMSE 3.4e-5 against 2.9e-5);
    # six halve draft's error (1.4e-5; final 7.2e-6) at the cost of one more sample
    "preview": FlareLevel("physical: 6 wavelengths, edges >= 1.5 px at reduced resolution; "
                          "artistic: analytic ghosts", fp64=True, wavelengths=6, level_scale=1.5),
    "final": FlareLevel("physical: 7 wavelengths, edges >= 2 px at reduced resolution (bilinear "
                        "upsampling); artistic: analytic ghosts", fp64=True),
    "reference": FlareLevel("physical: 11 wavelengths, every ghost at full resolution; "
                            "artistic: analytic ghosts; float64 light measurement",
                            fp64=True, wavelengths=11, level_scale=math.inf),
}


def flare_wavelengths(count: int) -> tuple[float, ...]:
    """The wavelength samples (nm) of a level (see :class:`FlareLevel`)."""
    if count == 3:
        return optics.RGB_WAVELENGTHS_NM
    return tuple(float(v) for v in np.linspace(420.0, 680.0, count))


def flare_channel_weights(wavelengths, rgb_to_xyz=None) -> np.ndarray:
    """How each colour channel spreads over ``wavelengths`` (``clfx.fx.spectral``'s channel
    weights in the working space); three samples are one per channel in any space."""
    if len(wavelengths) == 3:
        return np.eye(3)
    return spectral.channel_weights(wavelengths, rgb_to_xyz)


def parse_ghosts(spec: str, count: int):
    """The ghost table: ``spec`` ("k:size:r,g,b[:softness[:rim]];...") or the first ``count``
    default ghosts; entries (k, size, tint, softness, rim), softness / rim ``None`` where the
    entry leaves them to the ``softness`` / ``rim`` parameters."""
    if not spec.strip():
        return list(DEFAULT_GHOSTS[:count])
    out = []
    for i, item in enumerate(t for t in spec.split(";") if t.strip()):
        parts = item.split(":")
        try:
            if len(parts) > 5:
                raise ValueError
            k, size = float(parts[0]), float(parts[1])
            tint = (tuple(float(v) for v in parts[2].split(",")) if len(parts) > 2
                    else (1.0,) * 3)
            soft = float(parts[3]) if len(parts) > 3 and parts[3].strip() else None
            rim = float(parts[4]) if len(parts) > 4 and parts[4].strip() else None
        except (ValueError, IndexError):
            raise ParamError(f"lens_flare.ghosts: entry {i} {item!r} is not "
                             f"'k:size:r,g,b[:softness[:rim]]'") from None
        finite = all(map(math.isfinite, (k, size) + tint))
        if len(tint) != 3 or size <= 0 or min(tint) < 0 or not finite:
            raise ParamError(f"lens_flare.ghosts: entry {i} {item!r} needs size > 0 and 3 "
                             f"non-negative tint values")
        for name, v in (("softness", soft), ("rim", rim)):
            if v is not None and not 0.0 <= v <= 1.0:
                raise ParamError(f"lens_flare.ghosts: entry {i} {item!r}: {name} {v!r} is "
                                 f"not in [0, 1]")
        out.append((k, size, tint, soft, rim))
    return out


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
        n = flare.aperture_normals(blades, rotation_deg)
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
        for k, size, tint, soft, rim in table:
            soft = p.softness if soft is None else soft
            rim = p.rim if rim is None else rim
            r = size * diagonal
            edge = max(soft, 1.5 / max(r, 1e-6))
            area = ghost_area(blades, rotation_deg, p.roundness, edge, rim) * r * r
            e = np.minimum(p.intensity * np.asarray(tint) * flux / area, FLOAT32_MAX)
            rows.append([cx + k * (lx - cx), cy + k * (ly - cy), r, 1.0 / edge, *e, 0, 0, 0,
                         rim, 0])
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


MULTI_COATINGS = (("broadband", 520.0), ("v-coat", 500.0), ("broadband", 540.0),
                  ("v-coat", 470.0), ("broadband-hi", 490.0), ("v-coat", 540.0),
                  ("broadband", 510.0), ("mgf2", 480.0), ("broadband-hi", 530.0),
                  ("v-coat", 520.0))
"""The films of a multi-coated lens, glass-air surface after surface: a design of
``clfx.fx.optics.MULTILAYER_DESIGNS`` and its wavelength (nm), as a maker mixes stacks and
tunes each surface differently.  Three-layer broadband stacks tuned to 510-540 nm reflect
a green hump between their two minima; quarter-quarter V-coats reflect magenta-purple
(tuned to the green), amber (to the blue) or violet-blue (to the yellow); the plain MgF2
film amber-pink.  A ghost's tint is the product of its two surfaces' curves: green, cyan,
magenta, amber, blue and near-white ghosts from one lens (``tests/plugins/
test_lens_flare.py``)."""


def multi_coated(d: dict) -> dict:
    """A lens dictionary whose glass-air surfaces without a coating of their own carry the
    stacks of ``MULTI_COATINGS`` in turn, as a maker coats each surface of a multi-coated
    lens differently; a bare lens (``coating: none``) stays bare."""
    base = d.get("coating", "default")
    if base is None or base is False or base == "none":
        return d
    rows = d.get("surfaces")
    if not isinstance(rows, list):
        return d
    out, n_before, j = [], 1.0, 0
    for row in rows:
        if isinstance(row, (list, tuple)) and len(row) == len(optics._ROW):
            row = dict(zip(optics._ROW, row))
        if not isinstance(row, dict):
            return d                         # malformed: let the prescription say why
        nd = row.get("nd")
        nd = 1.0 if nd is None else nd
        if "coating" not in row and (nd == 1.0) != (n_before == 1.0):
            design, nm = MULTI_COATINGS[j % len(MULTI_COATINGS)]
            row = {**row, "coating": {"design": design, "wavelength": nm}}
            j += 1
        out.append(row)
        n_before = nd
    return {**d, "surfaces": out}


@register
class LensFlare(Plugin):
    whole_frame = ("its ghosts come from the lights measured over the whole frame")
    descriptor = Descriptor(
        name="lens_flare", label="Lens flare", group="Lens", kernel="lens_flare.cl",
        summary="Ghosts of the aperture along the line through each light and the image "
                "centre: every two-reflection ghost of a lens prescription, coloured and "
                "as dim as its coatings make it (physical), or a ghost table and a halo "
                "(artistic); lights just outside the frame flare too.  Defaults after "
                "published reflectances (Fresnel 4 % per uncoated surface, 1.3-1.5 % MgF2, "
                "0.3-0.5 % multilayer: a ghost carries R1 R2 = 1e-5-2.5e-5 of its light): "
                "gain 50 for a clipped lamp (~1e3 x diffuse white), 3 for an unclipped sun "
                "or flame, so a sun at 1e5 lays ghosts of ~2e-5 of its peak; ghosts wider "
                "than 5 % of the diagonal fade out by 10 % (a real lens smears them into "
                "veiling glare: the glare effect).",
        spreads_light=True,
        params=(
            FloatParam("threshold", 5.0, min=0.0, max=1e6,
                       hint="Scene-linear luminance above which a region is a light source."),
            ChoiceParam("model", "physical", choices=("physical", "artistic"),
                        hint="physical: the ghosts of a lens prescription (`lens`); artistic: "
                             "the ghost table (`ghosts`, `intensity`) and a halo."),
            StringParam("lens", "double-gauss-50mm",
                        hint="Physical: a shipped prescription (presets/lenses/NAME.yaml: "
                             "double-gauss-50mm, retrofocus-28mm, zoom-80-200mm) or a YAML "
                             "file."),
            FloatParam("gain", DEFAULT_GAIN, min=0.0, max=1e6,
                       hint="Physical: multiplies the ghosts' brightness (1 = the coated "
                            "reflections of the recorded light alone; the default stands for "
                            "the light a plate's clipped highlights leave out)."),
            FloatParam("light_level", DEFAULT_LIGHT_LEVEL, min=0.0, max=1e12,
                       hint="Physical: the luminance real lights have (diffuse white = 1): a "
                            "light recorded at peak P takes min(gain, max(3, light_level / P)), "
                            "so an unclipped bright light (a sun at 1e5, an HDR candle at 200) "
                            "is not brightened as a clipped one; 0 = every light the whole "
                            "gain."),
            ChoiceParam("coatings", "multi", choices=("multi", "lens"),
                        hint="Physical: multi = each glass-air surface its own multilayer "
                             "stack (ghosts green, magenta, amber, cyan, blue); lens = the "
                             "prescription's coatings as written (one film: all alike)."),
            FloatParam("cull", 0.01, min=0.0, max=1.0,
                       hint="Physical: ghosts whose brightest pixel stays below this fraction "
                            "of the frame's median tile luminance are not drawn."),
            FloatParam("intensity", 0.05, min=0.0, max=1000.0,
                       hint="Artistic: ghost brightness, fraction of a light's flux times the "
                            "ghost tint, spread over the ghost's area."),
            IntParam("ghost_count", 6, min=0, max=len(DEFAULT_GHOSTS),
                     hint="Artistic: how many ghosts of the default table to use (when `ghosts` is empty)."),
            StringParam("ghosts", "",
                        hint="Artistic: ghost table 'k:size:r,g,b[:softness[:rim]];...': position factor "
                             "along light-centre line (0 = centre, 1 = light), radius (fraction "
                             "of diagonal), tint, optional edge softness and rim of the ghost."),
            FloatParam("softness", 0.15, min=0.0, max=1.0,
                       hint="Artistic: ghost edge width as a fraction of its radius (ghosts without their own)."),
            FloatParam("rim", 0.4, min=0.0, max=1.0,
                       hint="Artistic: ghost brightness profile, 0 = flat, 1 = dark centre rising to a "
                            "bright rim (1 - rim + rim * rho^2)."),
            FloatParam("roundness", 0.0, min=0.0, max=1.0,
                       hint="Artistic: 0 = the aperture polygon, 1 = a disk."),
            IntParam("blades", 0, min=0, max=32, exclude=NO_POLYGON, exclude_why=BLADES_WHY,
                     hint="Ghost polygon sides; 0 = the camera block's blades (0 there = round)."),
            FloatParam("rotation", 0.0, min=-360.0, max=360.0, units="deg",
                       hint="Added to the camera's blade rotation, degrees counter-clockwise."),
            FloatParam("halo_radius", 0.3, min=0.0, max=2.0,
                       hint="Artistic: halo ring radius around the centre, fraction of the diagonal."),
            FloatParam("halo_width", 0.02, min=0.0005, max=1.0,
                       hint="Artistic: halo ring Gaussian width (sigma), fraction of the diagonal."),
            FloatParam("halo_intensity", 0.005, min=0.0, max=100.0,
                       hint="Artistic: fraction of a light's flux in its halo (0 = no halo)."),
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

    def measure(self, rt, p, ctx, candidates, full: bool = False):
        """(x, y, flux RGB) per source in frame pixels, refined on the device; ``full``:
        the whole light (not only its excess over the threshold), as ``flare.Light`` with
        its rms radius."""
        src = ctx.source
        boxes = []
        for s in candidates:
            b = s.bbox.intersect(src.window)
            boxes.append([b.x0 - src.window.x0, b.y0 - src.window.y0,
                          b.x1 - src.window.x0, b.y1 - src.window.y0])
        n = len(boxes)
        out = rt.buffer(8 * 4 * n)
        if n == 0:
            return []
        knl = rt.kernel("lens_flare.cl", "lens_flare_measure", fp64=self.level(ctx).fp64,
                        FULL=int(full), **ctx.luminance_defines)
        rt.launch(knl, (n,), src, src.pitch, rt.to_device(np.asarray(boxes, np.int32).ravel()), n,
                  p.threshold, out)
        m = rt.from_device(out, np.float32, 8 * n).reshape(n, 8).astype(np.float64)
        if full:
            return [flare.Light(src.window.x0 + r[4], src.window.y0 + r[5], tuple(r[:3]), r[7],
                                light_gain(p.gain, p.light_level, s.peak))
                    for s, r in zip(candidates, m) if r[3] > 0]
        return [(src.window.x0 + r[4], src.window.y0 + r[5], tuple(r[:3])) for r in m if r[3] > 0]

    def lens_refs(self, p):
        return (("lens", "prescription", p.lens),) if p.model == "physical" else ()

    # cheap questions ------------------------------------------------------------------
    def is_identity(self, p, ctx):
        if p.model == "physical":
            if p.gain == 0.0:
                return "gain is 0"
        elif p.intensity == 0.0 and p.halo_intensity == 0.0:
            return "intensity and halo_intensity are 0"
        elif not parse_ghosts(p.ghosts, p.ghost_count) and p.halo_intensity == 0.0:
            return "no ghosts and no halo"
        if not ctx.analysis.any_above(p.threshold):
            return "no pixel above threshold"
        return self.planned(p, ctx).identity

    def plan(self, p, ctx) -> FlarePlan:
        """Whether any light flares and, for the physical model, every visible ghost
        (:meth:`ghost_plan`): once per step, read by ``is_identity`` and ``render``."""
        if not self.candidate_sources(p, ctx):
            return FlarePlan("no light source in or near view",
                             NO_GHOSTS if p.model == "physical" else None)
        if p.model != "physical":
            return FlarePlan()
        ghosts = self.ghost_plan(ctx.runtime, p, ctx)
        if not len(ghosts[0]):
            return FlarePlan("every ghost is below the visible level (cull)", ghosts)
        return FlarePlan(None, ghosts)

    def region_of_definition(self, p, ctx):
        # ghosts land anywhere on the display (and beyond, but only the display is kept)
        return ctx.source.window.union(ctx.display_window)

    # the physical model -----------------------------------------------------------------
    def prescription(self, p, ctx):
        """(key, Prescription) of ``p.lens``: read by the pipeline once per process and name
        (YAML parsing costs more than a frame's flare), keyed on its content; ``coatings``
        "multi" tunes each surface's film to its own wavelength (:func:`multi_coated`)."""
        def build():
            d = ctx.read_lens(p.lens)
            if p.coatings == "multi":
                d = multi_coated(d)
            return (json.dumps(d, sort_keys=True, default=str),
                    optics.Prescription.from_dict(d, p.lens))

        return ctx.runtime.cache.get(("lens_flare.lens", p.lens, p.coatings), build,
                                     nbytes=4096)

    def ghost_table(self, ctx, key, lens, f_number: float, wavelengths):
        def build():
            return optics.ghosts(lens.at_f_number(f_number), wavelengths)

        t = ctx.runtime.cache.get(("lens_flare.ghosts", key, f_number, wavelengths), build,
                                  nbytes=65536)
        return t

    @staticmethod
    def edge_tables(ctx):
        def build():
            edge = flare.edge_table()
            return edge, flare.area_table(edge), edge.astype(np.float32).ravel()

        return ctx.runtime.cache.get(("lens_flare.edge", flare.EDGE_ROWS, flare.EDGE_SAMPLES),
                                     build, nbytes=flare.EDGE_ROWS * 512 * 8)

    def visible_level(self, p, ctx) -> float:
        """The radiance below which a ghost is not drawn: ``cull`` times the median tile
        luminance of the frame (the level the scene is seen at)."""
        lum = ctx.analysis.mean_lum
        median = float(np.median(lum)) if lum.size else 0.0
        return p.cull * max(median, 1e-9)

    def ghost_plan(self, rt, p, ctx):
        """The entries of every visible ghost: (entries, levels, table rows, lights)."""
        lvl = self.level(ctx)
        key, lens = self.prescription(p, ctx)
        cam = ctx.camera
        design = lens.f_number_paraxial()
        if cam.f_number < 0.99 * design:
            ctx.warnings.append(
                f"lens_flare: lens {p.lens!r} opens to f/{design:.2g}; the camera's "
                f"f/{cam.f_number:g} opens its stop beyond the design (other rims limit the "
                f"beam, as they would)")
        wl = flare_wavelengths(lvl.wavelengths)
        table = self.ghost_table(ctx, key, lens, cam.f_number, wl)
        lights = self.measure(rt, p, ctx, self.candidate_sources(p, ctx), full=True)
        blades = p.blades or cam.blades
        geometry = flare.Optics(centre_px=ctx.display_window.center,
                                px_per_mm=ctx.width_px / cam.sensor_width, blades=blades,
                                stop_index=lens.stop_index, gain=p.gain,
                                diagonal_px=ctx.diagonal_px)
        level = self.visible_level(p, ctx)
        keep = flare.cull(table, lights, geometry, level)
        sub = table.subset(keep)
        edge, areas, _ = self.edge_tables(ctx)
        entries, levels, rows = flare.plan_entries(
            sub, lights, geometry, flare_channel_weights(wl, ctx.rgb_to_xyz), edge, areas,
            level=level, max_level=lvl.max_level, level_scale=lvl.level_scale)
        return (*read_only(entries, levels, keep[rows]), tuple(lights))

    def render_physical(self, rt, p, ctx):
        entries, levels, _, lights = self.planned(p, ctx).ghosts   # the physical plan's
        blades = p.blades or ctx.camera.blades
        out = self.draw(rt, ctx, entries, levels, self.output_window(p, ctx), blades,
                        ctx.camera.blade_rotation + p.rotation)
        ctx.notes.append(f"lens_flare: {len(lights)} light source(s), {len(entries)} ghost(s) "
                         f"drawn ({p.lens})")
        bad = ctx.analysis.nonfinite_count
        if bad:
            ctx.notes.append(f"lens_flare: {bad} non-finite pixels set to 0")
        return out

    def draw(self, rt, ctx, entries, levels, out_win, blades: int, rotation_deg: float):
        """The source plus the ghosts ``entries`` (``clfx.fx.flare.plan_entries``) over
        ``out_win``: each resolution level from the coarsest, its tiles' constants and edge
        lists, the coarser level upsampled into it; level 0 composes onto the source."""
        src = ctx.source
        top = min(int(levels.max(initial=0)), self.level(ctx).max_level)
        tiles = flare.tile_plan(entries, levels, out_win.x0, out_win.y0, out_win.width,
                                out_win.height, PHYSICAL_TILE, top)
        normals = flare.aperture_normals(blades, rotation_deg)
        ent = rt.to_device(entries.astype(np.float32).ravel() if entries.size
                           else np.zeros(flare.ENTRY, np.float32))
        norm = rt.to_device(normals.astype(np.float32).ravel())
        edge = rt.to_device(self.edge_tables(ctx)[2])
        ox, oy = src.window.offset_in(out_win)
        coarse = None
        for t in reversed(tiles):
            final = t.factor == 1
            out = rt.image(out_win) if final else rt.image((t.height, t.width))
            knl = rt.kernel("lens_flare.cl", "lens_flare_ghosts", TILE=PHYSICAL_TILE,
                            BLADES=blades if blades >= 3 else 0, COMPOSE=int(final),
                            EDGE_SAMPLES=flare.EDGE_SAMPLES, EDGE_REACH=f"{flare.EDGE_REACH}f")
            c = coarse if coarse is not None else out
            rt.launch(knl, (out.pitch // 4, t.height), out, out.pitch, t.width, t.height,
                      out_win.x0 + 0.5 * t.factor, out_win.y0 + 0.5 * t.factor, t.factor,
                      t.tiles_x, rt.to_device(t.start), rt.to_device(t.items), ent,
                      rt.to_device(t.constant.ravel()), norm, edge, c, c.pitch, c.width, c.height,
                      coarse is not None, src, src.pitch, src.width, src.height, ox, oy)
            coarse = out
        return coarse

    # render ---------------------------------------------------------------------------
    def render(self, rt, p, ctx):
        if p.model == "physical":   # spectral: in the reference basis, linear Rec.709
            return in_reference_basis(rt, ctx,
                                               lambda c: self.render_physical(rt, p, c))
        src = ctx.source
        out_win = self.output_window(p, ctx)
        sources = self.measure(rt, p, ctx, self.candidate_sources(p, ctx))
        blades = p.blades or ctx.camera.blades
        normals = flare.aperture_normals(blades, ctx.camera.blade_rotation + p.rotation)
        normals = normals.astype(np.float32)
        entries = flare_entries(sources, p, ctx.display_window.center, ctx.diagonal_px,
                                blades, ctx.camera.blade_rotation + p.rotation)
        tiles_x, start, flat = tile_lists(entries, out_win)
        ent = entries.astype(np.float32).ravel() if entries.size else np.zeros(ENTRY, np.float32)
        out = rt.image(out_win)
        ox, oy = src.window.offset_in(out_win)
        knl = rt.kernel("lens_flare.cl", "lens_flare_render", TILE=TILE,
                        BLADES=blades if blades >= 3 else 0, **ctx.luminance_defines)
        rt.launch(knl, (out.pitch // 4, out.height), src, src.pitch, src.width, src.height, ox, oy,
                  out, out.pitch, out.width, out.height, out_win.x0, out_win.y0, tiles_x,
                  rt.to_device(start), rt.to_device(flat), rt.to_device(ent),
                  rt.to_device(normals.ravel()), p.roundness, p.rim)
        ctx.notes.append(f"lens_flare: {len(sources)} light source(s)")
        bad = ctx.analysis.nonfinite_count
        if bad:
            ctx.notes.append(f"lens_flare: {bad} non-finite pixels set to 0")
        return out
