"""Finding beauty, depth and velocity channels, and converting renderers' conventions to clfx's.

This module knows channel *names* and *conventions*; it never touches OpenImageIO (``clfx.io.read``
does the reading and calls the functions here with plain lists of channel names).

Internal conventions (see ``clfx.core.frame``)
-----------------------------------------
- depth: planar camera-space z in scene units, background (no hit) = +inf.
- velocity: forward displacement in pixels per frame (where the point will be one frame later
  minus where it is now), +x right, +y down (image rows).

Views (stereo)
--------------
Channel names are first split into a *view* and a view-less *base name*:

- single-part files with a ``multiView`` attribute: a dotted component equal to a view name is
  the view (``left.Z`` -> base ``Z``, view ``left``; ``forward.right.u`` -> ``forward.u``,
  ``right``).  Channels of the default layer without a view name (``R``, ``Z``) belong to the
  hero view, the first entry of ``multiView``; layered channels without a view name
  (``disparityL.x``) belong to no view.
- multipart files: a part's ``view`` attribute applies to all its channels.

The beauty's view is the *chosen view*.  Passes are taken from the chosen view or from channels
with no view; channels of other views are never used (probe lists them as ignored).

Beauty search order
-------------------
1. unlayered ``R, G, B`` (``A`` optional), first part first, chosen view preferred;
2. a layer named ``Combined``, ``rgba``, ``RGBA``, ``beauty`` or ``Beauty`` with ``R, G, B``
   (Blender ``ViewLayer.Combined.R``);
3. the first layer with ``R, G, B`` (parts in order, channels in file order);
4. grey: an unlayered ``Y`` (``A`` optional), or a part with a single channel that is not a
   depth channel (a file holding only ``Z`` has no beauty: it is refused, not read as grey).

Depth search order (first match wins; the mode is what ``depth_mode="auto"`` uses)
----------------------------------------------------------------------------------
======================  ============  =========================================================
name                    auto mode     whose convention
======================  ============  =========================================================
``Z``                   z             EXR/deep convention: Arnold, Fusion, Blender single-layer,
                                      OpenEXR Beachball samples
``depth.Z``             inverse       Nuke ScanlineRender: 1/z, far = 0
``Depth.Z``             z             Blender pass without a view-layer prefix
``<layer>.Depth.Z``     z             Blender Cycles/EEVEE multilayer (background 1e10)
``<layer>.Z``           z             any other layer's Z
``zDepth``              normalized    V-Ray (0..1 between ``depth_near`` and ``depth_far``)
``VRayZDepth``          normalized    V-Ray render element
``depth``               z             generic
======================  ============  =========================================================

Names are case-sensitive (``depth.Z`` is Nuke's 1/z, ``Depth.Z`` is Blender's planar z).  A rule
name ``N`` also matches ``N.Z``, ``N.R`` and ``N.Y`` for the single-channel names (V-Ray writes
render elements as ``VRayZDepth.R/G/B``).

"No hit" (background) in depth passes
-------------------------------------
clfx's background is +inf.  Real files mark "no hit" in other ways; `no_hit` decides, per
frame, from the converted depth (before ``depth_scale``) and the beauty's alpha:

- **huge values**: converted depths whose magnitude is at least ``far_threshold`` (default
  1e9: Blender writes 1e10, RenderMan 1e30, 3ds Max -1e30), -inf, and in a half-float channel
  the largest half (65504, a saturated depth) are no hit -> +inf.
- **zero**: planar z = 0 lies on the camera and is never a real hit.  With ``zero="auto"``
  zeros are no hit (-> +inf) when they cover at least `ZERO_FAR_SHARE` of the pass's pixels
  or when at least `ZERO_FAR_TRANSPARENT` of them are transparent in the beauty (alpha <=
  1/1024), as in the OpenEXR Beachball sequence (22 % of Z is 0, all of it with alpha 0);
  otherwise (a few opaque zeros) they stay 0, *invalid*, and effects treat them as in focus.
  ``zero="far"`` / ``"invalid"`` force either reading (``--depth-zero``).  No renderer is
  known to state its zero convention in the header, so no attribute is consulted.
- inverse depth (Nuke ``depth.Z``) already maps 0 to +inf; ``normalized`` depth is 0 at
  ``depth_near``, so zeros only arise there when ``depth_near`` is 0.

What was assumed is reported by ``clfx probe`` (``depth.no_hit``) and, by the reader, as one
stderr line per sequence.

Velocity search order (first match wins)
----------------------------------------
=======================  ==========  =====  =================================================
names (u, v)             direction   y-up   whose convention
=======================  ==========  =====  =================================================
``forward.u/v``          forward     yes    Nuke; OpenEXR Beachball samples (see below)
``motion.u/v``           forward     yes    Nuke ``motion`` layer
``<layer>.Vector.Z/W``   backward    yes    Blender: ZW = current - next (exact -forward)
``<layer>.Vector.X/Y``   backward    yes    Blender: XY = previous - current (used if no ZW)
``velocity.x/y``         forward     yes    generic (compositing convention assumed)
``vel.x/y``              forward     yes    generic (compositing convention assumed)
``motionvector.x/y``     forward     yes    Arnold (pixels over the shutter interval: if the
                                            shutter is not one frame, set ``velocity_scale``)
``VRayVelocity.x/y``     forward     yes    V-Ray (current -> next)
=======================  ==========  =====  =================================================

The generic layers (``velocity``, ``vel``, ``motionvector``, ``VRayVelocity``) accept the
component pairs ``x/y``, ``X/Y``, ``u/v`` and ``R/G`` (V-Ray render elements are RGB).
*Backward* vectors point from the current position to the previous one; clfx negates them,
which is exact for Blender's ZW and a constant-velocity approximation for XY.  *y-up* vectors
have their v negated (clfx is +y down).  Then ``velocity_scale`` multiplies both.

Beachball: its README says the content of its non-RGBAZ channels is arbitrary.  Measured on
frames 1-2, ``forward.u`` is positive and ``forward.v`` negative while the ball moves right and
down the image rows, so the signs agree with Nuke's forward, y-up convention; the magnitudes
(~42 px) are about 0.4x the ball's centroid motion between frames.  clfx reads them as Nuke
forward vectors and does not rescale; treat them as test data, not truth.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from clfx.core.colour import REC709_LUMINANCE

#: Converted depths at or above this are background (Blender writes 1e10).
DEPTH_FAR_AS_INF = 1e9
#: ``zero="auto"``: zeros on at least this share of a depth pass's pixels are no hit.
ZERO_FAR_SHARE = 0.05
#: ``zero="auto"``: zeros of which at least this share is transparent are no hit.
ZERO_FAR_TRANSPARENT = 0.9
#: Alpha at or below this is transparent (one half-float step above 0 at 1/1024).
TRANSPARENT_ALPHA = 1.0 / 1024
HALF_MAX = 65504.0

DEPTH_ZERO = ("auto", "far", "invalid")

DEPTH_MODES = ("auto", "z", "inverse", "distance", "normalized")
VELOCITY_DIRECTIONS = ("auto", "forward", "backward")

BEAUTY_LAYER_NAMES = ("Combined", "rgba", "RGBA", "beauty", "Beauty")


@dataclass(frozen=True)
class DepthRule:
    """One entry of the depth search order."""

    pattern: str      # human-readable pattern, ``<layer>`` = any non-empty dotted prefix
    mode: str         # how ``depth_mode="auto"`` interprets it
    source: str       # whose convention


@dataclass(frozen=True)
class VelocityRule:
    """One entry of the velocity search order (``pattern`` names the layer, ``pairs`` the
    accepted (u, v) component names)."""

    pattern: str
    pairs: tuple[tuple[str, str], ...]
    direction: str    # "forward" or "backward"
    y_up: bool
    source: str

    def label(self) -> str:
        u, v = self.pairs[0]
        return f"{self.pattern}.{u}/{v}"


DEPTH_RULES = (
    DepthRule("Z", "z", "EXR/deep convention (Arnold, Fusion, Blender single-layer): planar z"),
    DepthRule("depth.Z", "inverse", "Nuke ScanlineRender: 1/z, far = 0"),
    DepthRule("Depth.Z", "z", "Blender Depth pass: planar z"),
    DepthRule("<layer>.Depth.Z", "z", "Blender multilayer Depth pass: planar z, background 1e10"),
    DepthRule("<layer>.Z", "z", "layered Z: planar z"),
    DepthRule("zDepth", "normalized", "V-Ray zDepth: normalised 0..1 (set depth_near/depth_far)"),
    DepthRule("VRayZDepth", "normalized",
              "V-Ray VRayZDepth: normalised 0..1 (set depth_near/depth_far)"),
    DepthRule("depth", "z", "generic depth: planar z"),
)

_XY_PAIRS = (("x", "y"), ("X", "Y"), ("u", "v"), ("R", "G"))

VELOCITY_RULES = (
    VelocityRule("forward", (("u", "v"),), "forward", True, "Nuke forward vectors: pixels, y-up"),
    VelocityRule("motion", (("u", "v"),), "forward", True, "Nuke motion layer: pixels, y-up"),
    VelocityRule("<layer>.Vector", (("Z", "W"),), "backward", True,
                 "Blender Vector pass ZW = current - next: pixels, y-up"),
    VelocityRule("<layer>.Vector", (("X", "Y"),), "backward", True,
                 "Blender Vector pass XY = previous - current: pixels, y-up"),
    VelocityRule("velocity", _XY_PAIRS, "forward", True, "generic velocity: pixels, y-up assumed"),
    VelocityRule("vel", _XY_PAIRS, "forward", True, "generic velocity: pixels, y-up assumed"),
    VelocityRule("motionvector", _XY_PAIRS, "forward", True,
                 "Arnold motionvector: pixels over the shutter interval, y-up assumed"),
    VelocityRule("VRayVelocity", _XY_PAIRS, "forward", True,
                 "V-Ray velocity: current -> next, pixels, y-up assumed"),
)


def search_order() -> dict:
    """The documented search orders as JSON-able lists (printed by ``probe``)."""
    return {
        "beauty": ["R,G,B(,A) unlayered", "layer " + "|".join(BEAUTY_LAYER_NAMES) + " with R,G,B",
                   "first layer with R,G,B", "Y(,A) or a single non-depth channel (grey)"],
        "depth": [f"{r.pattern} ({r.mode})" for r in DEPTH_RULES],
        "velocity": [f"{r.label()} ({r.direction}, {'y-up' if r.y_up else 'y-down'})"
                     for r in VELOCITY_RULES],
    }


# --------------------------------------------------------------------------------------------
# Channel catalogue: every channel of every part, with its view and view-less base name.

@dataclass(frozen=True)
class Channel:
    """One channel of one part.

    ``name`` is the name in the file, ``base`` the name without its view component, ``view``
    the view it belongs to (``None``: no view), ``index`` its position in the part.
    """

    part: int
    index: int
    name: str
    base: str
    view: str | None


def split_view(name: str, views: tuple[str, ...]) -> tuple[str, str | None]:
    """Split a single-part multi-view channel name into (base, view).

    Parameters
    ----------
    name : str
        Channel name as stored, e.g. ``"left.Z"`` or ``"forward.right.u"``.
    views : tuple of str
        The ``multiView`` attribute; ``views[0]`` is the hero (default) view.

    Returns
    -------
    (str, str or None)
        ``("Z", "left")``, ``("forward.u", "right")``; unlayered names belong to the hero
        view; layered names without a view component belong to no view.
    """
    if not views:
        return name, None
    parts = name.split(".")
    for i, comp in enumerate(parts[:-1]):
        if comp in views:
            return ".".join(parts[:i] + parts[i + 1:]), comp
    return name, (views[0] if len(parts) == 1 else None)


def catalogue(parts: list[dict]) -> list[Channel]:
    """All channels of a file, parts in order.

    Parameters
    ----------
    parts : list of dict
        Per part: ``channels`` (names in file order), ``view`` (part ``view`` attribute or
        None) and ``views`` (single-part ``multiView`` tuple, may be empty).
    """
    out = []
    for p, part in enumerate(parts):
        views = tuple(part.get("views") or ())
        for i, name in enumerate(part["channels"]):
            if part.get("view"):
                out.append(Channel(p, i, name, name, part["view"]))
            else:
                base, view = split_view(name, views)
                out.append(Channel(p, i, name, base, view))
    return out


def hero_view(parts: list[dict]) -> str | None:
    """The default view: first ``multiView`` entry, else the first part's ``view``."""
    for part in parts:
        if part.get("views"):
            return part["views"][0]
    for part in parts:
        if part.get("view"):
            return part["view"]
    return None


