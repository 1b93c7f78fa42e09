"""Tiled renders (issue 26): an effect that tiles (``whole_frame`` None) gives, band by band
from its region of interest, exactly the pixels of its whole render; every other effect
says why it renders whole."""
import numpy as np
import pytest

from clfx.pipeline.look import render_tiled, tile_bands
from clfx.core.rect import Rect

from . import effects

TILING = [n for n in effects.EFFECTS if effects.plugin(n).whole_frame is None]

WARPS = [n for n in TILING
         if any(prm.name == "border" for prm in effects.plugin(n).descriptor.params)]
"""Tiling effects that read the source at mapped points, with a border rule at the frame."""

LAYOUTS = {
    # data window strictly inside the display window: transparent black around it
    "inside": (Rect(6, 5, 96, 75), Rect(0, 0, 110, 84)),
    # overscan: a data window past the display window on every side (negative origin)
    "overscan": (Rect(-7, -9, 83, 61), Rect(0, 0, 76, 52)),
}
"""(data window, display window) of a 70x90 frame placed off the origin."""


def test_every_effect_tiles_or_says_why_not():
    for name in effects.EFFECTS:
        why = effects.plugin(name).whole_frame
        assert why is None or (isinstance(why, str) and len(why) > 10), name
    assert {"vignette", "grain", "chromatic_aberration", "distortion",
            "sensor_noise"} <= set(TILING)


def test_bands_cover_the_window_once():
    w = Rect(-3, 2, 97, 75)
    bands = tile_bands(w, 100 * 9)
    assert len(bands) == 9 and bands[0].y0 == 2 and bands[-1].y1 == 75
    assert all(a.y1 == b.y0 for a, b in zip(bands, bands[1:]))
    assert tile_bands(w, None) == [w] and tile_bands(w, 10 ** 9) == [w]


def assert_tiles_give_the_whole_render(rt, name, p, quality, src, rows=9, **where):
    """``name`` at ``quality`` over ``src`` (context keywords ``where``): bands of ``rows``
    rows give its whole render bit for bit."""
    plugin = effects.plugin(name)

    def step(tile_pixels=None):   # the look sets the band size before the step plans
        ctx = effects.context(rt, name, src, quality=quality, **where).for_step(quality)
        ctx = ctx.over(tile_pixels=tile_pixels)
        assert plugin.is_identity(p, ctx) is None
        return ctx

    ctx = step()
    window = plugin.output_window(p, ctx)
    whole = rt.download(plugin.render(rt, p, ctx))
    ctx = step(window.width * rows)
    renders = []
    plugin.render = lambda *a: renders.append(a[2].tiling) or type(plugin).render(plugin, *a)
    try:
        tiled = rt.download(render_tiled(rt, plugin, p, ctx, window, window.width * rows))
    finally:
        del plugin.render
    bands = tile_bands(window, window.width * rows)
    assert len(bands) > 2 and [t.band for t in renders] == bands   # not the whole fallback
    assert tiled.shape == whole.shape
    assert np.array_equal(tiled.view(np.uint32), whole.view(np.uint32))


@pytest.mark.parametrize("quality", effects.QUALITIES)
@pytest.mark.parametrize("name", TILING)
def test_tiles_give_the_whole_render(rt, name, quality):
    assert_tiles_give_the_whole_render(rt, name, effects.params(name), quality,
                                       effects.scene((70, 90)))


@pytest.mark.parametrize("quality", effects.QUALITIES)
@pytest.mark.parametrize("layout", sorted(LAYOUTS))
@pytest.mark.parametrize("border", ["black", "edge", "mirror"])
@pytest.mark.parametrize("name", WARPS)
def test_warp_tiles_at_every_border_and_window(rt, name, border, layout, quality):
    # the canvas (frame, overscan, the border's repeated edge) is the whole render's in
    # every band; bands of 7 rows, so some band's rows need the canvas past the frame
    window, display = LAYOUTS[layout]
    assert_tiles_give_the_whole_render(rt, name, effects.params(name, border=border), quality,
                                       effects.scene((70, 90)), rows=7, window=window,
                                       display_window=display)


@pytest.mark.parametrize("quality", effects.QUALITIES)
@pytest.mark.parametrize("mosaic", ["bayer", "none"])
def test_sensor_noise_tiles_with_its_mosaic_and_chroma(rt, mosaic, quality):
    p = effects.params("sensor_noise", mosaic=mosaic, chroma_noise=1.0)
    window, display = LAYOUTS["overscan"]
    assert_tiles_give_the_whole_render(rt, "sensor_noise", p, quality, effects.scene((70, 90)),
                                       rows=5, window=window, display_window=display)


