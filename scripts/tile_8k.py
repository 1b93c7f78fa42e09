"""8K cinema, tiled against untiled (issue 26): the same bits, and what tiling saves.

Renders a synthetic plate (`clfx.bench.scene.synthetic_plate`: RGBA, depth, velocity) through
the cinema look twice, each in a fresh process with the same small pool (``CLFX_POOL_MB``):
whole frames, then the steps that tile in bands of ``--tile-pixels``.  Prints one JSON line
per render (device peak: the most bytes of pooled device buffers at once, `rt.cache`; process
peak: the largest resident set, ``ru_maxrss``; the SHA-256 of the output's float bits; which
steps tiled) and exits 1 unless both outputs are bit-identical.

    python scripts/tile_8k.py [--size 7680x4320] [--pool-mb 64] [--tile-pixels 1048576]
                              [--tiling-steps] [--steps A,B]

``--tiling-steps`` keeps only the look's steps that tile (what tiling itself saves: the
whole look's peaks are those of its steps that render whole); ``--steps`` keeps only the
named effects (one step's peaks, e.g. ``--steps dof``).

A kernel compile counts in the first process's wall time, not in its peaks (PoCL caches
binaries across processes; docs/performance.md's "Memory" has what a cold cache adds).
"""
from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import os
import resource
import subprocess
import sys
import time


def child(size: tuple[int, int], tile_pixels: int, tiling_steps: bool = False,
          steps: tuple[str, ...] = ()) -> dict:
    import clfx
    from clfx.bench.scene import synthetic_plate
    from clfx.device.runtime import Runtime
    from clfx.pipeline.look import render_frame

    rt = Runtime.get()
    look = clfx.load_look("cinema")
    if tiling_steps:
        look = dataclasses.replace(look, steps=[s for s in look.steps
                                                if s.plugin.whole_frame is None])
    if steps:
        look = dataclasses.replace(look, steps=[s for s in look.steps if s.effect in steps])
    frame = synthetic_plate(*size)
    rt.cache.reset_peak()
    t0 = time.perf_counter()
    out, report = render_frame(rt, look, frame, frame_number=5, release_input=True,
                               tile_pixels=tile_pixels)
    wall = time.perf_counter() - t0
    return {"tile_pixels": tile_pixels or None, "size": list(size),
            "pool_mb": int(os.environ.get("CLFX_POOL_MB", "512")),
            "device_peak_mib": round(rt.cache.device_peak / 2 ** 20, 1),
            "process_peak_mib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
            "wall_s": round(wall, 1),
            "ran": [s.effect for s in report.steps if s.ran],
            "tiled": [s.effect for s in look.steps if s.plugin.whole_frame is None
                      and tile_pixels] if report.steps else [],
            "window": str(out.data_window),
            "sha256": hashlib.sha256(out.rgba.tobytes()).hexdigest()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="7680x4320", help="WIDTHxHEIGHT (default 8K UHD)")
    ap.add_argument("--pool-mb", type=int, default=64, help="CLFX_POOL_MB of both renders")
    ap.add_argument("--tile-pixels", type=int, default=1 << 20,
                    help="the tiled render's band size in pixels")
    ap.add_argument("--tiling-steps", action="store_true",
                    help="only the look's steps that tile")
    ap.add_argument("--steps", default="",
                    help="only these effects of the look (comma-separated names)")
    ap.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    size = tuple(int(v) for v in args.size.lower().split("x"))
    steps = tuple(n for n in args.steps.split(",") if n)
    if args.child is not None:
        print(json.dumps(child(size, args.child, args.tiling_steps, steps)), flush=True)
        return 0
    env = {**os.environ, "CLFX_POOL_MB": str(args.pool_mb)}
    env.pop("CLFX_TILE_PIXELS", None)
    results = []
    for tiles in (0, args.tile_pixels):
        proc = subprocess.run([sys.executable, __file__, "--size", args.size, "--child",
                               str(tiles)] + ["--tiling-steps"] * args.tiling_steps
                              + ["--steps", args.steps] * bool(steps), env=env,
                              capture_output=True, text=True)
        lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
        if proc.returncode or not lines:
            print(proc.stderr[-4000:], file=sys.stderr)
            return proc.returncode or 1
        results.append(json.loads(lines[-1]))
        print(lines[-1], flush=True)
    same = results[0]["sha256"] == results[1]["sha256"]
    print(json.dumps({"bit_identical": same}))
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
