"""One plan per step per frame (issue 26): `Plugin.plan` is built once per step of a frame
and read by is_identity, the regions, the clamp warnings and render; the render context is
frozen and derived with `dataclasses.replace`."""
import dataclasses
from collections import Counter

import numpy as np
import pytest

import clfx
from clfx.bench.scene import synthetic_plate as cinema_frame
from clfx.core.frame import Frame
from clfx.core.rect import Rect
from clfx.host import Plugin, RenderContext, StepPlan
from clfx.pipeline.look import render_frame, tile_bands
from clfx.plugins import dof as dof_module
from clfx.plugins import get_plugin

# a rack focus (breathing), a shallow focus over a depth ramp (dof), a light (lens_flare,
# glare) and the cheap steps around them
PLANNED_LOOK = {
    "name": "planned", "schema": 1,
    "camera": {"focal_length": 50.0, "f_number": 2.0, "focus_distance": {1: 5.0, 3: 0.6},
               "breathing": 1.0, "blades": 6},
    "effects": [
        {"effect": "dof", "params": {"focus_distance": 2.0}},
        {"effect": "breathing"},
        # artistic: this small frame's physical ghosts are all wider than a tenth of its
        # diagonal, which fade into veiling glare (clfx.fx.flare.VEIL_TO): nothing would draw
        {"effect": "lens_flare", "params": {"model": "artistic"}},
        {"effect": "glare"},
        {"effect": "vignette", "params": {"amount": 0.3}},
    ]}


def scene(h=48, w=80):
    src = np.full((h, w, 4), 0.05, np.float32)
    src[..., 3] = 1.0
    src[10:13, 60:63, :3] = 2e4                         # a light near a corner
    depth = np.tile(np.linspace(0.5, 20.0, w, dtype=np.float32), (h, 1))
    return Frame.from_array(src, depth=depth)


def test_one_plan_and_one_lens_per_step_per_frame(rt, monkeypatch):
    """dof built its Lens ~12 times and its tile radii 4 times per frame; now every step
    plans once per frame (and dof builds one Lens, its radii once per window)."""
    look = clfx.load_look(PLANNED_LOOK)
    plans, lenses, radii = Counter(), Counter(), Counter()
    for name in ("dof", "breathing", "lens_flare", "glare", "vignette"):
        cls = get_plugin(name)
        real = cls.plan

        def counted(self, p, ctx, real=real, name=name):
            plans[name] += 1
            return real(self, p, ctx)
        monkeypatch.setattr(cls, "plan", counted)
    real_lens, real_radii = dof_module.Lens, dof_module.Dof._tile_radii
    monkeypatch.setattr(dof_module, "Lens",
                        lambda *a, **k: lenses.update(["dof"]) or real_lens(*a, **k))
    monkeypatch.setattr(dof_module.Dof, "_tile_radii", staticmethod(
        lambda lens, tiles, offset: radii.update([tiles.window]) or real_radii(lens, tiles, offset)))
    frames = (2, 3)
    for n in frames:
        _, report = render_frame(rt, look, scene(), frame_number=n)
        assert [s.ran for s in report.steps] == [True] * 5, report.explain()
    assert plans == {name: len(frames) for name in plans} and len(plans) == 5
    assert lenses["dof"] == len(frames)
    # the tile radii: once over the source window and once over the window dof grows to
    assert all(v == len(frames) for v in radii.values()) and len(radii) <= 2


def test_a_batch_plans_each_step_once_as_a_lone_render_does(rt, monkeypatch):
    """A batch renders with ``tile_pixels=0`` (`RenderSettings`: whole frames), a lone
    `render_frame` with None.  The step's plan was keyed on None and its render on 0, so
    every step of every batch frame planned twice: streaks built their whole streak sum
    again (issue 37: the 1080p cinema stream's streaks took 821 ms of CPU against 473
    alone).  Both now mean one whole-frame plan."""
    look = clfx.load_look(PLANNED_LOOK)
    plans = Counter()
    for name in ("dof", "breathing", "lens_flare", "glare", "vignette"):
        cls = get_plugin(name)

        def counted(self, p, ctx, real=cls.plan, name=name):
            plans[name] += 1
            return real(self, p, ctx)
        monkeypatch.setattr(cls, "plan", counted)
    whole, _ = render_frame(rt, look, scene(), frame_number=2)
    batch, _ = render_frame(rt, look, scene(), frame_number=2, tile_pixels=0)
    assert plans == {name: 2 for name in plans} and len(plans) == 5
    assert np.array_equal(whole.rgba, batch.rgba)


