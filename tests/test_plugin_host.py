"""The plugin host: registry, parameter validation, look rendering on the device."""
import numpy as np
import pytest

from clfx.core.camera import Camera
from clfx.core.errors import ClipError, ParamError
from clfx.core.frame import Frame
from clfx.pipeline.look import Look, Step, render_frame
from clfx.core.plugin import (QUALITY_LEVELS, BoolParam, Level, ChoiceParam, FloatParam, IntParam, RGBParam,
                         Vec2Param)
from clfx.plugins import discover, get_plugin
from clfx.core.rect import Rect
from tests.effects import render_effect


def test_every_plugin_descriptor_is_complete():
    reg = discover()
    assert "vignette" in reg
    for name, cls in reg.items():
        d = cls.descriptor.describe()
        assert d["name"] == name and d["kernel"].endswith(".cl")
        assert set(d["quality"]) == set(QUALITY_LEVELS) and all(d["quality"].values())
        for p in d["params"]:
            assert p["hint"], f"{name}.{p['name']} has no hint"


def test_every_plugin_has_its_kernel_file_shipped():
    from clfx.device.runtime import kernel_dir

    for cls in discover().values():
        assert (kernel_dir() / cls.descriptor.kernel).is_file()


def test_unknown_effect_suggests_closest():
    with pytest.raises(ParamError, match="did you mean 'vignette'"):
        get_plugin("vignete")


@pytest.mark.parametrize("param, good, bad", [
    (FloatParam("x", 0.5, min=0.0, max=1.0, hint="h"), 1, 1.5),
    (IntParam("n", 3, min=1, max=8, hint="h"), 8, 9),
    (BoolParam("b", True, hint="h"), False, 1),
    (ChoiceParam("c", "a", choices=("a", "b"), hint="h"), "b", "z"),
    (RGBParam("t", (1.0, 1.0, 1.0), hint="h"), [0.5, 1, 2], [1, -1, 0]),
    (Vec2Param("v", (0.0, 0.0), min=-1, max=1, hint="h"), (0.5, -0.5), (2, 0)),
])
def test_param_validation(param, good, bad):
    param.validate(good)
    with pytest.raises(ParamError):
        param.validate(bad)


def test_params_reject_unknown_names_and_out_of_range():
    cls = get_plugin("vignette")
    with pytest.raises(ParamError, match="did you mean 'amount'"):
        cls.params(amout=0.3)
    with pytest.raises(ParamError, match=r"outside the allowed range \[-1, 1\]"):
        cls.params(amount=3.0)
    with pytest.raises(ParamError, match="not a number"):
        cls.params(amount="lots")


def test_look_renders_with_one_upload_and_one_download(rt, rng, monkeypatch):
    src = rng.uniform(0, 4, (20, 30, 4)).astype(np.float32)
    frame = Frame.from_array(src)
    cls = get_plugin("vignette")
    look = Look("two", steps=[Step("vignette", cls.params(amount=0.3)),
                              Step("vignette", cls.params(amount=0.0, natural=0.0)),
                              Step("vignette", cls.params(amount=0.2, natural=0.5))])
    calls = {"upload": 0, "download": 0}
    up, down = rt.upload, rt.download
    monkeypatch.setattr(rt, "upload", lambda *a, **k: calls.__setitem__("upload", calls["upload"] + 1) or up(*a, **k))
    monkeypatch.setattr(rt, "download", lambda *a, **k: calls.__setitem__("download", calls["download"] + 1) or down(*a, **k))
    out, report = render_frame(rt, look, frame, frame_number=7)
    assert calls == {"upload": 1, "download": 1}
    assert [s.ran for s in report.steps] == [True, False, True]
    assert report.steps[1].reason == "natural and amount are 0"
    one = render_effect(rt, cls(), cls.params(amount=0.3), src)
    two = render_effect(rt, cls(), cls.params(amount=0.2, natural=0.5), one)
    np.testing.assert_allclose(out.rgba, two, rtol=1e-6)
    assert out.metadata["clfx:look"] == "two" and len(out.metadata["clfx:paramsHash"]) == 16


def test_look_keeps_windows(rt, rng):
    src = rng.uniform(0, 1, (10, 12, 4)).astype(np.float32)
    frame = Frame(src, Rect(5, 6, 17, 16), Rect(0, 0, 40, 30), pixel_aspect=1.5)
    look = Look("v", steps=[Step("vignette", get_plugin("vignette").params(amount=0.5))])
    out, _ = render_frame(rt, look, frame)
    assert out.data_window == frame.data_window and out.display_window == frame.display_window
    assert out.pixel_aspect == 1.5


def test_missing_required_pass_is_reported_before_rendering(rt):
    from clfx.core.plugin import Clip, Descriptor
    from clfx.host import Plugin

    class NeedsDepth(Plugin):
        descriptor = Descriptor(name="needs_depth", label="x", group="t", summary="x",
                                kernel="lib/image.cl", clips=(Clip("source"), Clip("depth")),
                                quality={q: Level("x") for q in QUALITY_LEVELS})

    look = Look("d", steps=[Step("needs_depth", NeedsDepth.params(), plugin=NeedsDepth())])
    frame = Frame.from_array(np.zeros((4, 4, 4), np.float32))
    frame.source = "shot.0001.exr"
    with pytest.raises(ClipError, match="shot.0001.exr.*needs a depth pass"):
        render_frame(rt, look, frame)