# --------------------------------------------------------------------------------------------
# Beauty

@dataclass(frozen=True)
class BeautyChoice:
    """Channels of the beauty: ``rgb`` has 3 names (or 1 for grey), ``alpha`` may be None."""

    part: int
    rgb: tuple[str, ...]
    alpha: str | None
    view: str | None
    why: str

    @property
    def grey(self) -> bool:
        return len(self.rgb) == 1

    @property
    def channels(self) -> list[str]:
        return list(self.rgb) + ([self.alpha] if self.alpha else [])


def _layer_groups(chans: list[Channel]) -> dict:
    """{(part, layer, view): {component: channel name}} keeping first-seen order."""
    groups: dict = {}
    for c in chans:
        layer, _, comp = c.base.rpartition(".")
        groups.setdefault((c.part, layer, c.view), {}).setdefault(comp, c.name)
    return groups


def file_views(parts: list[dict]) -> tuple[str, ...]:
    """Every view a file names, hero first (``multiView`` order, then part ``view``s)."""
    out: list[str] = []
    for p in parts:
        for v in tuple(p.get("views") or ()) + ((p["view"],) if p.get("view") else ()):
            if v not in out:
                out.append(v)
    hero = hero_view(parts)
    if hero in out:
        out.remove(hero)
        out.insert(0, hero)
    return tuple(out)


