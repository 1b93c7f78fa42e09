"""`clfx gallery`: every effect and every built-in look on a few test images, one labelled
before/after contact sheet per image, so anyone can judge the looks at a glance.

Images: the built-in demo scene (frame 1, with its depth and velocity passes), a synthetic
sunny day (:func:`sun_scene`: the light flare and corona are seen with) and, where
the shared OpenEXR test images are found (``CLFX_SHARED_DATA``, else ``shared/data`` next to
the repository or one folder further up), ``ScanLines/CandleGlass.exr`` and
``ScanLines/Desk.exr``; a missing image is skipped with one line on stderr.  Each input is
area-downscaled to ``width`` pixels (640 by default: the whole gallery takes a few minutes on
a CPU device); sizes are fractions of the frame diagonal, so the effects look as they would
at full resolution.

Calibration: every tile is exposed as the footage would be seen, not graded to show off its
defect: one exposure per image, taken from the *input* (its log-average luminance to middle
grey, :func:`exposure_for`), the same for every tile, through the same plain per-channel
Reinhard curve and the sRGB encoding; nothing is boosted, and each effect and look runs as
shipped (an effect that needs a choice to do anything, ``lens``, gets the real-lens look's
lens: `EFFECT_SETTINGS`).

Every effect runs alone at its default parameters (``clfx apply EFFECT``; one whose defaults
change nothing, camera_blur and distortion, at the `DEMO_VALUES` its label and caption
name), options that are off by default on their own (`VARIANTS`: cat-eye, anamorphic and
chromatic bokeh, a pulled focus breathing), every built-in look as shipped; an effect or
look step that needs a depth or velocity pass the image lacks is skipped, and the tile says
so.  Written to OUTDIR:

- ``<image>/sheet.png``: the input (``before``) then every effect and look (``after``), each
  tile labelled and captioned with one sentence (`CAPTIONS`: what the defect is and where
  to look), tone-mapped with one exposure per image (so tiles compare);
- ``<image>/<kind>-<name>.png``: each tile at full gallery resolution (`tile_filename`:
  letters, digits, ``.``, ``_`` and ``-`` only, so ``dof:cat-eye`` is
  ``effect-dof-cat-eye.png``: SMB and Windows shares refuse ``:``);
- ``index.json``: what was rendered (each tile's file and settings), skipped and how long it
  took.

Every file is written atomically through `clfx.io.write` (never through a symbolic link);
without ``overwrite`` (``--overwrite``) a file of an earlier gallery is an error before
anything renders.
"""
from __future__ import annotations

import json
import math
import os
import re
import sys
import textwrap
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from clfx.bench.scene import demo_scene, render_sharp
from clfx.core.errors import ClfxError, ParamError
from clfx.core.frame import Frame, crop_to
from clfx.demo import tile_sheet, tonemap_preview as tonemap
from clfx.io.read import read_frame
from clfx.io.write import OutputExistsError, output_folder, write_frame, write_text
from clfx.pipeline.look import render_frame
from clfx.pipeline.presets import available_looks, load_look, single_effect_look
from clfx.plugins import discover

GALLERY_WIDTH = 640
SCANLINES = ("CandleGlass", "Desk")
KEY_VALUE = 0.18
"""Tone mapping: the input's log-average luminance is exposed to this middle grey."""