def test_params_hash_changes_with_params_and_camera():
    cls = get_plugin("vignette")
    a = Look("a", steps=[Step("vignette", cls.params(amount=0.3))])
    b = Look("a", steps=[Step("vignette", cls.params(amount=0.4))])
    c = Look("a", camera=Camera(focal_length=50), steps=[Step("vignette", cls.params(amount=0.3))])
    assert len({a.params_hash(), b.params_hash(), c.params_hash()}) == 3


def test_step_that_skips_missing_passes_reports_why(rt, rng):
    from clfx.core.errors import ClipError

    frame = Frame.from_array(rng.uniform(0, 1, (16, 16, 4)).astype(np.float32))
    dof = get_plugin("dof")
    strict = Look("strict", steps=[Step("dof", dof.params())])
    with pytest.raises(ClipError, match="needs a depth pass"):
        render_frame(rt, strict, frame)
    lenient = Look("lenient", steps=[Step("dof", dof.params(), missing_passes="skip"),
                                     Step("vignette", get_plugin("vignette").params(amount=0.2))])
    _, report = render_frame(rt, lenient, frame)
    assert report.steps[0].reason == "no depth pass in the input" and report.steps[1].ran


def test_analysis_always_covers_the_current_source_window(rt):
    from clfx.host import RenderContext

    src = rt.upload(np.zeros((8, 8, 4), np.float32))
    ctx = RenderContext(rt, src)
    first = ctx.analysis
    assert ctx.analysis is first  # computed once
    grown = np.zeros((12, 16, 4), np.float32)
    grown[0, 0, :3] = 50.0
    ctx = ctx.over(source=rt.upload(grown, Rect(-4, -2, 12, 10)))  # an effect grew the window
    assert ctx.analysis.window == Rect(-4, -2, 12, 10)
    assert ctx.analysis.peak_luminance == pytest.approx(50.0, rel=4e-7)  # float32 luminance


def test_passes_no_step_reads_are_not_uploaded(rt, rng, monkeypatch):
    src = rng.uniform(0, 1, (8, 12, 4)).astype(np.float32)
    frame = Frame.from_array(src, depth=np.ones((8, 12), np.float32),
                             velocity=np.zeros((8, 12, 2), np.float32))
    look = Look("v", steps=[Step("vignette", get_plugin("vignette").params(amount=0.2))])
    uploads = []
    up = rt.upload
    monkeypatch.setattr(rt, "upload", lambda a, *k, **kw: uploads.append(a.shape) or up(a, *k, **kw))
    out, _ = render_frame(rt, look, frame)
    assert uploads == [(8, 12, 4)]
    assert out.depth is not None and out.velocity is not None  # still written with the output


def test_steps_are_configuration_and_runs_keep_their_own_stats(rt):
    """A Step is frozen configuration; the running costs that estimate what skipping saved
    live in the RunStats the caller owns (issue 9)."""
    import dataclasses

    from clfx.pipeline.look import RunStats

    glare = Step("glare", get_plugin("glare").params())
    with pytest.raises(dataclasses.FrozenInstanceError):
        glare.quality = "draft"
    look = Look("g", steps=[glare])
    hot = np.zeros((24, 24, 4), np.float32)
    hot[..., 3] = 1.0
    hot[12, 12, :3] = 1e4
    dark = np.full((24, 24, 4), 0.1, np.float32)
    stats = RunStats()
    _, first = render_frame(rt, look, Frame.from_array(hot), stats=stats)
    _, second = render_frame(rt, look, Frame.from_array(dark), stats=stats)
    assert first.steps[0].ran and not second.steps[0].ran
    assert stats.timing(0).runs == 1 and second.saved_ms == pytest.approx(first.steps[0].ms)
    assert look.steps == [glare]  # rendering changed nothing in the look
    _, alone = render_frame(rt, look, Frame.from_array(dark))  # no stats: nothing to estimate
    assert alone.saved_ms == 0.0


def test_disabled_steps_never_run_nor_require_passes(rt, rng):
    frame = Frame.from_array(rng.uniform(0, 1, (8, 8, 4)).astype(np.float32))
    look = Look("d", steps=[Step("dof", get_plugin("dof").params(), enabled=False),
                            Step("vignette", get_plugin("vignette").params(amount=0.2))])
    assert look.required_clips() == {} and "depth" not in look.clips_used()
    _, report = render_frame(rt, look, frame)
    assert [s.effect for s in report.steps] == ["vignette"]


def test_per_step_contexts_share_the_frame_analysis(rt):
    """RenderContext.for_step: a step's context with its own quality and notes; an analysis
    it computes is the frame's (no reaching into another context's private state)."""
    from clfx.host import RenderContext

    ctx = RenderContext(rt, rt.upload(np.ones((8, 8, 4), np.float32)))
    step = ctx.for_step("draft")
    assert step.quality == "draft" and ctx.quality != "draft"
    step.notes.append("x")
    assert ctx.notes == []
    computed = step.analysis
    assert ctx.analysis is computed and ctx.for_step("final").analysis is computed
    assert ctx.analysis_seconds == pytest.approx(computed.seconds)


def test_setting_a_param_says_how_to_make_new_ones():
    from clfx.plugins import discover

    glare = discover()["glare"]
    p = glare.params(strength=0.1)
    with pytest.raises(AttributeError) as err:
        p.strength = 0.2
    said = str(err.value)
    assert "immutable" in said and "params(strength=" in said
    # what it says works, and validates
    assert glare.params(strength=0.2).strength == 0.2
    with pytest.raises(ParamError):
        glare.params(strength=-1.0)