def beauty_views(parts: list[dict]) -> tuple[str, ...]:
    """The views that have a beauty of their own, hero first (empty: not multi-view)."""
    return tuple(v for v in file_views(parts)
                 if (b := find_beauty(parts, view=v)) is not None and b.view == v)


def find_beauty(parts: list[dict], *, part: int | None = None,
                view: str | None = None) -> BeautyChoice | None:
    """Pick the beauty channels following the documented order (see module docstring).

    Parameters
    ----------
    parts : list of dict
        As for `catalogue`.
    part : int, optional
        Restrict the search to this part index.
    view : str, optional
        The beauty of this view (channels of other views are not considered); default: the
        hero view preferred.
    """
    chans = [c for c in catalogue(parts) if (part is None or c.part == part)
             and (view is None or c.view in (view, None))]
    hero = view or hero_view(parts)
    groups = _layer_groups(chans)

    def has_rgb(comps):
        return all(k in comps for k in ("R", "G", "B"))

    def pick(key, comps, why):
        p, layer, view = key
        rgb = tuple(comps[k] for k in ("R", "G", "B")) if has_rgb(comps) else (comps["Y"],)
        return BeautyChoice(p, rgb, comps.get("A"), view, why)

    unlayered = [(k, g) for k, g in groups.items() if k[1] == "" and has_rgb(g)]
    unlayered.sort(key=lambda kg: (kg[0][2] not in (hero, None), kg[0][0]))
    if unlayered:
        return pick(*unlayered[0], "unlayered R,G,B" + (",A" if "A" in unlayered[0][1] else ""))
    for key, g in groups.items():
        if key[1].rpartition(".")[2] in BEAUTY_LAYER_NAMES and has_rgb(g):
            return pick(key, g, f"layer {key[1]!r} (beauty layer name)")
    for key, g in groups.items():
        if key[1] and has_rgb(g):
            return pick(key, g, f"first layer with R,G,B: {key[1]!r}")
    for key, g in groups.items():
        if key[1] == "" and "Y" in g:
            return pick(key, g, "grey: Y channel")
    for p, info in enumerate(parts):
        if ((part is None or p == part) and len(info["channels"]) == 1
                and any(c.part == p for c in chans)):
            name = info["channels"][0]
            if depth_rule_for(name, tuple(info.get("views") or ())):
                continue       # a lone Z is a depth pass, not a grey picture
            view = next(c.view for c in chans if c.part == p)
            return BeautyChoice(p, (name,), None, view, f"grey: the only channel {name!r}")
    return None