def test_dof_finds_the_lattice_level_of_its_largest_radius_once_per_step(rt, monkeypatch):
    """The lattice level of a gather's largest radius sets the padding, the prefilter
    pyramid's depth and the reach of the regions; the regions and the render each computed
    it (three times a frame); now it is the step plan's, once per window and channel offset
    (`Dof.gather_levels`).  Counted: every call but the tap tables' and the per-tile levels'."""
    import sys

    calls = []
    real = dof_module.lattice_level

    def counted(radius, lattice, dense):
        caller = sys._getframe(1).f_code.co_name
        if caller not in ("tap_table", "lattice_levels"):
            calls.append(caller)
        return real(radius, lattice, dense)

    monkeypatch.setattr(dof_module, "lattice_level", counted)
    look = clfx.load_look({"name": "d", "schema": 1, "camera": {"f_number": 1.4},
                           "effects": [{"effect": "dof", "params": {"focus_distance": 1.0}}]})
    out, report = render_frame(rt, look, scene(), frame_number=1)
    assert report.steps[0].ran and np.isfinite(out.rgba).all()
    # once over the source window and once over the window dof grows to (as the radii)
    assert set(calls) == {"gather_levels"} and len(calls) <= 2, calls


def test_dof_bands_derive_nothing_frame_wide_again(rt, monkeypatch):
    """A tiled dof renders its bands from the frame's plan: the tile radii, the lattice
    levels (the largest's and every tile's) and the tap tables are derived as often as in a
    whole render (the review found the per-tile lattice levels recomputed per band)."""
    look = clfx.load_look({"name": "d", "schema": 1, "camera": {"f_number": 1.4},
                           "effects": [{"effect": "dof", "params": {"focus_distance": 1.0}}]})
    calls = Counter()
    for name in ("lattice_level", "quantised_radius", "dilate_tiles"):
        real = getattr(dof_module, name)
        monkeypatch.setattr(dof_module, name, lambda *a, real=real, name=name:
                            calls.update([name]) or real(*a))
    real_tables = dof_module.Dof.tap_tables
    monkeypatch.setattr(dof_module.Dof, "tap_tables", lambda self, *a, **k:
                        calls.update(["tap_tables"]) or real_tables(self, *a, **k))
    counts = []
    for tiles in (None, 80 * 6):
        calls.clear()
        out, report = render_frame(rt, look, scene(), frame_number=1, tile_pixels=tiles)
        assert report.steps[0].ran
        counts.append((dict(calls), out.rgba))
    assert counts[0][0] == counts[1][0] and counts[0][0]["tap_tables"] >= 1
    assert np.array_equal(counts[0][1].view(np.uint32), counts[1][1].view(np.uint32))


def test_plans_are_per_step_and_per_source(rt):
    """A step's contexts share its plan (derived with `over`, `grown_to`); a new step
    (`for_step`) or another source (`with_source`) plans afresh."""
    built = []

    class Counting(Plugin):
        descriptor = get_plugin("vignette").descriptor

        def plan(self, p, ctx):
            built.append(ctx.source.window)
            return StepPlan()

    fx, p = Counting(), get_plugin("vignette").params()
    ctx = RenderContext(rt, rt.upload(np.ones((8, 8, 4), np.float32))).for_step("final")
    first = fx.planned(p, ctx)
    assert fx.planned(p, ctx.over(frame=3)) is first
    assert fx.planned(p, ctx.grown_to(Rect(-2, -2, 10, 10))) is first
    assert fx.planned(get_plugin("vignette").params(amount=0.5), ctx) is not first
    assert fx.planned(p, ctx.for_step("final")) is not first
    assert fx.planned(p, ctx.with_source(rt.upload(np.zeros((8, 8, 4), np.float32)))) is not first
    assert len(built) == 4


def test_render_context_is_frozen_and_derived_with_replace(rt):
    ctx = RenderContext(rt, rt.upload(np.ones((8, 8, 4), np.float32)), frame=4, quality="draft")
    with pytest.raises(dataclasses.FrozenInstanceError):
        ctx.source = None
    step = ctx.for_step("final")
    assert (step.quality, step.frame, ctx.quality) == ("final", 4, "draft")
    assert step.notes is not ctx.notes and step.shared is ctx.shared
    same = dataclasses.replace(step, seed=7)
    assert same.notes is step.notes and same.plans is step.plans and same.seed == 7
    assert same.display_window == ctx.display_window == Rect(0, 0, 8, 8)