@pytest.mark.parametrize("mosaic", ["bayer", "none"])
def test_sensor_noise_is_the_same_on_a_crop_at_the_same_place(rt, mosaic):
    """Noise is hashed on frame coordinates: a crop (odd origin) gets the frame's noise at
    its pixels (with a mosaic, away from the crop's edges the demosaic reads past).  The
    middle grey is stated: metered (``auto``, the default) it is the frame's own, and a crop
    is another frame."""
    name = "sensor_noise"
    plugin = effects.plugin(name)
    p = effects.params(name, mosaic=mosaic, chroma_noise=1.0, coverage="ignore",
                       middle_grey=0.18)
    src = effects.scene((70, 90))
    window, crop = Rect(-7, -9, 83, 61), Rect(-2, 4, 61, 41)
    full = rt.download(plugin.render(rt, p, effects.context(rt, name, src, window=window)))
    part = src[crop.y0 - window.y0:crop.y1 - window.y0, crop.x0 - window.x0:crop.x1 - window.x0]
    cropped = rt.download(plugin.render(rt, p, effects.context(rt, name, part.copy(),
                                                               window=crop,
                                                               display_window=window)))
    inner = crop.grown(-2) if mosaic == "bayer" else crop
    want = full[inner.y0 - window.y0:inner.y1 - window.y0, inner.x0 - window.x0:inner.x1 - window.x0]
    got = cropped[inner.y0 - crop.y0:inner.y1 - crop.y0, inner.x0 - crop.x0:inner.x1 - crop.x0]
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
    assert not np.array_equal(got, part[inner.y0 - crop.y0:inner.y1 - crop.y0,
                                        inner.x0 - crop.x0:inner.x1 - crop.x0])


@pytest.mark.parametrize("quality", effects.QUALITIES)
@pytest.mark.parametrize("layout", sorted(LAYOUTS))
@pytest.mark.parametrize("reference_focus", [0.5, 20.0])   # the frame widens / narrows
def test_breathing_tiles_in_every_window(rt, reference_focus, layout, quality):
    window, display = LAYOUTS[layout]
    p = effects.params("breathing", reference_focus=reference_focus)
    assert_tiles_give_the_whole_render(rt, "breathing", p, quality, effects.scene((70, 90)),
                                       rows=7, window=window, display_window=display)


DOF_LENSES = {
    "camera": ({}, 1.0),
    # CoC radii past the dense taps: the lattice over the prefiltered colour, half resolution
    "lattice": ({"coc_source": "max_blur", "max_blur": 0.25, "max_coc": 1.0}, 1.0),
    # three gathers (axial CA), cat-eye bokeh, an anamorphic squeeze
    "ca-cateye-squeeze": ({"axial_ca_red": 60.0, "axial_ca_blue": -40.0,
                           "optical_vignetting": 1.0, "anamorphic_squeeze": 1.5}, 1.0),
    # tall pixels: the reach in rows doubles
    "pixel-aspect": ({"coc_source": "max_blur", "max_blur": 0.05, "optical_vignetting": 0.7},
                     2.0),
    # both rims (two clipping circles) and the front rim alone, the half-resolution gather
    "both-rims": ({"coc_source": "max_blur", "max_blur": 0.25, "max_coc": 1.0,
                   "optical_vignetting": 0.6, "optical_vignetting_front": 0.8}, 1.0),
    "front-rim": ({"optical_vignetting_front": 1.2, "anamorphic_squeeze": 1.3}, 2.0),
}
"""dof's lenses for the tiling test: (params, pixel aspect)."""


@pytest.mark.parametrize("quality", effects.QUALITIES)
@pytest.mark.parametrize("layout", ["frame"] + sorted(LAYOUTS))
@pytest.mark.parametrize("lens", sorted(DOF_LENSES))
def test_dof_tiles_with_every_lens_and_window(rt, lens, layout, quality, monkeypatch):
    """dof's bands give its whole render bit for bit, its frame-wide tables (tile radii,
    lattice levels, half-resolution choice, caps) made once on the whole frame: bands of 7
    rows, far less than the CoC's reach, in frames whose data window lies inside the display
    window (dof grows it) or past it."""
    from clfx.plugins.dof import Dof

    made = []
    real = Dof._make_frame
    monkeypatch.setattr(Dof, "_make_frame", lambda self, *a: made.append(1) or real(self, *a))
    kw, aspect = DOF_LENSES[lens]
    p = effects.params("dof", **kw)
    window, display = LAYOUTS.get(layout, (None, None))
    where = {"window": window, "display_window": display} if window else {}
    assert_tiles_give_the_whole_render(rt, "dof", p, quality, effects.scene((70, 90)), rows=7,
                                       pixel_aspect=aspect, **where)
    assert len(made) == 2            # once for the whole render, once for the tiled one
    if lens == "lattice" and quality == "draft":   # the paths a band must rebuild exactly
        ctx = effects.context(rt, "dof", effects.scene((70, 90)), quality=quality,
                              **where).for_step(quality)
        frame = effects.plugin("dof").frame(p, ctx)
        assert frame.gather(0.0).full_l >= 1 and frame.gather(0.0).half.any()


