"""Pack Blender's renders (render_scenes.py's output) into the bench's small data files.

    python -m clfx.bench.cycles.pack RENDER_DIR [--out clfx/bench/cycles/data]

``<name>.sharp.exr`` (Blender's multi-part multilayer file) becomes ``<name>.exr``: one part
with the same channel names (``ViewLayer.Combined.RGBA`` half, ``ViewLayer.Depth.Z`` float,
``ViewLayer.Vector.XYZW`` half; the depth-of-field scenes have no Vector pass), ZIP; the
truths and the compositor's Vector Blur or Defocus (``Composite.Combined``) go into
``<name>.ref.exr`` as ``truth.RGB`` (the seed-1 render) and ``vectorblur.RGB`` or
``defocus.RGB`` (half, ZIP), with the log-PSNR of the seed-2 render against it in the
header (``clfx:noise_floor_log_psnr``; ``--keep-second`` stores that render too, as
``truth2.RGB``).  Prints each scene's noise floor and file sizes.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import OpenImageIO as oiio
import numpy as np

from clfx.bench import cycles
from clfx.bench.cycles import DOF_SCENES, FLOOR_ATTRIBUTE, base_scene
from clfx.bench.metrics import psnr_log
from clfx.io.read import read_channels


def _write(path: str, channels: dict[str, np.ndarray], formats: dict[str, str],
           attributes: dict | None = None) -> None:
    names = list(channels)
    h, w = channels[names[0]].shape
    spec = oiio.ImageSpec(w, h, len(names), "half")
    spec.channelnames = tuple(names)
    spec.channelformats = tuple(oiio.TypeDesc(formats.get(n, "half")) for n in names)
    spec.attribute("compression", "zip")
    for k, v in (attributes or {}).items():
        spec.attribute(k, v)
    for i, n in enumerate(names):
        if n.endswith(".A"):
            spec.alpha_channel = i
    out = oiio.ImageOutput.create(path)
    if not out.open(path, spec):
        raise OSError(oiio.geterror())
    out.write_image(np.stack([channels[n] for n in names], -1).astype(np.float32))
    out.close()


def pack(src: str, name: str, out_dir: str, keep_second: bool = False) -> None:
    if base_scene(name) == name:
        sharp = read_channels(os.path.join(src, f"{name}.sharp.exr"))
        keep = [f"ViewLayer.Combined.{c}" for c in "RGBA"] + ["ViewLayer.Depth.Z"]
        keep += [f"ViewLayer.Vector.{c}" for c in "XYZW" if f"ViewLayer.Vector.{c}" in sharp]
        _write(os.path.join(out_dir, f"{name}.exr"), {k: sharp[k] for k in keep},
               {"ViewLayer.Depth.Z": "float"})
    else:
        sharp = {}
    truths = []
    for seed in (1, 2):
        path = os.path.join(src, f"{name}.truth{seed}.exr")
        if os.path.exists(path):
            t = read_channels(path)
            truths.append(np.stack([t[c] for c in "RGB"], -1))
    ref = {f"truth.{c}": truths[0][..., i] for i, c in enumerate("RGB")}
    if keep_second and len(truths) > 1:
        ref.update({f"truth2.{c}": truths[1][..., i] for i, c in enumerate("RGB")})
    if "Composite.Combined.R" in sharp:
        peer = "defocus" if name in DOF_SCENES else "vectorblur"
        for c in "RGB":
            ref[f"{peer}.{c}"] = sharp[f"Composite.Combined.{c}"]
    # The floor of the stored (half-float) truth: both renders rounded as stored.
    half = [t.astype(np.float16).astype(np.float32) for t in truths]
    attrs = {FLOOR_ATTRIBUTE: float(psnr_log(half[1], half[0]))} if len(half) > 1 else {}
    _write(os.path.join(out_dir, f"{name}.ref.exr"), ref, {}, attrs)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("src")
    ap.add_argument("--out", default=str(cycles.DATA))
    ap.add_argument("--scenes", default=",".join(cycles.SCENES))
    ap.add_argument("--keep-second", action="store_true",
                    help="store the second seed's render too (the floor is stored either way)")
    args = ap.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    cycles.DATA = Path(args.out).resolve()
    for name in args.scenes.split(","):
        pack(args.src, name, args.out, args.keep_second)
        cycles.load.cache_clear()
        sharp, ref = cycles.files(name)
        floor = cycles.noise_floor(name)
        print(f"{name}: noise floor {'-' if floor is None else f'{floor:.1f} dB'}, "
              f"{os.path.getsize(sharp) // 1024} + {os.path.getsize(ref) // 1024} KiB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