def test_a_bad_lens_name_fails_at_look_load_in_one_line(tmp_path):
    """Lenses are read and validated when the look is loaded (`clfx.io.lenses`): a bad
    name is one line naming the file and the key, before any frame is read."""
    from clfx.core.errors import PresetError
    from clfx.pipeline.presets import apply_overrides, load_look, look_from_dict

    path = tmp_path / "flare.yaml"
    path.write_text("name: flare\neffects:\n  - effect: lens_flare\n"
                    "    params: {lens: zoom-80-20, model: physical}\n")
    with pytest.raises(PresetError) as err:
        load_look(str(path))
    line = str(err.value)
    assert "\n" not in line and line.startswith(f"{path}: lens_flare.lens: unknown lens 'zoom-80-20'")
    assert "did you mean 'zoom-80-200mm'" in line
    with pytest.raises(PresetError, match=r"^look: lens\.model: lens: no lens 'Nope 1mm'"):
        look_from_dict({"name": "x", "effects": [{"effect": "lens", "params": {"model": "Nope 1mm"}}]})
    with pytest.raises(PresetError, match=r"^lens_flare\.lens: lens file /no/such\.yaml does not exist"):
        apply_overrides(load_look("sunny-flare"), ["lens_flare.lens=/no/such.yaml"])
    # artistic flares and disabled steps name no lens
    look_from_dict({"name": "x", "effects": [
        {"effect": "lens_flare", "params": {"lens": "nope", "model": "artistic"}},
        {"effect": "lens", "params": {"model": "Nope 1mm"}, "enabled": False}]})


def test_set_reads_only_the_lenses_it_names(monkeypatch):
    """--set resolves the look's lenses again (a lens it names is checked before any frame),
    taking those read when the look was loaded from them: each prescription is read once."""
    from clfx.io import lenses as lens_io
    from clfx.pipeline.presets import apply_overrides, load_look

    reads, real = [], lens_io.read_lens
    monkeypatch.setattr(lens_io, "read_lens", lambda name: reads.append(name) or real(name))
    look = load_look("sunny-flare")
    apply_overrides(look, ["corona.intensity=0.2"])
    assert reads == ["zoom-80-200mm"]
    apply_overrides(look, ["lens_flare.lens=double-gauss-50mm"])
    assert reads == ["zoom-80-200mm", "double-gauss-50mm"]
    assert set(look.lenses.prescriptions) == {"double-gauss-50mm"}


def test_the_files_a_batch_protects_are_the_lenses_its_steps_read():
    """`lens_files` lists what `Plugin.lens_refs` names (the lenses the render reads): a
    physical flare's prescription; not an artistic flare's unused ``lens``, nor a disabled
    step's, nor the ``lens`` effect's lensfun name (no file)."""
    from clfx.pipeline.preflight import lens_files
    from clfx.pipeline.presets import find_lens, look_from_dict

    look = look_from_dict({"name": "x", "effects": [
        {"id": "a", "effect": "lens_flare", "params": {"lens": "zoom-80-200mm", "model": "artistic"}},
        {"id": "p", "effect": "lens_flare", "params": {"lens": "double-gauss-50mm", "model": "physical"}},
        {"id": "off", "effect": "lens_flare", "params": {"lens": "zoom-80-200mm", "model": "physical"},
         "enabled": False}]})
    assert lens_files(look) == [("p.lens", str(find_lens("double-gauss-50mm")))]


def test_a_loaded_look_renders_from_the_lenses_it_resolved(rt, monkeypatch):
    """A render reads the prescriptions resolved at load, never a file."""
    from clfx.io import lenses as lens_io
    from clfx.pipeline.presets import load_look

    look = load_look("sunny-flare")
    assert set(look.lenses.prescriptions) == {"zoom-80-200mm"}
    monkeypatch.setattr(lens_io, "read_lens", lambda name: pytest.fail(f"read {name} late"))
    _, report = render_frame(rt, look, scene(), frame_number=1)
    assert report.steps[0].ran


@pytest.mark.parametrize("overscan", [0, 12])
def test_cinema_renders_tiled_with_the_pixels_of_a_whole_render(rt, overscan):
    """The cinema look with its tiling steps in bands of 64 rows: bit-identical to the
    whole frame (the steps that cannot tile run whole: `Plugin.whole_frame`).  With
    ``overscan`` pixels of data window past the display window on every side, a warp's
    canvas and region of definition in a band are the whole render's
    (`clfx.kit.warp.whole_context`: with the band's own instead, the overscan frame's pixels
    differ; the frame without overscan, and the 32-band test's, keep them).  Every warp at
    every border and window: tests/contract/test_tiles.py."""
    look = clfx.load_look("cinema")
    frame = cinema_frame(480 + 2 * overscan, 270 + 2 * overscan)
    frame = dataclasses.replace(frame, data_window=Rect(-overscan, -overscan, 480 + overscan,
                                                        270 + overscan),
                                display_window=Rect.from_size(480, 270))
    whole, _ = render_frame(rt, look, frame, frame_number=5, tile_pixels=None)
    tiled, _ = render_frame(rt, look, frame, frame_number=5, tile_pixels=480 * 64)
    assert whole.data_window == tiled.data_window
    assert np.array_equal(whole.rgba.view(np.uint32), tiled.rgba.view(np.uint32))


