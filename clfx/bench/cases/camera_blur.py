"""Bench case of camera_blur: a handheld-style pan with a slight roll and trucking."""
from __future__ import annotations

from clfx.bench.cases import Case
from clfx.bench.scene import moving_scene, render_sharp
from clfx.core.camera import Camera


def make(width: int, height: int, rng) -> dict:
    """A handheld-style pan with a slight roll and trucking over the layered test scene."""
    scene = moving_scene(width, height, 0.0)
    sharp = render_sharp(scene, 0.0, ss=2)
    return dict(source=sharp.rgba, depth=sharp.depth, velocity=None,
                params=dict(length=0.01, direction=200.0, roll=0.3, truck=(0.02, 0.0)),
                camera=Camera(shutter_angle=180.0))


CASE = Case(make=make)
