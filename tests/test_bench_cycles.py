"""The motion effects (issue 24) and depth of field (issue 35) against Blender Cycles' own
renders (clfx.bench.cycles).

The renders are checked in (clfx/bench/cycles/data, made by render_scenes.py with bpy and
packed by pack.py): these tests need neither Blender nor a render, only the files.
"""
from __future__ import annotations

import numpy as np
import pytest

from clfx.bench import cases, cycles
from clfx.bench.cases.shared import case_context
from clfx.bench.metrics import EDGE_BAND_PX, edge_band, error_metrics
from clfx.core.frame import crop_to
from clfx.plugins import get_plugin

MOTION = [(e, v) for e in ("motion_blur", "camera_blur", "rolling_shutter")
          for v in cases.for_effect(e).variants if v.startswith("cycles_")]

DOF = [v for v in cases.for_effect("dof").variants if v.startswith("cycles_")]

DATA_BUDGET = 3_500_000
"""Bytes of every checked-in render together (3.3 MB: 320x180 lossless half float of
textured scenes; see clfx/bench/cycles/__init__.py)."""


def _have(name):
    if not cycles.available(name):
        pytest.skip(f"no Cycles data for {name} under {cycles.DATA}")


def test_cycles_data_is_small_and_read_as_blender_writes_it():
    _have("spin")
    assert sum(p.stat().st_size for p in cycles.data_files()) < DATA_BUDGET
    d = cycles.load("spin")
    h, w = cycles.HEIGHT, cycles.WIDTH
    assert d["source"].shape == (h, w, 4) and d["truth"].shape == (h, w, 4)
    # Blender's Vector pass has both halves: clfx reads ZW as forward, XY as backward.
    assert d["velocity"] is not None and d["velocity_back"] is not None
    assert np.all(np.isfinite(d["depth"])) and float(d["depth"].min()) > 0
    speed = np.hypot(*np.moveaxis(d["velocity"], -1, 0))
    assert speed.max() > 40.0          # the wheel's rim at 72 deg/frame
    # The two halves differ on the spinning wheel (a curve, not a line).
    assert float(np.abs(d["velocity"] - d["velocity_back"]).max()) > 10.0
    assert cycles.noise_floor("spin") is not None


def test_cycles_references_are_read_through_clfx_io_as_stored(rt):
    """The references are read by `clfx.io.read.read_channels` (grouped into layers) and the
    noise floor by `header_attribute`: the same numbers as OpenImageIO's own read of the
    file, channel for channel."""
    import OpenImageIO as oiio

    from clfx.io.probe import header_attribute

    _have("spin")
    _, ref = cycles.files("spin")
    inp = oiio.ImageInput.open(str(ref))
    spec = inp.spec()
    direct = inp.read_image(0, 0, 0, spec.nchannels, "float")
    names = list(spec.channelnames)
    inp.close()
    layers = cycles.read_layers(ref)
    assert sorted(layers) == sorted({n.rpartition(".")[0] for n in names})
    for layer, planes in layers.items():
        idx = [i for i, n in enumerate(names) if n.rpartition(".")[0] == layer]
        assert planes.dtype == np.float32 and np.array_equal(planes, direct[..., idx])
    floor = spec.getattribute(cycles.FLOOR_ATTRIBUTE)
    assert header_attribute(ref, cycles.FLOOR_ATTRIBUTE) == floor
    assert cycles.noise_floor("spin") == float(floor)


def _score(rt, effect, variant, quality="final"):
    spec = cases.for_effect(effect)
    case = spec.maker(variant)(cycles.WIDTH, cycles.HEIGHT, None)
    cls = get_plugin(effect)
    params = cls.params(**case.get("params", {}))
    ctx = case_context(rt, case, quality)
    img = cls().render(rt, params, ctx)
    out = crop_to(rt.download(img), img.window, ctx.source.window)
    truth = np.asarray(case["truth"], np.float64)
    scores = {"final": error_metrics(out, truth)["psnr_log"],
              "input": error_metrics(case["source"], truth)["psnr_log"]}
    if spec.naive is not None:
        naive = np.asarray(spec.naive.make(case, params, case_context(rt, case, "final"))())
        scores["naive"] = error_metrics(naive, truth)["psnr_log"]
    for label, peer in (case.get("peer_images") or {}).items():
        scores[label] = error_metrics(peer, truth)["psnr_log"]
    return scores, case.get("truth_floor")


@pytest.mark.parametrize("effect,variant", MOTION, ids=[f"{e}:{v}" for e, v in MOTION])
def test_final_beats_input_naive_and_blender_on_cycles_renders(rt, effect, variant):
    """Issue 24's "done when": on Cycles' own motion-blurred renders, ``final`` scores above
    the unchanged input, the naive line blur and Blender's Vector Blur, and the truth's
    noise floor lies above every score (the comparison is not lost in the truth's noise)."""
    scores, floor = _score(rt, effect, variant)
    mine = scores.pop("final")
    for what, theirs in scores.items():
        assert mine > theirs, f"{effect}:{variant}: final {mine:.2f} dB <= {what} {theirs:.2f} dB"
    if floor is not None:
        assert floor > mine, f"{effect}:{variant}: noise floor {floor:.1f} dB <= final {mine:.1f}"


# The spin scene's rim light (render_scenes.scene_spin): the wheel's centre 75 px left of and
# 10 px above the frame centre, the light 0.84 of the wheel's 55 px radius above it at the
# frame time, turning 72 deg/frame (36 degrees inside the centred 180 degree shutter).
RIM_CENTRE = (cycles.WIDTH / 2 - 75.0, cycles.HEIGHT / 2 - 10.0)
RIM_RADIUS = 0.84 * 55.0