def layered_aa(shape, ss=4):
    """A renderer's frame of three layers: the contract's textured frame as a far wall at
    20 m, a striped card in focus (2 m) and a bar at 0.7 m in front, with slanted edges; the
    beauty the ``ss x ss`` box mean of sub-samples (edge pixels mix two layers), the depth
    the surface at each pixel centre: (rgba, depth)."""
    h, w = shape
    wall = np.repeat(np.repeat(effects.scene(shape), ss, 0), ss, 1)
    y, x = (np.mgrid[0:h * ss, 0:w * ss] + 0.5) / ss
    card = (np.abs(x - 0.45 * w + 0.1 * y) < 0.25 * w) & (np.abs(y - 0.5 * h) < 0.3 * h)
    bar = np.abs(x - 0.8 * w - 0.15 * y + 0.1 * h) < 3.3
    stripes = np.where((x // 5) % 2 == 0, 0.9, 0.08)[..., None] * np.array([1.0, 0.9, 0.7])
    sub = wall.copy()
    sub[card, :3] = stripes[card]
    sub[bar, :3] = (0.6, 0.2, 0.1)
    z = np.where(bar, 0.7, np.where(card, 2.0, 20.0)).astype(np.float32)
    rgba = sub.reshape(h, ss, w, ss, 4).mean(axis=(1, 3)).astype(np.float32)
    return rgba, np.ascontiguousarray(z[ss // 2::ss, ss // 2::ss])


@pytest.mark.parametrize("quality", effects.QUALITIES)
@pytest.mark.parametrize("lens", ["camera", "ca-cateye-squeeze", "pixel-aspect", "both-rims"])
def test_dof_bands_split_mixed_edge_pixels_as_the_whole_render(rt, lens, quality, monkeypatch):
    """Antialiased depth edges: the mixed pixels a band splits (from its own rows and the
    two beyond) and the gathers that read them are the whole render's, bit for bit, and the
    bands' counts add up to the whole render's report line."""
    from clfx.plugins.dof import MIXED_NOTE

    src, depth = layered_aa((70, 90))
    monkeypatch.setattr(effects, "depth_pass", lambda shape: depth)
    kw, aspect = DOF_LENSES[lens]
    p = effects.params("dof", **kw)
    assert_tiles_give_the_whole_render(rt, "dof", p, quality, src, rows=7, pixel_aspect=aspect)
    plugin = effects.plugin("dof")
    said = []
    for rows in (None, 7):
        ctx = effects.context(rt, "dof", src, quality=quality,
                              pixel_aspect=aspect).for_step(quality)
        window = plugin.output_window(p, ctx)
        render_tiled(rt, plugin, p, ctx, window, rows and window.width * rows)
        said.append([n for n in ctx.notes if n.endswith(MIXED_NOTE)])
    assert said[0] == said[1] and len(said[0]) == 1, said
    assert int(said[0][0].split()[1]) > 100, said


MOTION_SHUTTERS = {
    # (shutter params, layout): centred on the frame's own place; opening over two frames with
    # the data window inside the display window (the smear grows the window); closing short
    # with overscan
    "centred-180": ({"shutter_angle": 180.0, "shutter_offset": "centered"}, None),
    "opening-360-inside": ({"shutter_angle": 360.0, "shutter_offset": "opening"}, "inside"),
    "closing-90-overscan": ({"shutter_angle": 90.0, "shutter_offset": "closing"}, "overscan"),
}
"""Shutter shapes (and frame layouts) of the blurs of motion's tiled renders."""


def backward_pass(shape):
    """The other half of the vector pass: the swirl turned a little against the forward
    motion, so paths are arcs (`clfx.fx.motion.path`)."""
    v = effects.velocity_pass(shape).astype(np.float64)
    c, s = np.cos(0.3), np.sin(0.3)
    return np.ascontiguousarray(np.stack([c * v[..., 0] - s * v[..., 1],
                                          s * v[..., 0] + c * v[..., 1]], axis=2), np.float32)


CAMERA_MOTIONS = {
    "pan-roll-zoom": {},                                   # the exact path gather
    "tilt": {"length": 0.06, "direction": 100.0, "roll": 0.0, "zoom": 0.0},
    "truck": {"truck": (0.3, 0.2), "roll": 0.0, "zoom": 0.0},          # the motion gather
    "truck-roll": {"truck": (0.3, 0.2), "roll": 3.0},     # both halves: arcs
    "dolly": {"dolly": 0.3, "roll": 0.0},
}
"""camera_blur's motions (over the contract's active pan, roll and zoom)."""


@pytest.mark.parametrize("quality", effects.QUALITIES)
@pytest.mark.parametrize("shutter", sorted(MOTION_SHUTTERS))
@pytest.mark.parametrize("motion", sorted(CAMERA_MOTIONS))
def test_camera_blur_tiles_with_every_motion(rt, monkeypatch, motion, shutter, quality):
    from clfx.fx import motion as motion_fx

    monkeypatch.setattr(motion_fx, "GRID_CHUNK_PIXELS", 1)   # one row of tiles at a time
    params, layout = MOTION_SHUTTERS[shutter]
    window, display = LAYOUTS[layout] if layout else (None, None)
    p = effects.params("camera_blur", **params, **CAMERA_MOTIONS[motion])
    assert_tiles_give_the_whole_render(rt, "camera_blur", p, quality, effects.scene((70, 90)),
                                       rows=7, window=window, display_window=display)


ROLLING_READOUTS = {
    # (params, layout): rows read top-down from the first; bottom-up about the middle row with
    # the data window inside the display window; columns left-right, t = 0 at the last, with
    # overscan; right-left about the middle over a long readout (large shifts)
    "top-down-first": ({}, None),
    "bottom-up-centre-inside": ({"direction": "bottom-up", "reference": "centre"}, "inside"),
    "left-right-last-overscan": ({"direction": "left-right", "reference": "last"}, "overscan"),
    "right-left-centre-long": ({"direction": "right-left", "reference": "centre",
                                "readout_fraction": 2.0}, None),
}
"""rolling_shutter's readouts (and frame layouts) of its tiled renders."""


MOTION_CASES = ([("motion_blur", k, *v) for k, v in sorted(MOTION_SHUTTERS.items())]
                + [("rolling_shutter", k, *v) for k, v in sorted(ROLLING_READOUTS.items())])


@pytest.mark.parametrize("quality", effects.QUALITIES)
@pytest.mark.parametrize("halves", [1, 2])
@pytest.mark.parametrize("name,case,params,layout", MOTION_CASES,
                         ids=[f"{n}-{c}" for n, c, *_ in MOTION_CASES])
def test_velocity_effects_tile_at_every_shutter_and_path(rt, monkeypatch, name, case, params,
                                                         layout, halves, quality):
    # bands of 7 rows: a band's samples reach past its neighbours, the tiles of its velocity
    # grid straddle bands (the grid and neighbour max are the frame's, built once, here from
    # one row of tiles at a time: the dilation's rows past each chunk); positions and row
    # times are the whole render's
    from clfx.fx import motion
    from clfx.plugins import rolling_shutter

    for module in (motion, rolling_shutter):
        monkeypatch.setattr(module, "GRID_CHUNK_PIXELS", 1)
    window, display = LAYOUTS[layout] if layout else (None, None)
    where = dict(window=window, display_window=display)
    if halves == 2:
        where["velocity_back"] = rt.upload(backward_pass((70, 90)),
                                           window or Rect.from_size(90, 70))
    assert_tiles_give_the_whole_render(rt, name, effects.params(name, **params), quality,
                                       effects.scene((70, 90)), rows=7, **where)


@pytest.mark.parametrize("quality", effects.QUALITIES)
@pytest.mark.parametrize("layout", ["frame", "overscan"])
@pytest.mark.parametrize("streamed", [False, True], ids=["whole-passes", "streamed"])
@pytest.mark.parametrize("mode", ["star", "anamorphic"])
def test_streaks_tiles_from_the_frames_streak_sum(rt, monkeypatch, mode, streamed, layout,
                                                  quality):
    # the plan's streak sum is the whole frame's (its passes over frame-sized buffers, or
    # streamed through in chunks of 3 rows as an 8K frame is); a band composes its rows of it
    # (a band reads only its rows of the source: one past the data window makes
    # render_tiled render whole, so "inside" is not a layout here)
    import clfx.plugins.streaks as mod
    if streamed:
        monkeypatch.setattr(mod, "streams", lambda *a: True)
        monkeypatch.setattr(mod, "CHUNK_PIXELS", 3 * 96)
    window, display = LAYOUTS.get(layout, (None, None))
    p = effects.params("streaks", mode=mode, angle=30.0, length=0.3, streaks=5)
    assert_tiles_give_the_whole_render(rt, "streaks", p, quality, effects.scene((70, 90)),
                                       rows=7, window=window, display_window=display)
