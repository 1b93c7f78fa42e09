"""`clfx gallery`: every effect and every built-in look on a few test images, one labelled
before/after contact sheet per image, so anyone can judge the looks at a glance.

Images: the built-in demo scene (frame 1, with its depth and velocity passes) and, where
the shared OpenEXR test images are found (``CLFX_SHARED_DATA``, else ``shared/data`` next to
the repository or one folder further up), ``ScanLines/CandleGlass.exr`` and
``ScanLines/Desk.exr``; a missing image is skipped with one line on stderr.  Each input is
area-downscaled to ``width`` pixels (640 by default: the whole gallery takes a few minutes on
a CPU device); sizes are fractions of the frame diagonal, so the effects look as they would
at full resolution.

Every effect runs alone at its default parameters (``clfx apply EFFECT``), every built-in
look as shipped; an effect or look step that needs a depth or velocity pass the image lacks
is skipped, and the tile says so.  Written to OUTDIR:

- ``<image>/sheet.png``: the input (``before``) then every effect and look (``after``), each
  tile labelled, tone-mapped with one exposure per image (so tiles compare);
- ``<image>/<kind>-<name>.png``: each tile at full gallery resolution;
- ``index.json``: what was rendered, skipped and how long it took.
"""
from __future__ import annotations

import json
import math
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from clfx.core.frame import Frame
from clfx.demo import tonemap_preview as tonemap
from clfx.pipeline.look import render_frame

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
    " ": "00 00 00 00 00 00 00",
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


def label(tile: np.ndarray, text: str, *, scale: int = 2) -> np.ndarray:
    """``tile`` (display-linear RGB) with ``text`` written in white on a dark band at the top."""
    out = tile.copy()
    mask = text_mask(text, scale)
    h = mask.shape[0] + 2 * scale
    w = min(mask.shape[1], out.shape[1] - 2 * scale)
    band = out[:h]
    band *= 0.25                                   # darken behind the text, keep the image
    if w > 0:
        region = band[scale:scale + mask.shape[0], scale:scale + w]
        region[mask[:, :w]] = 1.0
    return out


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


def gallery_inputs(width: int, log=print) -> list[tuple[str, Frame]]:
    """(name, frame) of every gallery image found, downscaled to ``width`` pixels."""
    from clfx.bench.scene import demo_scene, render_sharp

    height = int(round(width * 9 / 16))
    demo = render_sharp(demo_scene(1, width, height))
    demo.source = "demo scene frame 1"
    out = [("demo", demo)]
    for name in SCANLINES:
        path = find_scanline_image(name)
        if path is None:
            log(f"clfx gallery: {name}.exr not found (looked in "
                f"{', '.join(str(d / 'openexr-images/ScanLines') for d in shared_data_dirs())}); "
                f"skipped")
            continue
        from clfx.core.frame import crop_to
        from clfx.io.read import read_frame

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


def gallery_looks(only=None):
    """(kind, name, look) of every effect alone and every built-in look."""
    from clfx.pipeline.presets import available_looks, load_look, single_effect_look
    from clfx.plugins import discover

    items = [("effect", e, single_effect_look(e, [])) for e in discover()]
    items += [("look", name, load_look(str(path))) for name, (origin, path)
              in available_looks().items() if origin == "built-in"]
    return [it for it in items if only is None or it[1] in only]


def _runnable(look, frame: Frame):
    """The look with steps lacking passes set to skip, and the names of those steps."""
    have = {"depth": frame.depth is not None, "velocity": frame.velocity is not None}
    missing = [s.id for _, s in look.active_steps() if s.absent_passes(have)]
    steps = [replace(s, missing_passes="skip") if s.absent_passes(have) else s for s in look.steps]
    return replace(look, steps=steps), missing


def contact_sheet(tiles: list[np.ndarray], columns: int = 6, gap: int = 4) -> np.ndarray:
    th = max(t.shape[0] for t in tiles)
    tw = max(t.shape[1] for t in tiles)
    cols = min(columns, len(tiles))
    rows = -(-len(tiles) // cols)
    sheet = np.full((rows * (th + gap) + gap, cols * (tw + gap) + gap, 3), 0.02, np.float32)
    for i, t in enumerate(tiles):
        r, c = divmod(i, cols)
        y, x = gap + r * (th + gap), gap + c * (tw + gap)
        sheet[y:y + t.shape[0], x:x + t.shape[1]] = t
    return sheet


def run_gallery(rt, outdir: str, *, width: int = GALLERY_WIDTH, quality: str | None = None,
                only=None, columns: int = 6, verbosity: int = 1) -> dict:
    """Render the gallery into ``outdir``; returns the index written to ``index.json``."""
    from clfx.io.write import write_frame

    def log(msg):
        if verbosity > 0:
            print(msg, file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    os.makedirs(outdir, exist_ok=True)
    items = gallery_looks(only)
    index = {"width": width, "quality": quality or "final", "images": []}
    for name, frame in gallery_inputs(width, log):
        folder = os.path.join(outdir, name)
        os.makedirs(folder, exist_ok=True)
        from clfx.core.frame import crop_to

        exposure = exposure_for(frame.rgba)
        tiles = [label(tonemap(frame.rgba, exposure), f"{name}: before")]
        write_frame(Frame.from_array(tiles[0]), os.path.join(folder, "before.png"),
                    overwrite=True)
        entry = {"image": name, "source": frame.source, "size": [frame.rgba.shape[1],
                 frame.rgba.shape[0]], "exposure": round(exposure, 4), "tiles": []}
        for kind, item, look in items:
            runnable, missing = _runnable(look, frame)
            t1 = time.perf_counter()
            out, report = render_frame(rt, runnable, frame, frame_number=1, quality=quality)
            ms = (time.perf_counter() - t1) * 1e3
            rgba = crop_to(out.rgba, out.data_window, frame.display_window)
            text = f"{kind[0]}: {item}"
            if missing:
                text += " (no passes: " + ",".join(missing) + " skipped)"
            tile = label(tonemap(rgba, exposure), text)
            tiles.append(tile)
            write_frame(Frame.from_array(tile), os.path.join(folder, f"{kind}-{item}.png"),
                        overwrite=True)
            warnings = [w for s in report.steps for w in s.warnings]
            entry["tiles"].append({"kind": kind, "name": item, "ms": round(ms, 1),
                                   "skipped_steps": missing, "warnings": warnings})
            log(f"clfx gallery: {name}: {kind} {item} ({ms:.0f} ms)")
        sheet = os.path.join(folder, "sheet.png")
        write_frame(Frame.from_array(contact_sheet(tiles, columns)), sheet, overwrite=True)
        entry["sheet"] = sheet
        index["images"].append(entry)
        log(f"clfx gallery: contact sheet {sheet}")
    index["wall_s"] = round(time.perf_counter() - t0, 1)
    with open(os.path.join(outdir, "index.json"), "w") as f:
        json.dump(index, f, indent=1)
    return index
