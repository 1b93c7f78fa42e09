"""Bench case of motion_blur: layers at several depths moving up to 60 px/frame at 1920 px
wide, against a multisample ground truth."""
from __future__ import annotations

from clfx.bench.cases import Case
from clfx.bench.groundtruth import render_truth
from clfx.bench.scene import moving_scene, render_sharp
from clfx.core.camera import Camera


def make(width: int, height: int, rng, *, truth: bool = True, truth_samples: int = 64,
         moving_fraction=None) -> dict:
    """A representative hard case: layers at several depths moving up to 60 px/frame at
    1920 px wide (scaled with the width), with the multisample ground truth (``truth``)."""
    scene = moving_scene(width, height, 60.0 * width / 1920.0, moving_fraction)
    camera = Camera(shutter_angle=180.0, shutter_offset="centered")
    sharp = render_sharp(scene, 0.0, ss=2)
    case = dict(source=sharp.rgba, depth=sharp.depth, velocity=sharp.velocity,
                params={}, camera=camera)
    if truth:
        case["truth"] = render_truth(scene, camera, samples=truth_samples, dof=False,
                                     motion=True, ss=2)
    return case


CASE = Case(make=make)
