"""Bench case of dof: the demo scene through a shallow lens, against a multisample ground
truth (the runner caches it on disk: it takes tens of seconds at 1080p)."""
from __future__ import annotations

from clfx.bench.cases import Case
from clfx.bench.groundtruth import make_case
from clfx.bench.scene import demo_scene
from clfx.core.camera import Camera


def bench_camera(width: int) -> Camera:
    """A 50 mm f/2.2 lens focused on the demo subject at 3 m: CoC up to ~40 px at 1920 wide."""
    return Camera(focal_length=50.0, f_number=2.2, sensor_width=36.0, focus_distance=3.0,
                  shutter_angle=180.0)


def make(width: int, height: int, rng=None) -> dict:
    """The demo scene through a shallow lens, with its multisample ground truth (``truth``)."""
    scene = demo_scene(12, int(width), int(height))
    case = make_case(scene, bench_camera(width), samples=1024, dof=True, motion=False, ss=1)
    return dict(source=case.sharp.rgba, depth=case.sharp.depth, velocity=None,
                params={}, camera=case.camera, truth=case.truth, truth_seconds=case.seconds)


CASE = Case(make=make)
