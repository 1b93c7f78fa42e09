"""``clfx prebuild``: compile the kernels of looks at quality levels ahead of any render, so a
farm node's image (or a workstation) starts warm.

A cold kernel cache costs a first render 2-9x its time: every OpenCL program a look runs is
compiled once per machine and kept in PoCL's cache (``POCL_CACHE_DIR``, by default
``$XDG_CACHE_HOME/clfx/pocl``).  Prebuilding renders one frame of the demo scene (with its
depth and velocity passes, and highlights, so no step skips) through each look at each level;
programs do not depend on the frame's size, but PoCL also compiles each kernel's work-group
code per work-group size it is launched with, which a frame size picks: ``--size`` the
plates' size warms those too.
"""
from __future__ import annotations

import time
from typing import Callable

from clfx.bench.looks import demo_frame
from clfx.core.plugin import QUALITY_LEVELS
from clfx.pipeline.look import render_frame
from clfx.pipeline.presets import load_look


def prebuild(rt, looks: list[str], levels: list[str], width: int, height: int, *,
             log: Callable[[str], None] = lambda line: None) -> list[dict]:
    """Render one demo frame of ``width`` x ``height`` through each look at each level.

    Returns
    -------
    list of dict
        Per look and level: ``look``, ``quality``, ``programs`` (programs it needed that
        this process had not built yet), ``compiled`` (of those, the ones the kernel cache
        did not hold: compiled now) and ``s`` (seconds, the render included).
    """
    frame = demo_frame(width, height)
    rows = []
    for name in looks:
        look = load_look(name)
        for level in levels:
            first, t0 = len(rt.builds), time.perf_counter()
            render_frame(rt, look, frame, frame_number=1, quality=level)
            rt.finish()
            new = rt.builds[first:]
            row = {"look": name, "quality": level, "programs": len(new),
                   "compiled": sum(b.cold for b in new),
                   "s": round(time.perf_counter() - t0, 2)}
            rows.append(row)
            log(f"{name:<20} {level:<9} {row['compiled']:>3} program(s) compiled, "
                f"{row['programs'] - row['compiled']:>3} from the cache  {row['s']:7.1f} s")
    return rows


def levels_of(text: str) -> list[str]:
    """``draft,final`` or ``all`` -> the quality levels (ValueError naming an unknown one)."""
    names = list(QUALITY_LEVELS) if text == "all" else [t.strip() for t in text.split(",")]
    for n in names:
        if n not in QUALITY_LEVELS:
            raise ValueError(f"unknown quality level {n!r} (expected {', '.join(QUALITY_LEVELS)}"
                             f" or all)")
    return names