# --------------------------------------------------------------------------------------------
# Depth and velocity

@dataclass(frozen=True)
class PassChoice:
    """A found pass: ``channels`` (1 for depth, 2 for velocity) in ``part``; conventions."""

    part: int
    channels: tuple[str, ...]
    rule: str
    why: str
    mode: str | None = None          # depth
    direction: str | None = None     # velocity
    y_up: bool | None = None         # velocity


def _pattern_regex(pattern: str) -> str:
    return re.escape(pattern).replace(re.escape("<layer>"), r".+")


def _depth_names(rule: DepthRule) -> list[str]:
    rx = _pattern_regex(rule.pattern)
    if "." in rule.pattern:
        return [rx]
    return [rx] + [rx + re.escape("." + c) for c in ("Z", "R", "Y")]


def _usable(chans: list[Channel], view: str | None) -> list[Channel]:
    """Channels of the chosen view first, then channels with no view; other views dropped."""
    same = [c for c in chans if c.view is not None and c.view == view]
    none = [c for c in chans if c.view is None]
    return same + none


def other_view_channels(parts: list[dict], view: str | None) -> list[str]:
    """Channels that belong to a view other than ``view`` (ignored for passes), as
    ``"name"`` (single part) or ``"name (part i, view v)"`` (multipart)."""
    multi = len(parts) > 1
    return [f"{c.name} (part {c.part}, view {c.view})" if multi else c.name
            for c in catalogue(parts) if c.view is not None and c.view != view]


