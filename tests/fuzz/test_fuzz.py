"""Every effect (draft and final, at its defaults and at the contract's active parameters)
and every built-in look over OpenEXR's unusual-value images: the output is finite wherever
the input was, and sanitised (finite) where it was not (issue 10 item 6).

Frames are read by ``clfx.io.read.read_frame`` and rendered by
``clfx.pipeline.look.render_frame``, as ``clfx apply`` / ``clfx render`` do; effects and
looks that read depth or velocity get the contract's synthetic passes.
"""
import numpy as np
import pytest

from clfx.core.frame import Frame
from clfx.pipeline.look import Look, Step, render_frame
from clfx.pipeline.presets import available_looks, load_look
from tests.contract import effects as E
from tests.contract.known import param
from tests.fuzz import images

pytestmark = [pytest.mark.fuzz, pytest.mark.slow]

QUALITIES = ("draft", "final")
NO_DEFAULTS = {"lens": "its defaults name no lens model (a clean ParamError)"}
"""Effects whose default parameters cannot render, with why."""

BUILTIN_LOOKS = sorted(n for n, (origin, _) in available_looks().items() if origin == "built-in")


def settings(name: str) -> list[str]:
    """``default`` (what ``clfx apply EFFECT`` renders) and, where it differs, ``active``."""
    return [s for s in ("default", "active")
            if (s == "default" and name not in NO_DEFAULTS) or (s == "active" and name in E.ACTIVE)]


def inputs(test: str, cases: list[tuple]) -> list:
    """``cases`` x every input image, with known-bug marks; one skip without the images."""
    found = images.variants()
    if not found:
        return [pytest.param(*(None,) * (len(cases[0]) + 1),
                             marks=pytest.mark.skip(reason=f"{images.FOLDER} not found"))]
    return [param(test, *case, img, id="-".join(case + (img,))) for case in cases
            for img in found]


def frame_for(img: str, clips: set[str]) -> Frame:
    rgba = images.image(img)
    make = {"depth": E.depth_pass, "velocity": E.velocity_pass}
    return Frame.from_array(rgba, **{c: make[c](rgba.shape[:2]) for c in clips if c in make})


def check(src: Frame, out: Frame, what: str):
    assert out.rgba.shape == src.rgba.shape, what
    bad = ~np.isfinite(out.rgba).all(axis=2)
    if bad.any():
        was = ~np.isfinite(src.rgba).all(axis=2)
        pytest.fail(f"{what}: {int((bad & ~was).sum())} non-finite output pixels where the "
                    f"input was finite, {int((bad & was).sum())} kept from non-finite input "
                    f"(of {int(was.sum())})")


@pytest.mark.parametrize("name,setting,quality,img", inputs(
    "test_effect_output_is_finite",
    [(n, s, q) for n in E.EFFECTS for s in settings(n) for q in QUALITIES]))
def test_effect_output_is_finite(rt, name, setting, quality, img):
    p = E.params(name) if setting == "active" else E.discover()[name].params()
    look = Look(name=f"fuzz-{name}", camera=E.CAMERA, steps=[Step(name, p)])
    src = frame_for(img, E.clip_names(name))
    out, report = render_frame(rt, look, src, frame_number=3, quality=quality)
    ran = report.steps[0].reason or "ran"
    check(src, out, f"{name} ({setting}, {quality}) on {img} [{ran}]")


@pytest.mark.parametrize("look_name,img", inputs(
    "test_look_output_is_finite", [(n,) for n in BUILTIN_LOOKS]))
def test_look_output_is_finite(rt, look_name, img):
    look = load_look(look_name)
    src = frame_for(img, look.clips_used())
    out, report = render_frame(rt, look, src, frame_number=3)
    steps = ", ".join(f"{s.effect}: {s.reason or 'ran'}" for s in report.steps)
    check(src, out, f"look {look_name} on {img} [{steps}]")