def _streak_offsets(img, half_width=12):
    """Per column over the middle of the rim light's streak: the light's centroid (rows
    within 8 px of the arc, weighted by luminance above 1) minus the true arc's height."""
    cx, cy = RIM_CENTRE
    lum = np.asarray(img)[..., :3].mean(-1)
    out = []
    for x in range(int(cx) - half_width, int(cx) + half_width):
        arc = cy - np.sqrt(RIM_RADIUS ** 2 - (x + 0.5 - cx) ** 2)
        rows = np.arange(int(arc) - 8, int(arc) + 9)
        w = np.clip(lum[rows, x] - 1.0, 0.0, None)
        out.append(float((w * (rows + 0.5)).sum() / w.sum() - arc))
    return np.array(out)


def test_rotating_light_streak_follows_its_arc_on_a_cycles_render(rt):
    """Issue 24: a light on a wheel turning 72 deg/frame streaks along its arc.  Its centre
    line in Cycles' render lies within 0.24 px of the arc (the geometry is right); clfx's
    within 1 px (0.32 with the arc paths, 1.12 with the quadratic through the same three
    positions, whose ends fall short and inside); Blender's Vector Blur follows the chord
    (6-8 px off, its ends short)."""
    _have("spin")
    d = cycles.load("spin")
    assert np.abs(_streak_offsets(d["truth"])).max() < 0.5
    spec = cases.for_effect("motion_blur")
    case = spec.maker("cycles_spin")(cycles.WIDTH, cycles.HEIGHT, None)
    cls = get_plugin("motion_blur")
    ctx = case_context(rt, case, "final")
    img = cls().render(rt, cls.params(), ctx)
    out = crop_to(rt.download(img), img.window, ctx.source.window)
    assert np.abs(_streak_offsets(out)).max() < 1.0
    assert np.nanmax(np.abs(_streak_offsets(d["vector_blur"]))) > 3.0   # (nan: no light)


def test_cycles_dof_scene_is_read_as_blender_writes_it():
    """The dof scene's input is the pinhole frame with Blender's Depth pass read as planar z
    (the wall facing the camera reads 12 m in the corners too, where the distance along the
    ray is 6 cm longer), no Vector pass, and clfx's CoC of those depths has the scene's
    radii and signs: the wall +41 px behind the focus plane, the near post -40 px in front."""
    _have("dof_large")
    d = cycles.load("dof_large")
    assert d["velocity"] is None and d["velocity_back"] is None
    z = np.asarray(d["depth"], np.float64)
    wall = np.abs(z - 12.0) < 0.2
    for y, x in ((0, 0), (0, -1), (-1, 0), (-1, -1), (2, 200)):
        assert wall[y, x], (y, x, z[y, x])
        assert abs(z[y, x] - 12.0) < 1e-3, (y, x, z[y, x])
    cam = cycles.dof_camera()
    r = 0.5 * cam.coc_signed_px(z, cycles.WIDTH)
    assert abs(float(np.median(r[wall])) - 41.15) < 0.05
    post = np.abs(z - 1.1) < 0.01       # the near post, 64 px left of the centre
    assert post[:, 96].all() and abs(float(r[post].mean()) + 40.40) < 0.05
    assert float(r[np.abs(z - 2.0) < 0.01].std()) < 0.5      # the subject: in focus
    assert "Blender Defocus" in " ".join(d["peers"])


@pytest.mark.parametrize("variant", DOF, ids=[f"dof:{v}" for v in DOF])
def test_every_dof_level_beats_naive_and_input_on_cycles_thin_lens(rt, variant):
    """Issue 35: circles of confusion of 27-41 px over each other, Cycles' thin lens as the
    truth: every level scores above the unchanged input and >= 1 dB above the naive
    per-pixel-CoC gather (log-PSNR, and edge-band RMSE in dB), final's relative error is
    within 5 % of reference's, and the truth's noise floor lies above every level.  Before
    (a half-resolution tile's edge pixels upsampled the unblurred lamps of the tile beside
    it): +0.7 dB over naive at draft to final, final's error 20 % above reference's."""
    spec = cases.for_effect("dof")
    case = spec.maker(variant)(cycles.WIDTH, cycles.HEIGHT, None)
    cls = get_plugin("dof")
    params = cls.params(**case.get("params", {}))
    truth = np.asarray(case["truth"], np.float64)
    edge = edge_band(case["depth"], None, EDGE_BAND_PX)
    naive = error_metrics(np.asarray(spec.naive.make(case, params,
                                                     case_context(rt, case, "final"))()),
                          truth, edge)
    theirs = {"naive": naive["psnr_log"] + 1.0,
              "input": error_metrics(case["source"], truth)["psnr_log"]}
    floor = case["truth_floor"]
    rel = {}
    for q in ("draft", "preview", "final", "reference"):
        ctx = case_context(rt, case, q)
        img = cls().render(rt, params, ctx)
        m = error_metrics(crop_to(rt.download(img), img.window, ctx.source.window), truth, edge)
        mine, rel[q] = m["psnr_log"], m["rel_rmse"]
        for what, score in theirs.items():
            assert mine > score, f"dof:{variant} {q}: {mine:.2f} dB <= {what} {score:.2f} dB"
        assert 20 * np.log10(naive["edge_rmse"] / m["edge_rmse"]) > 1.0, (q, m, naive)
        assert floor > mine, f"dof:{variant}: noise floor {floor:.1f} dB <= {q} {mine:.1f} dB"
    assert rel["final"] <= 1.05 * rel["reference"], rel   # measured 0.244 / 0.244
