"""`clfx demo`: the built-in procedural scene rendered through a look, no input files needed.

For each frame the layered HDR scene of :func:`clfx.bench.scene.demo_scene` (bright lights,
textured surfaces at several depths, moving objects) is rendered sharp with exact depth and
velocity passes and written; the look then runs over those files through ``clfx render``'s
own pipeline.  Written to OUTDIR:

- ``scene.#.exr``  the sharp input with its ``Z`` and ``forward.u/v`` passes (feed it to
  ``clfx render`` to try other looks);
- ``demo.#.exr``   the look's output (half float, scene-linear);
- ``demo.#.png``   a tone-mapped sRGB preview of each output;
- ``contact_sheet.png`` each frame's input (before) beside its output (after), labelled
  with the frame and the look, tone-mapped alike.
"""
from __future__ import annotations

import json
import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from clfx.bench.scene import demo_scene, render_sharp
from clfx.core.errors import ImageIOError, option
from clfx.core.frame import Frame, crop_to
from clfx.io.read import read_frame
from clfx.io.write import output_folder, write_frame
from clfx.pipeline.batch import Batch
from clfx.pipeline.options import RenderOptions
from clfx.pipeline.presets import load_look
from clfx.pipeline.stream import codec_threads_for, io_threads, render_stream

PREVIEW_EXPOSURE = 1.0


def tonemap_preview(rgba: np.ndarray, exposure: float = PREVIEW_EXPOSURE) -> np.ndarray:
    """Scene-linear RGBA -> display-linear RGB in [0, 1] (Reinhard on each channel).

    For previews only: the EXR outputs keep the full radiance.  Non-finite values become 0.
    """
    rgb = np.nan_to_num(rgba[..., :3].astype(np.float32), nan=0.0, posinf=65504.0, neginf=0.0)
    rgb = np.maximum(rgb * exposure, 0.0)
    return rgb / (1.0 + rgb)


def contact_sheet(pairs: list[tuple[int, np.ndarray, np.ndarray]], look_name: str,
                  columns: int = 6, thumb_width: int = 320) -> np.ndarray:
    """Each frame's ``(number, before, after)`` previews (display-linear RGB) side by side,
    box-downscaled and labelled ``frame N`` / ``before`` or ``after: LOOK`` (the gallery's
    labels), pairs kept on one row."""
    from clfx.gallery import label, thumbnail     # lazy: clfx.gallery imports this module (a cycle)

    tiles = []
    for number, before, after in pairs:
        for img, what in ((before, "before"), (after, f"after: {look_name}")):
            thumb = thumbnail(img, thumb_width)
            tiles.append(label(thumb, [f"frame {number}", what],
                               scale=2 if thumb.shape[1] >= 240 else 1))
    return tile_sheet(tiles, max(2, columns - columns % 2))


def tile_sheet(tiles: list[np.ndarray], columns: int = 6, gap: int = 4) -> np.ndarray:
    """Tiles (display-linear RGB, any sizes) on a dark sheet, row by row."""
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


def demo_files(outdir: str, count: int) -> list[str]:
    """Every file a demo of ``count`` frames writes into ``outdir``."""
    names = [f"{kind}.{i:04d}.{ext}" for i in range(1, count + 1)
             for kind, ext in (("scene", "exr"), ("demo", "exr"), ("demo", "png"))]
    return [os.path.join(outdir, n) for n in names + ["contact_sheet.png"]]