# -- a tiny bitmap font for the labels (5 x 7, upper case) ---------------------------------
_GLYPHS = {
    "A": "0E 11 11 1F 11 11 11", "B": "1E 11 11 1E 11 11 1E", "C": "0E 11 10 10 10 11 0E",
    "D": "1E 11 11 11 11 11 1E", "E": "1F 10 10 1E 10 10 1F", "F": "1F 10 10 1E 10 10 10",
    "G": "0E 11 10 17 11 11 0F", "H": "11 11 11 1F 11 11 11", "I": "0E 04 04 04 04 04 0E",
    "J": "07 02 02 02 02 12 0C", "K": "11 12 14 18 14 12 11", "L": "10 10 10 10 10 10 1F",
    "M": "11 1B 15 15 11 11 11", "N": "11 11 19 15 13 11 11", "O": "0E 11 11 11 11 11 0E",
    "P": "1E 11 11 1E 10 10 10", "Q": "0E 11 11 11 15 12 0D", "R": "1E 11 11 1E 14 12 11",
    "S": "0F 10 10 0E 01 01 1E", "T": "1F 04 04 04 04 04 04", "U": "11 11 11 11 11 11 0E",
    "V": "11 11 11 11 11 0A 04", "W": "11 11 11 15 15 15 0A", "X": "11 11 0A 04 0A 11 11",
    "Y": "11 11 0A 04 04 04 04", "Z": "1F 01 02 04 08 10 1F", "0": "0E 11 13 15 19 11 0E",
    "1": "04 0C 04 04 04 04 0E", "2": "0E 11 01 02 04 08 1F", "3": "1F 02 04 02 01 11 0E",
    "4": "02 06 0A 12 1F 02 02", "5": "1F 10 1E 01 01 11 0E", "6": "06 08 10 1E 11 11 0E",
    "7": "1F 01 02 04 08 08 08", "8": "0E 11 11 0E 11 11 0E", "9": "0E 11 11 0F 01 02 0C",
    "-": "00 00 00 1F 00 00 00", "_": "00 00 00 00 00 00 1F", ":": "00 0C 0C 00 0C 0C 00",
    ".": "00 00 00 00 00 0C 0C", "(": "02 04 08 08 08 04 02", ")": "08 04 02 02 02 04 08",
    "/": "01 01 02 04 08 10 10", "=": "00 00 1F 00 1F 00 00", ",": "00 00 00 00 0C 04 08",
    " ": "00 00 00 00 00 00 00", "'": "04 04 08 00 00 00 00", "%": "18 19 02 04 08 13 03",
    "+": "00 04 04 1F 04 04 00", ";": "00 0C 0C 00 0C 04 08", "^": "04 0A 11 00 00 00 00",
}


def _glyph(ch: str) -> np.ndarray:
    rows = _GLYPHS.get(ch.upper(), _GLYPHS["-"]).split()
    return np.array([[(int(r, 16) >> (4 - b)) & 1 for b in range(5)] for r in rows], bool)


def text_mask(text: str, scale: int = 2) -> np.ndarray:
    """A boolean mask of ``text`` in the 5 x 7 font (1 px spacing), each pixel ``scale`` wide."""
    if not text:
        return np.zeros((7 * scale, 1), bool)
    cols = [np.pad(_glyph(ch), ((0, 0), (0, 1))) for ch in text]
    mask = np.concatenate(cols, axis=1)
    return np.kron(mask, np.ones((scale, scale), bool))


def _text_band(out: np.ndarray, lines: list[str], top: int, scale: int) -> np.ndarray:
    """Draw ``lines`` in white on a darkened band of ``out`` from row ``top`` (in place; text
    wider than the tile is cut, lines below its bottom are left out)."""
    line_h = 9 * scale
    out[top:top + line_h * len(lines) + scale] *= 0.25   # darken behind the text, keep the image
    for k, text in enumerate(lines):
        mask = text_mask(text, scale)
        w = min(mask.shape[1], out.shape[1] - 2 * scale)
        y = top + scale + k * line_h
        if w > 0 and y + mask.shape[0] <= out.shape[0]:
            out[y:y + mask.shape[0], scale:scale + w][mask[:, :w]] = 1.0
    return out


def label(tile: np.ndarray, lines, *, scale: int = 2) -> np.ndarray:
    """``tile`` (display-linear RGB) with ``lines`` of text in white on a darkened band at the
    top (text wider than the tile is cut)."""
    lines = [lines] if isinstance(lines, str) else list(lines)
    return _text_band(tile.copy(), lines, 0, scale)