def find_depth(parts: list[dict], view: str | None) -> PassChoice | None:
    """First depth channel in the documented order, from ``view`` or no view."""
    chans = _usable(catalogue(parts), view)
    for rule in DEPTH_RULES:
        for rx in _depth_names(rule):
            for c in chans:
                if re.fullmatch(rx, c.base):
                    return PassChoice(c.part, (c.name,), rule.pattern, rule.source,
                                      mode=rule.mode)
    return None


def find_velocity(parts: list[dict], view: str | None) -> PassChoice | None:
    """First velocity channel pair in the documented order, from ``view`` or no view."""
    chans = _usable(catalogue(parts), view)
    for rule in VELOCITY_RULES:
        rx = _pattern_regex(rule.pattern)
        for u, v in rule.pairs:
            for c in chans:
                m = re.fullmatch(f"({rx})" + re.escape("." + u), c.base)
                if not m:
                    continue
                want = m.group(1) + "." + v
                mate = next((d for d in chans if d.part == c.part and d.view == c.view
                             and d.base == want), None)
                if mate is not None:
                    return PassChoice(c.part, (c.name, mate.name), f"{rule.pattern}.{u}/{v}",
                                      rule.source, direction=rule.direction, y_up=rule.y_up)
    return None


def explicit_choice(parts: list[dict], names: tuple[str, ...], view: str | None,
                    prefer_part: int | None) -> int | None:
    """Part index holding all ``names`` exactly (preferring ``prefer_part``, then the chosen
    view or no view, then file order), or None."""
    order = list(range(len(parts)))
    if prefer_part is not None and prefer_part in order:
        order.remove(prefer_part)
        order.insert(0, prefer_part)
    chans = catalogue(parts)

    def rank(p):
        views = {c.view for c in chans if c.part == p and c.name in names}
        return 0 if views <= {view, None} else 1

    candidates = [p for p in order if all(n in parts[p]["channels"] for n in names)]
    candidates.sort(key=rank)     # stable: keeps prefer_part / file order within a rank
    return candidates[0] if candidates else None