def run_demo(rt, outdir: str, *, count: int = 24, width: int = 640, height: int = 360,
             look_name: str = "default", quality: str | None = None, overwrite: bool = False,
             explain: bool = False, as_json: bool = False, verbosity: int = 1) -> dict:
    """Render the demo scene into ``outdir``.  Without ``overwrite``, files of an earlier
    demo there are an error before anything is rendered (like ``clfx render``).

    The scene's frames are written first (``scene.#.exr``, float); the look then runs over
    them through `clfx render`'s own pipeline (`clfx.pipeline.stream.render_stream`: read,
    render, write; half-float output stamped like a render's), so ``clfx render`` of the
    scene files with the same look renders the same frames (written as float there, the
    input's type).  Each preview is the output as written."""
    look = load_look(look_name)
    if not overwrite:
        there = [p for p in demo_files(outdir, count) if os.path.lexists(p)]
        if there:
            more = f" (and {len(there) - 1} more)" if len(there) > 1 else ""
            raise ImageIOError(f"{there[0]} exists{more}; use {option('--overwrite')} to replace the "
                               f"demo in {outdir}, or another folder")
    output_folder(outdir)          # a file or a broken link there: one error line
    t0 = time.perf_counter()
    with ThreadPoolExecutor(max_workers=2, thread_name_prefix="clfx-demo") as pool:
        list(pool.map(lambda n: write_scene(outdir, n, width, height, overwrite), range(1, count + 1)))
    batch = Batch(look=look, input_path=os.path.join(outdir, "scene.#.exr"),
                  output_path=os.path.join(outdir, "demo.#.exr"),
                  options=RenderOptions(frames=f"1-{count}", quality=quality, bit_depth="half",
                                        overwrite=overwrite, as_json=as_json),
                  verbosity=0)
    batch.prepare()
    pairs, reports = [], []

    def frame_done(result):
        report = result.report
        reports.append(report)
        after = preview_of(result.output)
        pairs.append((result.frame, preview_of(result.input), after))
        write_frame(Frame.from_array(after), os.path.splitext(result.output)[0] + ".png",
                    overwrite=overwrite)
        if explain:
            print(report.explain(), file=sys.stderr)
        if as_json:
            print(json.dumps(report.as_dict()), flush=True)
        elif verbosity > 0 and sys.stderr.isatty():
            print(f"\rclfx demo: frame {result.frame}/{count}", end="", file=sys.stderr, flush=True)

    with io_threads(codec_threads_for(rt)):
        render_stream(rt, batch.plan, batch.jobs, frame_done, stats=batch.stats)
    if verbosity > 0 and sys.stderr.isatty() and not as_json:
        print("", file=sys.stderr)
    sheet_path = os.path.join(outdir, "contact_sheet.png")
    write_frame(Frame.from_array(contact_sheet(pairs, look.name)), sheet_path, overwrite=overwrite)
    wall = time.perf_counter() - t0
    summary = {"summary": True, "look": look.name, "frames": count, "size": [width, height],
               "outdir": outdir, "contact_sheet": sheet_path, "wall_s": round(wall, 2),
               "device_ms_mean": round(float(np.mean([r.total_ms for r in reports])), 1)}
    if as_json:
        print(json.dumps(summary), flush=True)
    elif verbosity > 0:
        print(f"clfx demo: {count} frames of {width}x{height} through look {look.name!r} in "
              f"{wall:.1f} s ({summary['device_ms_mean']} ms/frame on the device) -> {outdir}/",
              file=sys.stderr)
        print(f"clfx demo: contact sheet {sheet_path}", file=sys.stderr)
    return summary


def write_scene(outdir: str, frame_no: int, width: int, height: int, overwrite: bool) -> str:
    """Frame ``frame_no`` of the demo scene, sharp with its depth and velocity passes, as
    ``scene.#.exr`` (float) in ``outdir``; its path."""
    path = os.path.join(outdir, f"scene.{frame_no:04d}.exr")
    write_frame(render_sharp(demo_scene(frame_no, width, height)), path, overwrite=overwrite,
                bit_depth="float")
    return path


def preview_of(path: str) -> np.ndarray:
    """The tone-mapped preview (`tonemap_preview`) of an output file's display window."""
    out = read_frame(path)
    return tonemap_preview(crop_to(out.rgba, out.data_window, out.display_window))