def wrap(text: str, chars: int) -> list[str]:
    """``text`` in lines of at most ``chars`` characters, broken at spaces."""
    return textwrap.wrap(text, chars, break_long_words=False, break_on_hyphens=False)


def caption(tile: np.ndarray, text: str, *, scale: int = 1, max_lines: int = 4) -> np.ndarray:
    """``tile`` with ``text`` wrapped in white on a darkened band at the bottom (at most
    ``max_lines`` lines; the image above it untouched)."""
    out = tile.copy()
    chars = max(1, (out.shape[1] - 2 * scale) // (6 * scale))
    lines = wrap(text, chars)[:max_lines]
    if not lines:
        return out
    top = max(0, out.shape[0] - 9 * scale * len(lines) - scale)
    return _text_band(out, lines, top, scale)


def thumbnail(img: np.ndarray, width: int) -> np.ndarray:
    """Box-downscale ``img`` by the integer factor that brings it to at most ``width``."""
    step = max(1, int(math.ceil(img.shape[1] / width)))
    if step == 1:
        return img
    h, w = img.shape[0] // step * step, img.shape[1] // step * step
    return img[:h, :w].reshape(h // step, step, w // step, step, -1).mean(axis=(1, 3))


# -- images ---------------------------------------------------------------------------------
def shared_data_dirs() -> list[Path]:
    """Where the shared test data may be: ``CLFX_SHARED_DATA``, then ``shared/data`` beside
    the repository, then one folder further up (a git worktree under ``wt/``)."""
    repo = Path(__file__).resolve().parents[1]
    env = os.environ.get("CLFX_SHARED_DATA")
    dirs = [Path(env)] if env else []
    return dirs + [repo.parent / "shared" / "data", repo.parent.parent / "shared" / "data"]


def find_scanline_image(name: str) -> Path | None:
    for d in shared_data_dirs():
        p = d / "openexr-images" / "ScanLines" / f"{name}.exr"
        if p.is_file():
            return p
    return None


def area_resize(img: np.ndarray, width: int, height: int) -> np.ndarray:
    """Area-average resampling of an (h, w, c) array to (height, width, c): each output
    pixel is the mean of the input area it covers, so light keeps its energy density."""
    def weights(n_in, n_out):
        edges = np.linspace(0.0, n_in, n_out + 1)
        lo, hi = edges[:-1, None], edges[1:, None]
        x = np.arange(n_in)[None, :]
        cover = np.clip(np.minimum(hi, x + 1) - np.maximum(lo, x), 0.0, None)
        return cover / cover.sum(axis=1, keepdims=True)

    a = np.nan_to_num(np.asarray(img, np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    wy, wx = weights(a.shape[0], height), weights(a.shape[1], width)
    out = np.einsum("yi,ijc->yjc", wy, a)
    return np.einsum("xj,yjc->yxc", wx, out).astype(np.float32)


def sun_scene(width: int, height: int) -> Frame:
    """A sunny day: a blue sky over dark ground and a post, and the sun (a limb-darkened disc
    of radius 0.8 % of the width, 1e5 at its centre, diffuse white being 1; the size of the
    Sun through a 55 mm lens on full frame) high on the right: the light that lens flare,
    corona and spikes are seen with."""
    ys, xs = np.mgrid[0:height, 0:width] + 0.5
    v = ys / height
    rgba = np.ones((height, width, 4), np.float32)
    sky = np.array([0.35, 0.55, 1.1]) + (np.array([0.9, 1.0, 1.15]) - [0.35, 0.55, 1.1]) * \
        (v / 0.62)[..., None] ** 2
    ground = np.array([0.12, 0.1, 0.06]) * (1.0 + 0.3 * np.sin(xs / width * 40.0) *
                                             np.sin(ys / height * 25.0))[..., None]
    rgba[..., :3] = np.where((v < 0.62)[..., None], sky, ground)
    post = (np.abs(xs - 0.3 * width) < 0.012 * width) & (v > 0.25)
    rgba[post, :3] = 0.05
    r = 0.008 * width
    sun = np.hypot(xs - 0.78 * width, ys - 0.3 * height)
    # limb-darkened (I = 1 - 0.6 (1 - mu), the Sun's in the visible): brightest at its centre
    mu = np.sqrt(np.clip(1.0 - (sun / r) ** 2, 0.0, 1.0))
    rgba[..., :3] += (1e5 * np.clip(r + 0.5 - sun, 0.0, 1.0) * (1.0 - 0.6 * (1.0 - mu)))[..., None]
    return Frame.from_array(rgba.astype(np.float32))


def gallery_image_names() -> list[str]:
    """The names of the gallery's images (`gallery_inputs`'s, in order), without reading
    them: the built-in two and the shared test images found."""
    return ["demo", "sun"] + [n for n in SCANLINES if find_scanline_image(n) is not None]


def gallery_inputs(width: int, log=print) -> list[tuple[str, Frame]]:
    """(name, frame) of every gallery image found, downscaled to ``width`` pixels."""
    height = int(round(width * 9 / 16))
    demo = render_sharp(demo_scene(1, width, height))
    demo.source = "demo scene frame 1"
    sun = sun_scene(width, height)
    sun.source = "a synthetic sunny day (clfx.gallery.sun_scene)"
    out = [("demo", demo), ("sun", sun)]
    for name in SCANLINES:
        path = find_scanline_image(name)
        if path is None:
            log(f"clfx gallery: {name}.exr not found (looked in "
                f"{', '.join(str(d / 'openexr-images/ScanLines') for d in shared_data_dirs())}); "
                f"skipped")
            continue

        frame = read_frame(path)
        rgba = crop_to(frame.rgba, frame.data_window, frame.display_window)
        h, w = rgba.shape[:2]
        small = area_resize(rgba, width, max(1, int(round(h * width / w)))) if w > width else rgba
        f = Frame.from_array(small)
        f.source = str(path)
        out.append((name, f))
    return out


# -- rendering ------------------------------------------------------------------------------
def exposure_for(rgba: np.ndarray) -> float:
    """One exposure per image: its log-average luminance mapped to middle grey."""
    rgb = np.nan_to_num(rgba[..., :3].astype(np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    lum = np.maximum(rgb @ np.array([0.2126, 0.7152, 0.0722]), 0.0)
    key = math.exp(float(np.mean(np.log(lum + 1e-4))))
    return float(np.clip(KEY_VALUE / max(key, 1e-6), 1e-3, 1e3))


EFFECT_SETTINGS = {
    # effects that do nothing until a setting is chosen: the gallery chooses one
    "lens": ["maker=Canon", "model=Canon EF 24-70mm f/2.8L II USM", "fit=fill",
             "camera.focal_length=24", "camera.f_number=2.8"],
}
"""Settings the gallery gives an effect that needs one to run at all (``lens`` needs a lens
from lensfun: the real-lens look's)."""

DEMO_VALUES = {
    # effects whose defaults are 0 (no change): the tile shows them at these values, said on
    # its label and caption
    "camera_blur": ["length=0.01", "roll=0.3"],     # short enough for a thumbnail's label
    "distortion": ["k1=-0.08"],
    "keystone": ["tilt=12"],
}
"""Demonstration values of effects that change nothing at their defaults: their tiles would
be the input itself under a caption promising the effect."""

CAPTIONS = {
    "before": "The input, exposed as every tile of this sheet: log-average to middle grey, "
              "no grade.",
    # effects at their defaults
    "bleed": "Sensor crosstalk: look at the edges of the brightest lights, a pixel or two of "
             "soft spill.",
    "breathing": "Focus breathing, still focus: nothing changes (the frame scales only while "
                 "the focus moves).",
    "camera_blur": "Camera shake (length=0.01 roll=0.3; default 0): every edge smeared the "
                   "same way, the lights drawn into short trails.",
    "chromatic_aberration": "Lateral colour: red and blue fringes on edges towards the "
                            "corners, none at the centre.",
    "corona": "Diffraction corona: rainbow rings around the strongest lights only.",
    "defocus": "Uniform defocus: the whole frame evenly soft, lights into small discs.",
    "distortion": "Barrel distortion (k1=-0.08; default 0): straight lines near the edges "
                  "bow outwards.",
    "dof": "Depth of field from the depth pass: the focus plane sharp, near and far soft, "
           "lights into aperture-shaped bokeh.",
    "glare": "Veiling glare: a faint wide glow around the brightest lights, lifting the dark "
             "areas next to them.",
    "grain": "Film grain: fine clumpy texture, most visible in the midtones and flat areas.",
    "halation": "Halation: a thin red-orange glow hugging bright edges and lights.",
    "keystone": "Keystone (tilt=12; default 0): the camera tilted up, verticals converge "
                "towards the top, the centre where it was.",
    "lens": "A real lens (Canon 24-70 at 24 mm, lensfun): barrel distortion, colour fringes "
            "and darker corners.",
    "lens_flare": "Lens flare: coloured aperture-shaped ghosts on the line through each "
                  "strong light and the centre.",
    "motion_blur": "Object motion blur from the velocity pass: movers smeared along their "
                   "paths, the background sharp.",
    "rolling_shutter": "Rolling shutter: moving objects and verticals lean, rows read one "
                       "after another.",
    "shake": "Handheld shake: every edge smeared a few pixels the same wandering way, a "
             "little more in the corners that the roll turns.",
    "sensor_noise": "Sensor noise: colour speckle and blotches in the shadows, little in the "
                    "highlights.",
    "soft_focus": "Diffusion filter: bright areas glow softly into their surroundings.",
    "streaks": "Star-filter streaks: four thin rays from each light, fading with distance.",
    "vignette": "Natural falloff: corners a little darker than the centre.",
    # option variants
    "dof:cat-eye": "Optical vignetting: bokeh towards the corners cut into cat's eyes, round "
                   "at the centre.",
    "dof:anamorphic-2x": "Anamorphic bokeh: tall ovals, squeezed twice as narrow as high.",
    "dof:axial-ca": "Axial colour: green rims on bokeh behind the focus, magenta ones in "
                    "front.",
    "breathing:pull-focus": "Focus pulled from 20 m to 0.5 m: the frame grows by 7 %, edges "
                            "move outwards.",
    # looks
    "anamorphic-night": "Anamorphic at night: long thin blue streaks across the lights, oval "
                        "bokeh, soft glare.",
    "cinema": "Cinema camera: a subtle mix, shallow focus, a little glare, fringing, falloff "
              "and grain.",
    "default": "A general camera: depth of field and motion where passes exist, subtle glare, "
               "falloff, fine grain.",
    "dreamy": "Diffusion filter: every bright area glows, a warm halo round the lights.",
    "film-35mm": "35 mm negative: red halation round lights, colour grain, a soft vignette.",
    "handheld-phone": "Handheld phone in dim light: camera shake smearing every edge, fine "
                      "noise.",
    "high-iso": "ISO 12800: coarse colour noise and chroma blotches, blue noisiest.",
    "macro": "Macro at f/2.8: a paper-thin plane of focus, everything else melts.",
    "phone-pan": "A fast phone pan: motion smear and leaning verticals (rolling shutter).",
    "real-lens": "Canon 24-70 at 24 mm wide open: distortion, fringes and vignetting as "
                 "measured.",
    "soft-camera": "A plastic lens: nothing quite sharp, dark corners.",
    "star-filter": "Six-point star filter: long rays from every bright light, slightly "
                   "coloured.",
    "sunny-flare": "Sun through a zoom: coloured ghosts across the frame, rainbow corona, "
                   "faint thin spikes.",
    "vintage-prime": "Vintage prime wide open: cat-eye bokeh, coloured fringes on blur, a "
                     "glow and strong falloff.",
    "vintage-zoom": "Old tele zoom: pincushion lines and strong colour fringes.",
    "webcam": "Cheap webcam: barrel distortion, dark corners and heavy noise.",
    "wide-angle": "16 mm wide angle: strong cos^4 falloff towards the corners.",
}
"""One sentence per tile: what the defect is and where to look (on the tile and in
``index.json``)."""

VARIANTS = {
    # options that are off at an effect's defaults, shown on their own (name: effect, settings)
    # focused at 1 m, wide open: the demo scene's wall and lights far out of focus
    "dof:cat-eye": ("dof", ["camera.optical_vignetting=1.2", "camera.f_number=1.4",
                            "camera.focus_distance=1"]),
    "dof:anamorphic-2x": ("dof", ["camera.anamorphic_squeeze=2", "camera.f_number=1.4",
                                  "camera.focus_distance=1"]),
    "dof:axial-ca": ("dof", ["camera.axial_ca_red=150", "camera.axial_ca_blue=150",
                             "camera.f_number=1.4", "camera.focus_distance=1"]),
    # a focus pulled from 20 m to 0.5 m on a unit-focusing lens: the frame narrows by 7%
    "breathing:pull-focus": ("breathing", ["amount=1", "reference_focus=20",
                                           "camera.focus_distance=0.5"]),
}
"""Gallery tiles for options that are off at an effect's defaults."""


def gallery_looks(only=None):
    """(kind, name, look) of every effect alone, every option variant (`VARIANTS`) and every
    built-in look."""
    items = [("effect", e, single_effect_look(e, EFFECT_SETTINGS.get(e, [])
                                              + DEMO_VALUES.get(e, [])))
             for e in discover()]
    items += [("effect", name, single_effect_look(effect, settings))
              for name, (effect, settings) in VARIANTS.items()]
    items += [("look", name, load_look(str(path))) for name, (origin, path)
              in available_looks().items() if origin == "built-in"]
    return [it for it in items if only is None or it[1] in only]


def tile_filename(kind: str, name: str) -> str:
    """The file name of a tile: ``<kind>-<name>.png`` with every character but letters,
    digits, ``.``, ``_`` and ``-`` as ``-`` (``dof:cat-eye`` -> ``effect-dof-cat-eye.png``:
    SMB and Windows shares refuse ``:``)."""
    return re.sub(r"[^A-Za-z0-9._-]", "-", f"{kind}-{name}") + ".png"


def gallery_files(outdir: str, images, items) -> list[str]:
    """Every file a gallery of ``images`` (names) and ``items`` (`gallery_looks`) writes
    into ``outdir``."""
    tiles = ["before.png", "sheet.png"] + [tile_filename(kind, name) for kind, name, _ in items]
    return [os.path.join(outdir, image, t) for image in images for t in tiles] + [
        os.path.join(outdir, "index.json")]


def _runnable(look, frame: Frame):
    """The look with steps lacking passes set to skip, and the names of those steps."""
    have = {"depth": frame.depth is not None, "velocity": frame.velocity is not None}
    missing = [s.id for _, s in look.active_steps() if s.absent_passes(have)]
    steps = [replace(s, missing_passes="skip") if s.absent_passes(have) else s for s in look.steps]
    return replace(look, steps=steps), missing


def run_gallery(rt, outdir: str, *, width: int = GALLERY_WIDTH, quality: str | None = None,
                only=None, columns: int = 6, thumb_width: int = 320, overwrite: bool = False,
                verbosity: int = 1) -> dict:
    """Render the gallery into ``outdir``; returns the index written to ``index.json``.

    Not a read/render/write loop (`clfx.pipeline.stream.render_stream` is the one): each
    input is read once and resized in memory, every look renders that frame in memory, and
    what is written is a labelled, tone-mapped sRGB tile about the render, never a rendered
    frame.  Every file goes through clfx's atomic writers (`clfx.io.write`: a temp file,
    then published; never through a symbolic link).  Without ``overwrite``, a file of an
    earlier gallery in ``outdir`` is an error before anything renders.

    Raises
    ------
    ParamError
        ``width`` or ``thumb_width`` below 1, ``columns`` below 1.
    ImageIOError
        ``outdir`` (or an image's folder in it) is a file or a symbolic link; a file the
        gallery writes exists and ``overwrite`` is off.
    """
    for what, value in (("width", width), ("thumb_width", thumb_width), ("columns", columns)):
        if int(value) < 1:
            raise ParamError(f"gallery: {what} must be at least 1, got {value}")

    def log(msg):
        if verbosity > 0:
            print(msg, file=sys.stderr, flush=True)

    def save(img, *parts):
        path = os.path.join(outdir, *parts)
        write_frame(Frame.from_array(np.ascontiguousarray(img, np.float32)), path,
                    overwrite=overwrite)
        return path

    t0 = time.perf_counter()
    items = gallery_looks(only)
    images = gallery_image_names()
    output_folder(outdir, create=False)       # a file there: one error, nothing written
    for name in images:                       # never written through a link to elsewhere
        output_folder(os.path.join(outdir, name), inside=outdir, create=False)
    if not overwrite:
        there = [p for p in gallery_files(outdir, images, items) if os.path.lexists(p)]
        if there:
            more = f" (and {len(there) - 1} more)" if len(there) > 1 else ""
            raise OutputExistsError(f"{there[0]} exists{more}; use --overwrite to replace the "
                                    f"gallery in {outdir}, or another folder")
    output_folder(outdir)
    index = {"width": width, "quality": quality or "final", "images": []}
    for name, frame in gallery_inputs(width, log):
        output_folder(os.path.join(outdir, name), inside=outdir)
        exposure = exposure_for(frame.rgba)
        before = tonemap(frame.rgba, exposure)
        save(label(before, f"{name}: before"), name, "before.png")
        thumbs = [caption(label(thumbnail(before, thumb_width), [name, "before"]),
                          CAPTIONS["before"])]
        entry = {"image": name, "source": frame.source,
                 "size": [frame.rgba.shape[1], frame.rgba.shape[0]],
                 "exposure": round(exposure, 4), "tiles": []}
        for kind, item, look in items:
            runnable, missing = _runnable(look, frame)
            lines = [f"{kind}: {item}"]
            if item in DEMO_VALUES:
                lines.append(" ".join(DEMO_VALUES[item]))
            if missing:
                lines.append("no pass: " + ",".join(missing) + " skipped")
            t1 = time.perf_counter()
            try:
                out, report = render_frame(rt, runnable, frame, frame_number=1,
                                           quality=quality)
            except ClfxError as exc:      # e.g. `lens` needs a lens chosen: say so, go on
                after, warnings, error = before, [], str(exc)
                lines.append("not rendered: " + error[:60])
            else:
                error = None
                after = tonemap(crop_to(out.rgba, out.data_window, frame.display_window),
                                exposure)
                warnings = [w for s in report.steps for w in s.warnings]
            ms = (time.perf_counter() - t1) * 1e3
            file = save(label(after, lines), name, tile_filename(kind, item))
            text = CAPTIONS.get(item, "")
            thumbs.append(caption(label(thumbnail(after, thumb_width), lines), text))
            entry["tiles"].append({"kind": kind, "name": item, "caption": text,
                                   "file": os.path.relpath(file, outdir),
                                   "settings": DEMO_VALUES.get(item, []),
                                   "ms": round(ms, 1),
                                   "skipped_steps": missing, "warnings": warnings,
                                   "error": error})
            log(f"clfx gallery: {name}: {kind} {item} ({ms:.0f} ms)")
        entry["sheet"] = save(tile_sheet(thumbs, columns), name, "sheet.png")
        index["images"].append(entry)
        log(f"clfx gallery: contact sheet {entry['sheet']}")
    index["wall_s"] = round(time.perf_counter() - t0, 1)
    write_text(json.dumps(index, indent=1) + "\n", os.path.join(outdir, "index.json"),
               overwrite=overwrite)
    return index