def depth_rule_for(name: str, views: tuple[str, ...] = ()) -> DepthRule | None:
    """The depth rule an explicitly named channel matches (for its auto mode), if any."""
    base, _ = split_view(name, views)
    for rule in DEPTH_RULES:
        if any(re.fullmatch(rx, base) for rx in _depth_names(rule)):
            return rule
    return None


def velocity_rule_for(u_name: str, views: tuple[str, ...] = ()) -> VelocityRule | None:
    """The velocity rule an explicitly named u channel matches, if any."""
    base, _ = split_view(u_name, views)
    for rule in VELOCITY_RULES:
        rx = _pattern_regex(rule.pattern)
        if any(re.fullmatch(f"{rx}" + re.escape("." + u), base) for u, _ in rule.pairs):
            return rule
    return None


# --------------------------------------------------------------------------------------------
# Conversions to the internal conventions (NumPy, float32 in and out)

def depth_to_planar(raw: np.ndarray, mode: str, *, scale: float = 1.0, near: float = 0.0,
                    far: float = 1.0, focal_length_px: float | None = None,
                    pixel_centres: tuple[np.ndarray, np.ndarray] | None = None,
                    pixel_aspect: float = 1.0,
                    far_threshold: float = DEPTH_FAR_AS_INF) -> np.ndarray:
    """Convert a stored depth channel to planar camera z in scene units, background +inf.

    Parameters
    ----------
    raw : ndarray, float32 (h, w)
        Values as stored.
    mode : {"z", "inverse", "distance", "normalized"}
        ``z``: planar z as is.  ``inverse``: stored 1/z (Nuke), 0 -> +inf.  ``distance``:
        radial distance from the camera centre, converted to planar z with
        ``z = d * f / sqrt(f**2 + dx**2 + dy**2)`` where ``dx, dy`` are the pixel centre's
        offsets from the display-window centre in pixels (``dx`` multiplied by
        ``pixel_aspect`` so that ``f`` is in pixel heights).  ``normalized``:
        ``z = near + v * (far - near)``.
    scale : float
        Multiplies the converted depth (unit conversion, e.g. cm -> m = 0.01).
    near, far : float
        Scene-unit distances of 0 and 1 for ``normalized``.
    focal_length_px : float, optional
        Focal length in pixels, required for ``distance``.
    pixel_centres : (ndarray, ndarray), optional
        ``(dx, dy)`` broadcastable to ``raw``: pixel-centre offsets from the optical centre in
        pixels; required for ``distance``.
    pixel_aspect : float
        Pixel width / height.
    far_threshold : float
        Converted values at or above this (before ``scale``) become +inf; ``inf`` keeps them.
        (`read_frame` passes ``inf`` and handles every sentinel with `no_hit`.)

    Returns
    -------
    ndarray, float32 (h, w)
        Planar z.  NaN, 0 and negatives pass through (effects sanitise them).
    """
    raw = np.asarray(raw, np.float32)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if mode == "z":
            z = raw.copy()
        elif mode == "inverse":
            z = np.where(raw == 0, np.float32(np.inf), np.float32(1.0) / raw)
        elif mode == "normalized":
            z = np.float32(near) + raw * np.float32(far - near)
        elif mode == "distance":
            if not focal_length_px or focal_length_px <= 0:
                raise ValueError("depth_mode='distance' needs focal_length_px > 0")
            if pixel_centres is None:
                raise ValueError("depth_mode='distance' needs pixel centres")
            dx, dy = pixel_centres
            f = np.float64(focal_length_px)
            cos = f / np.sqrt(f * f + (dx * pixel_aspect) ** 2 + dy ** 2)
            z = (raw * cos).astype(np.float32)
        else:
            raise ValueError(f"unknown depth mode {mode!r}; expected one of {DEPTH_MODES[1:]}")
        if math.isfinite(far_threshold):
            z = np.where(z >= far_threshold, np.float32(np.inf), z)
        if scale != 1.0:
            z = z * np.float32(scale)
    return z.astype(np.float32, copy=False)


