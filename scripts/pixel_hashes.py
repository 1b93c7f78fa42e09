"""Hash the pixels of every look and every effect at every quality level, on the demo scene and
on Beachball (with their depth and velocity passes): the net under a refactor that must keep
pixels bit-identical.

    python scripts/pixel_hashes.py > before.txt       # on the old commit
    python scripts/pixel_hashes.py > after.txt        # on the new one
    diff before.txt after.txt                          # empty: bit-identical

Each line is ``<plate> <look or effect> <level> <sha256 of the float32 RGBA>``.  ``--tile N``
sets ``CLFX_TILE_PIXELS`` so the tiled path is hashed too; ``--only`` filters names.
"""
from __future__ import annotations

import argparse
import hashlib
import os
import sys
import warnings
from pathlib import Path


STANDALONE = {"lens": {"maker": "Canon", "model": "Canon EF 24-70mm f/2.8L II USM"}}
"""Parameters an effect cannot render without."""


STANDALONE = {"lens": {"maker": "Canon", "model": "Canon EF 24-70mm f/2.8L II USM"}}
"""Parameters an effect cannot render without."""


def plates(size):
    import numpy as np
    from clfx.bench.scene import demo_scene, render_sharp
    from clfx.io.read import read_frame

    w, h = size
    demo = render_sharp(demo_scene(7, w, h))
    yield "demo", demo.rgba, demo.depth, demo.velocity
    shared = Path(os.environ.get("CLFX_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
    ball = read_frame(str(shared / "openexr-images" / "Beachball" / "singlepart.0001.exr"))
    bh, bw = ball.rgba.shape[:2]
    y0, x0 = max(0, (bh - h) // 2), max(0, (bw - w) // 2)
    crop = (slice(y0, y0 + h), slice(x0, x0 + w))
    yield ("beachball", np.ascontiguousarray(ball.rgba[crop]),
           None if ball.depth is None else np.ascontiguousarray(ball.depth[crop]),
           None if ball.velocity is None else np.ascontiguousarray(ball.velocity[crop]))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="240x136")
    ap.add_argument("--tile", type=int, default=0, help="CLFX_TILE_PIXELS for a tiled render")
    ap.add_argument("--only", default="", help="comma-separated looks/effects to hash")
    args = ap.parse_args()
    if args.tile:
        os.environ["CLFX_TILE_PIXELS"] = str(args.tile)
    warnings.simplefilter("ignore")
    import clfx
    from clfx.core.plugin import QUALITY_LEVELS
    from clfx.pipeline.presets import available_looks
    from clfx.plugins import discover

    size = tuple(int(v) for v in args.size.split("x"))
    only = set(filter(None, args.only.split(",")))
    looks = [(n, n) for n in sorted(available_looks())]
    looks += [(f"fx:{n}", {"effects": [{"effect": n, "params": STANDALONE.get(n, {})}]})
              for n in sorted(discover())]
    for plate, rgba, depth, velocity in plates(size):
        for name, look in looks:
            if only and name.removeprefix("fx:") not in only:
                continue
            for level in QUALITY_LEVELS:
                try:
                    out = clfx.render_array(rgba, look, depth=depth, velocity=velocity, frame=1,
                                            quality=level).rgba
                    digest = hashlib.sha256(out.astype("float32").tobytes()).hexdigest()[:16]
                except Exception as exc:      # a refusal is a result too
                    digest = f"error:{type(exc).__name__}"
                print(f"{plate} {name} {level} {digest}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