@pytest.mark.slow
def test_4k_renders_tiled_in_32_bands_bit_identical(rt, monkeypatch):
    """A 4K UHD render in 32 bands, at a quarter of its pixels: every step of cinema but glare
    (which convolves in capped blocks instead: `clfx.fx.fftconv.convolve_blocks`) tiles;
    its resampling and grain steps (chromatic aberration, distortion, vignette, grain)
    rendered in 32 bands give the same bits as whole frames.

    The frame is 1920x1080 with everything that scales with the frame scaled with it, so the
    render is 4K's (3840x2160, bands of 2^18 pixels) in every count: 32 bands of 2^16 pixels
    (34 rows, the last 26; 4K: 68, the last 52), the whole render's maps built in 32 bands
    (`clfx.fx.resample.BAND_PIXELS` 2^16 here, 2^18 there) and each band's map in one, the
    pool's byte cap a quarter of the runtime's, as the frame's bytes are.  Sizes and
    displacements are fractions of the frame; the rows a band reads past its band do not
    grow with it (with its region of interest ignored, 2 rows fail and 4 pass at 480x270
    and 1920x1080; 2 fail at 3840x2160).  This ran at 8K, then 4K (45 s); 1080p: ~9 s.
    dof, motion blur and streaks at 8K, whole against tiled, took ~250 s of this 2-core
    machine's time a run, so CI checks them in 7-row bands at every level and frame layout
    (tests/contract/test_tiles.py) and streaks' row rings forced on small frames, with their
    8K memory plan (tests/plugins/test_streaks.py); the whole look at 4K and 8K, its bits and
    its peaks, is scripts/tile_8k.py's.  With CLFX_POOL_MB=64 vignette + grain's device peak
    at 8K fell from 2065 to 1118 MiB."""
    from clfx.fx import resample

    look = clfx.load_look("cinema")
    tiling = [s.effect for s in look.steps if s.plugin.whole_frame is None]
    assert tiling == ["dof", "motion_blur", "streaks", "chromatic_aberration", "distortion",
                      "vignette", "grain"]
    look = dataclasses.replace(look, steps=[s for s in look.steps if s.effect in tiling[3:]])
    scale = 2                                     # of each side: 3840x2160 / 2
    w, h, band = 3840 // scale, 2160 // scale, (1 << 18) // scale ** 2
    monkeypatch.setattr(resample, "BAND_PIXELS", resample.BAND_PIXELS // scale ** 2)
    monkeypatch.setattr(rt.cache, "max_bytes", rt.cache.max_bytes // scale ** 2)
    assert len(tile_bands(Rect.from_size(w, h), band)) == 32
    assert len(resample.map_bands(h, w)) == 32
    whole, _ = render_frame(rt, look, cinema_frame(w, h), frame_number=5)
    tiled, report = render_frame(rt, look, cinema_frame(w, h), frame_number=5,
                                 tile_pixels=band)
    assert all(s.ran for s in report.steps)
    assert np.array_equal(whole.rgba.view(np.uint32), tiled.rgba.view(np.uint32))


def test_a_grown_window_carries_both_halves_of_the_vector_pass(rt):
    # dof grows the window before motion_blur in cinema: the backward half of the vector
    # pass was left at the old window, so motion_blur silently fell back to one half
    from clfx.core.rect import Rect
    from clfx.pipeline.look import _advance

    win = Rect(10, 10, 26, 22)
    vel = np.full((12, 16, 2), 1.5, np.float32)
    ctx = RenderContext(rt, rt.upload(np.ones((12, 16, 4), np.float32), win),
                        velocity=rt.upload(vel, win), velocity_back=rt.upload(-vel, win))
    grown = rt.image(win.grown(3), 4)
    after = _advance(rt, ctx, grown)
    assert after.velocity.window == after.velocity_back.window == grown.window
    back = rt.download(after.velocity_back)
    assert np.array_equal(back, np.full(back.shape, -1.5, np.float32))   # edge-clamped