def velocity_to_forward(u: np.ndarray, v: np.ndarray, *, direction: str, y_up: bool,
                        scale: float = 1.0) -> np.ndarray:
    """Convert stored (u, v) vectors to forward pixels per frame, +y down.

    Parameters
    ----------
    u, v : ndarray, float32 (h, w)
        Stored components in pixels.
    direction : {"forward", "backward"}
        ``backward`` vectors (pointing to the previous position, or Blender's current - next)
        are negated.
    y_up : bool
        True if positive v points up the image (Nuke, Blender); v is then negated.
    scale : float
        Multiplies both components (e.g. shutter-interval vectors to per-frame).

    Returns
    -------
    ndarray, float32 (h, w, 2)
    """
    sign_u = -1.0 if direction == "backward" else 1.0
    sign_v = sign_u * (-1.0 if y_up else 1.0)
    out = np.empty(np.shape(u) + (2,), np.float32)
    out[..., 0] = np.asarray(u, np.float32) * np.float32(sign_u * scale)
    out[..., 1] = np.asarray(v, np.float32) * np.float32(sign_v * scale)
    return out


# --------------------------------------------------------------------------------------------
# "No hit" sentinels in depth passes

@dataclass(frozen=True)
class NoHit:
    """How a depth pass marks "no hit", decided by `no_hit` (see the module docstring).

    ``zero``: ``"far"`` (zeros become +inf), ``"invalid"`` (zeros stay 0) or None (no zeros);
    ``zero_share``: zeros / pixels of the pass; ``zero_transparent``: share of the zeros
    where the beauty is transparent (None without alpha); ``zero_why``: why ``zero`` was
    chosen.  ``huge``: pixels taken as no hit because of their magnitude (or -inf, or half
    max); ``far_threshold``: the magnitude used.
    """

    zero: str | None
    zero_share: float
    zero_transparent: float | None
    zero_why: str
    huge: int
    far_threshold: float
    half_max: bool = False

    def apply(self, z: np.ndarray, *, scale: float = 1.0) -> np.ndarray:
        """``z`` with every no-hit pixel at +inf, then multiplied by ``scale``."""
        z = np.asarray(z, np.float32)
        with np.errstate(invalid="ignore", over="ignore"):
            far = _huge(z, self.far_threshold, self.half_max)
            if self.zero == "far":
                far |= z == 0
            z = np.where(far, np.float32(np.inf), z)
            if scale != 1.0:
                z = z * np.float32(scale)
        return z.astype(np.float32, copy=False)

    @property
    def assumed(self) -> list[str]:
        """Short keys of what was assumed: ``"zero-far"``, ``"huge"`` (for once-per-sequence
        messages)."""
        return (["zero-far"] if self.zero == "far" else []) + (["huge"] if self.huge else [])

    def describe(self) -> str:
        """One phrase: what the pass's sentinels were read as."""
        parts = []
        if self.zero == "far":
            parts.append(f"0 on {self.zero_share:.1%} of the pixels ({self.zero_why}) read "
                         "as no hit, infinitely far (--depth-zero invalid keeps 0 as invalid)")
        elif self.zero == "invalid":
            parts.append(f"0 on {self.zero_share:.1%} of the pixels ({self.zero_why}) kept "
                         "as invalid depth, treated as in focus (--depth-zero far reads it as "
                         "no hit)")
        if self.huge:
            what = "65504 (half-float maximum) or " if self.half_max else ""
            parts.append(f"{self.huge} pixel(s) at {what}a magnitude >= {self.far_threshold:g} "
                         "read as no hit, infinitely far (--depth-far-threshold to change)")
        return "; ".join(parts) or "no 0 or huge sentinel values; +inf is no hit"

    def as_dict(self) -> dict:
        return {"zero": self.zero, "zero_share": round(self.zero_share, 6),
                "zero_transparent": (None if self.zero_transparent is None
                                     else round(self.zero_transparent, 6)),
                "huge": self.huge, "far_threshold": self.far_threshold,
                "assumed": self.describe()}


def _huge(z: np.ndarray, threshold: float, half_max: bool) -> np.ndarray:
    far = np.isinf(z) | (np.abs(z) >= np.float32(min(threshold, np.finfo(np.float32).max)))
    if half_max:
        far |= z == np.float32(HALF_MAX)
    return far


