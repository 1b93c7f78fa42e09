"""One immutable plan per step per frame (issue 36): for every registered effect, the plan
the look builds (`Plugin.planned`) is a frozen dataclass holding no mutable container (no
dict, list or set, no writeable array, no thunk built later), complete before any band: a
tiled render hands every band that plan in its `clfx.host.Band` and never plans again."""
import dataclasses
import functools
import types

import numpy as np
import pytest

import clfx
from clfx.core.frame import Frame
from clfx.device.runtime import DeviceImage
from clfx.host import Band, StepPlan
from clfx.pipeline.look import render_frame

from . import effects

LOOK_CAMERA = {"focal_length": 35.0, "f_number": 1.4, "focus_distance": 2.0,
               "sensor_width": 12.0, "shutter_angle": 180.0, "blades": 6}
"""The contract camera (`effects.CAMERA`) as a look's camera block."""

ROWS = 9
"""Rows per band of the tiled render: several bands on the contract frame."""


def mutable_parts(value, where: str = "plan") -> list[str]:
    """Where ``value`` (a plan) holds something that can change after it is built: a dict,
    list, set or bytearray, a writeable array, a dataclass that is not frozen, a function
    (a thunk that computes later), an object whose attributes can be set (a memo that fills
    in later); through dataclasses, tuples and read-only mappings.  Device images and
    buffers are taken as they are."""
    if isinstance(value, DeviceImage):
        return []
    if isinstance(value, (dict, list, set, bytearray)):
        return [f"{where}: {type(value).__name__}"]
    if isinstance(value, np.ndarray):
        return [f"{where}: writeable array"] if value.flags.writeable else []
    if isinstance(value, (types.FunctionType, types.MethodType, functools.partial)):
        return [f"{where}: callable {value!r}"]
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        found = [] if value.__dataclass_params__.frozen else [f"{where}: not frozen"]
        for f in dataclasses.fields(value):
            found += mutable_parts(getattr(value, f.name), f"{where}.{f.name}")
        return found
    if isinstance(value, tuple):
        return [m for i, v in enumerate(value) for m in mutable_parts(v, f"{where}[{i}]")]
    if isinstance(value, types.MappingProxyType):
        return [m for k, v in value.items() for m in mutable_parts(v, f"{where}[{k!r}]")]
    if hasattr(value, "__dict__") and not isinstance(value, type):
        return [f"{where}: {type(value).__name__} with settable attributes"]
    return []    # scalars, strings, device buffers (slots)


def test_the_check_finds_what_can_change():
    @dataclasses.dataclass(frozen=True)
    class Loose(StepPlan):
        table: object = None

    ro = np.zeros(3)
    ro.flags.writeable = False
    assert mutable_parts(Loose(table=(1, ro, types.MappingProxyType({"a": (2,)})))) == []
    class Memo:
        def __init__(self):
            self.value = None

    for bad in ({}, [1], {1}, np.zeros(3), lambda: 1, (1, {"a": 1}), Memo(),
                types.MappingProxyType({"a": [1]}), Loose(table=[1])):
        assert mutable_parts(Loose(table=bad)), bad


def one_step(name: str):
    return clfx.load_look({"name": name, "schema": 1, "camera": LOOK_CAMERA,
                           "effects": [{"effect": name,
                                        "params": effects.ACTIVE.get(name, {})}]})


def contract_frame(name: str) -> Frame:
    """The contract frame with the passes ``name`` reads."""
    return Frame.from_array(effects.scene(), **effects.passes(name, effects.SIZE))


@pytest.mark.parametrize("name", effects.EFFECTS)
def test_the_plan_is_frozen_and_made_once_before_any_band(rt, name, monkeypatch):
    cls = effects.plugin(name).__class__
    events = []     # ("plan", plan) and ("band", Band or None), in order
    real_plan, real_render = cls.plan, cls.render

    def plan(self, p, ctx):
        out = real_plan(self, p, ctx)
        events.append(("plan", out))
        return out

    def render(self, rt, p, ctx):
        events.append(("band", ctx.tiling))
        return real_render(self, rt, p, ctx)

    monkeypatch.setattr(cls, "plan", plan)
    monkeypatch.setattr(cls, "render", render)
    tiles = effects.SIZE[1] * ROWS
    _, report = render_frame(rt, one_step(name), contract_frame(name), frame_number=7,
                             tile_pixels=tiles)
    assert report.steps[0].ran, report.explain()
    plans = [e[1] for e in events if e[0] == "plan"]
    assert len(plans) == 1, f"{name}: planned {len(plans)} times in one frame"
    plan = plans[0]
    assert isinstance(plan, StepPlan) and dataclasses.is_dataclass(plan)
    found = mutable_parts(plan)
    assert not found, f"{name}: {found}"
    renders = [e[1] for e in events if e[0] == "band"]
    assert events[0][0] == "plan"        # complete before the first band
    if cls.whole_frame is None:          # it tiles: every band carries that plan
        assert len(renders) > 2 and all(isinstance(b, Band) for b in renders), name
        assert all(b.plan is plan for b in renders)
        assert all(b.whole == renders[0].whole for b in renders)
    else:
        assert renders == [None]


@pytest.mark.parametrize("name", [n for n in effects.EFFECTS
                                  if effects.plugin(n).__class__.whole_frame is None])
def test_whole_frames_of_a_batch_plan_once(rt, name, monkeypatch):
    # a batch's tile_pixels 0 (RenderOptions: whole frames) is render_frame's None: the plan
    # the step makes is the one its render reads (issue 37: every `clfx render` built
    # streaks' whole streak sum twice a frame, dof's and motion blur's tiles twice)
    cls = effects.plugin(name).__class__
    calls = []
    real_plan = cls.plan
    monkeypatch.setattr(cls, "plan", lambda self, p, ctx: calls.append(1) or real_plan(self, p, ctx))
    _, report = render_frame(rt, one_step(name), contract_frame(name), frame_number=7,
                             tile_pixels=0)
    assert report.steps[0].ran, report.explain()
    assert len(calls) == 1, f"{name}: planned {len(calls)} times in one frame"
