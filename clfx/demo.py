"""`clfx demo`: the built-in procedural scene rendered through a look, no input files needed.

For each frame the layered HDR scene of :func:`clfx.bench.scene.demo_scene` (bright lights,
textured surfaces at several depths, moving objects) is rendered sharp with exact depth and
velocity passes, then through the look.  Written to OUTDIR:

- ``scene.####.exr``  the sharp input with its ``Z`` and ``forward.u/v`` passes (feed it to
  ``clfx render`` to try other looks);
- ``demo.####.exr``   the look's output (half float, scene-linear);
- ``demo.####.png``   a tone-mapped sRGB preview of each output;
- ``contact_sheet.png`` every preview on one sheet.
"""
from __future__ import annotations

import json
import math
import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from clfx.core.frame import Frame
from clfx.pipeline.look import RunStats, render_frame

PREVIEW_EXPOSURE = 1.0


def tonemap_preview(rgba: np.ndarray, exposure: float = PREVIEW_EXPOSURE) -> np.ndarray:
    """Scene-linear RGBA -> display-linear RGB in [0, 1] (Reinhard on each channel).

    For previews only: the EXR outputs keep the full radiance.  Non-finite values become 0.
    """
    rgb = np.nan_to_num(rgba[..., :3].astype(np.float32), nan=0.0, posinf=65504.0, neginf=0.0)
    rgb = np.maximum(rgb * exposure, 0.0)
    return rgb / (1.0 + rgb)


def contact_sheet(previews: list[np.ndarray], columns: int = 6, thumb_width: int = 320,
                  gap: int = 4) -> np.ndarray:
    """Tile display-linear RGB previews into one image (box-downscaled thumbnails)."""
    h, w = previews[0].shape[:2]
    step = max(1, int(math.ceil(w / thumb_width)))
    thumbs = [p[: h - h % step or h, : w - w % step or w] for p in previews]
    thumbs = [t.reshape(t.shape[0] // step, step, t.shape[1] // step, step, 3).mean(axis=(1, 3))
              if step > 1 else t for t in thumbs]
    return tile_sheet(thumbs, columns, gap)


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
    demo there are an error before anything is rendered (like ``clfx render``)."""
    from clfx.core.errors import ImageIOError
    from clfx.io.write import write_frame
    from clfx.pipeline.presets import load_look
    from clfx.bench.scene import demo_scene, render_sharp

    look = load_look(look_name)
    if not overwrite:
        there = [p for p in demo_files(outdir, count) if os.path.lexists(p)]
        if there:
            more = f" (and {len(there) - 1} more)" if len(there) > 1 else ""
            raise ImageIOError(f"{there[0]} exists{more}; use --overwrite to replace the "
                               f"demo in {outdir}, or another folder")
    os.makedirs(outdir, exist_ok=True)
    t0 = time.perf_counter()
    previews, reports = [], []
    stats = RunStats()

    def write_all(frame_no, sharp, out, preview):
        base = os.path.join(outdir, f"%s.{frame_no:04d}.%s")
        write_frame(sharp, base % ("scene", "exr"), overwrite=overwrite, bit_depth="float")
        write_frame(out, base % ("demo", "exr"), overwrite=overwrite,
                    attributes=look.stamp(frame_no))
        write_frame(Frame.from_array(preview), base % ("demo", "png"), overwrite=overwrite)

    def preview_of(out):
        from clfx.core.frame import crop_to

        rgba = crop_to(out.rgba, out.data_window, out.display_window)
        return tonemap_preview(rgba)

    with ThreadPoolExecutor(max_workers=2, thread_name_prefix="clfx-demo") as pool:
        writes = []
        for i in range(count):
            frame_no = i + 1
            sharp = render_sharp(demo_scene(frame_no, width, height))
            sharp.source = f"demo scene frame {frame_no}"
            out, report = render_frame(rt, look, sharp, frame_number=frame_no, quality=quality,
                                       analysis_summary=as_json, stats=stats)
            report.output = os.path.join(outdir, f"demo.{frame_no:04d}.exr")
            reports.append(report)
            previews.append(preview_of(out))
            writes.append(pool.submit(write_all, frame_no, sharp, out, previews[-1]))
            if explain:
                print(report.explain(), file=sys.stderr)
            if as_json:
                print(json.dumps(report.as_dict()), flush=True)
            elif verbosity > 0 and sys.stderr.isatty():
                print(f"\rclfx demo: frame {frame_no}/{count}", end="", file=sys.stderr, flush=True)
        for f in writes:
            f.result()
    if verbosity > 0 and sys.stderr.isatty() and not as_json:
        print("", file=sys.stderr)
    sheet_path = os.path.join(outdir, "contact_sheet.png")
    write_frame(Frame.from_array(contact_sheet(previews)), sheet_path, overwrite=overwrite)
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