def no_hit(z: np.ndarray, alpha: np.ndarray | None = None, *, zero: str = "auto",
           far_threshold: float = DEPTH_FAR_AS_INF, half: bool = False) -> NoHit:
    """Decide how a depth pass marks "no hit" (see the module docstring).

    Parameters
    ----------
    z : ndarray, float32 (h, w)
        Converted planar depth, before ``depth_scale`` and before any sentinel handling.
    alpha : ndarray, float32 (h, w), optional
        The beauty's alpha over the same pixels (outside the beauty: 0).
    zero : {"auto", "far", "invalid"}
        How exact zeros are read; ``auto`` decides from their share and from alpha.
    far_threshold : float
        Magnitudes at or above this are no hit (``inf`` turns it off; +-inf always are).
    half : bool
        The stored channel is half float: its maximum, 65504, is no hit too.

    Returns
    -------
    NoHit
        Apply it with ``NoHit.apply(z, scale=...)``.
    """
    if zero not in DEPTH_ZERO:
        raise ValueError(f"depth_zero {zero!r} is not one of {DEPTH_ZERO}")
    z = np.asarray(z, np.float32)
    zeros = z == 0
    n_zero = int(np.count_nonzero(zeros))
    share = n_zero / max(z.size, 1)
    transparent = None
    if alpha is not None and n_zero:
        transparent = float(np.count_nonzero(np.asarray(alpha)[zeros] <= TRANSPARENT_ALPHA)) / n_zero
    with np.errstate(invalid="ignore"):
        huge = int(np.count_nonzero(_huge(z, far_threshold, half) & ~np.isposinf(z)))
    if not n_zero:
        mode, why = None, ""
    elif zero != "auto":
        mode, why = zero, f"--depth-zero {zero}"
    elif transparent is not None and transparent >= ZERO_FAR_TRANSPARENT:
        mode, why = "far", f"alpha 0 on {transparent:.0%} of them"
    elif share >= ZERO_FAR_SHARE:
        mode, why = "far", f"at least {ZERO_FAR_SHARE:.0%} of the pass"
    else:
        mode, why = "invalid", (f"under {ZERO_FAR_SHARE:.0%} of the pass" +
                                ("" if transparent is None else
                                 f", alpha 0 on only {transparent:.0%} of them"))
    return NoHit(mode, share, transparent, why, huge, float(far_threshold), half)


# --------------------------------------------------------------------------------------------
# Channels out = channels in

def beauty_out(rgba: np.ndarray, count: int) -> np.ndarray:
    """The rendered ``rgba`` (h, w, 4) as the ``count`` beauty channels its input had, so an
    RGB input gives RGB and a grey one grey: 4 R,G,B,A; 3 R,G,B (alpha dropped: the
    premultiplied colour over black); 2 grey and alpha; 1 grey.  Grey is the BT.709
    luminance of the rendered RGB, exactly R where R = G = B (a grey picture through
    colour-neutral effects comes back bit for bit).

    Examples
    --------
    >>> beauty_out(np.full((1, 1, 4), 0.5, np.float32), 1).shape
    (1, 1, 1)
    """
    if count >= 4:
        return rgba
    if count == 3:
        return rgba[..., :3]

    r, g, b = rgba[..., 0], rgba[..., 1], rgba[..., 2]
    lum = (r * np.float32(REC709_LUMINANCE[0]) + g * np.float32(REC709_LUMINANCE[1])
           + b * np.float32(REC709_LUMINANCE[2]))
    grey = np.where((r == g) & (g == b), r, lum).astype(rgba.dtype)[..., None]
    return grey if count == 1 else np.concatenate([grey, rgba[..., 3:4]], axis=-1)


def beauty_out_names(count: int) -> tuple[str, ...]:
    """Channel names of `beauty_out`'s ``count`` channels in a file written afresh."""
    return {4: ("R", "G", "B", "A"), 3: ("R", "G", "B"), 2: ("Y", "A"), 1: ("Y",)}[count]
