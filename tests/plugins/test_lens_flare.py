import math

import numpy as np
import pytest

from clfx.core.camera import Camera
from clfx.core.errors import ParamError
from clfx.plugins.lens_flare import LensFlare, parse_ghosts
from clfx.core.rect import Rect
from tests.conftest import hard_shapes
from clfx.pipeline.presets import read_lens
from tests.reference.lens_flare import lens_flare as reference, sources
from tests.effects import render_effect

PARAMS = dict(model="artistic", threshold=5.0, ghost_count=8, softness=0.2, roundness=0.3, halo_intensity=0.05)
CAM = Camera(blades=6, blade_rotation=10.0)


def scene(rng, shape):
    src = rng.uniform(0.0, 0.5, shape + (4,)).astype(np.float32)
    h, w = shape
    src[h // 4, (3 * w) // 4, :3] = 1e3
    src[(2 * h) // 3, w // 5, :3] = (50.0, 20.0, 5.0)
    return src


def expected(src, p, camera=CAM, origin=(0, 0), display=None, margin_px=0):
    lights = sources(src, p.threshold, origin=origin, display=display, margin_px=margin_px,
                     max_sources=p.max_sources)
    table = parse_ghosts(p.ghosts, p.ghost_count)
    kw = p.as_dict() | {"blades": p.blades or camera.blades,
                        "rotation": camera.blade_rotation + p.rotation}
    return reference(src, lights, table, **kw, origin=origin, display=display)


@pytest.mark.parametrize("shape", hard_shapes() + [(90, 130)])
def test_lens_flare_matches_reference(rt, rng, shape):
    src = scene(rng, shape)
    p = LensFlare.params(**PARAMS)
    got = render_effect(rt, LensFlare(), p, src, camera=CAM)
    want = expected(src, p)
    # float32 entries and shape evaluation: ~1e-6 of the brightest ghost, plus the source
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5 * np.abs(want).max())


def test_round_ghosts_and_custom_table(rt, rng):
    src = scene(rng, (70, 100))
    p = LensFlare.params(**{**PARAMS, "ghosts": "-0.5:0.05:0.2,0.4,0.1; 0.4:0.02:1,1,1"})
    cam = Camera(blades=0)
    got = render_effect(rt, LensFlare(), p, src, camera=cam)
    np.testing.assert_allclose(got, expected(src, p, cam), rtol=1e-5,
                               atol=1e-5 * np.abs(got).max())


def test_ghost_spec_errors():
    with pytest.raises(ParamError):
        parse_ghosts("0.5:abc", 3)
    with pytest.raises(ParamError):
        parse_ghosts("0.5:-1:1,1,1", 3)
    assert len(parse_ghosts("", 3)) == 3


def test_ghost_position_and_brightness_follow_the_light(rt):
    h, w = 100, 160
    p = LensFlare.params(model="artistic", threshold=1.0, ghosts="-1:0.05:1,1,1",
                         halo_intensity=0.0, intensity=1.0,
                         roundness=1.0, softness=0.1)
    lx, ly = 120, 30
    glow = []
    for v in (101.0, 201.0):
        src = np.zeros((h, w, 4), np.float32)
        src[ly, lx, :3] = v
        out = render_effect(rt, LensFlare(), p, src, camera=Camera(blades=0)) - src
        ys, xs = np.mgrid[0:h, 0:w] + 0.5
        g = out[..., 1]
        # ghost centre = c + k (L - c) with k = -1: mirrored through the centre
        assert abs((g * xs).sum() / g.sum() - (w - (lx + 0.5))) < 0.05
        assert abs((g * ys).sum() / g.sum() - (h - (ly + 0.5))) < 0.05
        glow.append(g.sum())
    # brightness follows the light's flux (v - threshold): 200 / 100
    assert abs(glow[1] / glow[0] - 2.0) < 1e-5
    # and the ghost carries intensity * flux (area-normalised radiance; pixel sampling of a
    # 9 px disk: ~1 %)
    assert abs(glow[1] / 200.0 - 1.0) < 0.02


def test_hexagonal_ghost_shape(rt):
    h, w = 200, 200
    src = np.zeros((h, w, 4), np.float32)
    src[100, 100, :3] = 1e4                               # light at the centre: ghost there
    p = LensFlare.params(model="artistic", threshold=1.0, ghosts="1:0.2:1,1,1",
                         halo_intensity=0.0,
                         softness=0.02, roundness=0.0)
    out = render_effect(rt, LensFlare(), p, src, camera=Camera(blades=6, blade_rotation=0.0)) - src
    r = 0.2 * math.hypot(w, h)                            # circumradius 56.6 px
    c = 100.5
    # vertex 0 at 0 deg (+x): inside at 0.95 r; along an edge normal (30 deg) the apothem is
    # 0.866 r, so 0.93 r is outside
    vx = int(c + 0.95 * r)
    nx, ny = int(c + 0.93 * r * math.cos(math.pi / 6)), int(c - 0.93 * r * math.sin(math.pi / 6))
    assert out[100, vx, 1] > 0.5 * out[100, 100, 1]
    assert out[ny, nx, 1] < 1e-6 * out[100, 100, 1]


def test_light_just_outside_the_frame_flares(rt, rng):
    data = Rect(0, 0, 200, 100)                           # overscan around the display
    display = Rect(20, 10, 140, 90)
    src = rng.uniform(0.0, 0.2, (100, 200, 4)).astype(np.float32)
    src[4:7, 170:173, :3] = 500.0                         # 30 px right of the display window
    p = LensFlare.params(**{**PARAMS, "margin": 0.2})
    got = render_effect(rt, LensFlare(), p, src, camera=CAM, data_window=data,
                        display_window=display)
    want = expected(src, p, display=(20, 10, 140, 90), margin_px=math.ceil(0.2 * display.diagonal))
    assert np.abs(got - src).max() > 1e-3
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5 * np.abs(want).max())
    # with no margin the light does not count: identity with a reason
    p0 = LensFlare.params(**{**PARAMS, "margin": 0.0})
    from clfx.host import RenderContext
    ctx = RenderContext(rt, rt.upload(src, data), display_window=display, camera=CAM)
    assert LensFlare().is_identity(p0, ctx) == "no light source in or near view"


def test_identities(rt, rng):
    src = rng.uniform(0.0, 0.9, (9, 13, 4)).astype(np.float32)
    for kw in ({"intensity": 0.0, "halo_intensity": 0.0}, {}):
        got = render_effect(rt, LensFlare(), LensFlare.params(**{**PARAMS, **kw}), src)
        assert np.array_equal(got, src)


def test_nan_inf_determinism_alpha_no_negatives(rt, rng):
    src = scene(rng, (60, 80))
    src[..., 3] = rng.uniform(0, 1, (60, 80))
    src[3, 3, 0], src[20, 40, 2], src[5, 30, :] = np.nan, np.inf, -np.inf
    p = LensFlare.params(**PARAMS)
    a = render_effect(rt, LensFlare(), p, src, camera=CAM)
    b = render_effect(rt, LensFlare(), p, src, camera=CAM)
    assert a.tobytes() == b.tobytes()
    assert np.isfinite(a).all() and a.min() >= 0.0
    ok = np.isfinite(src[..., 3])
    np.testing.assert_array_equal(a[..., 3][ok], src[..., 3][ok])
    want = expected(src, p)
    np.testing.assert_allclose(a, want, rtol=1e-5, atol=1e-5 * np.abs(want).max())


def test_rod_covers_display(rt):
    src = np.zeros((20, 20, 4), np.float32)
    src[10, 10, :3] = 1e3
    p = LensFlare.params(**PARAMS)
    out, win = render_effect(rt, LensFlare(), p, src, data_window=Rect(40, 30, 60, 50),
                             display_window=Rect(0, 0, 100, 80), keep_rod=True, camera=CAM)
    assert win == Rect(0, 0, 100, 80)
    assert out[:30].max() > 0.0                           # ghosts land outside the data window


def wide_range_frame(h=64, w=96):
    """Finite values across the float range (issue 10 item 6, WideFloatRange.exr): +-1e38
    lights and blocks, FLT_MAX, half's 65504, tiny and denormal values; a few NaN/Inf pixels."""
    big = float(np.finfo(np.float32).max)
    src = np.full((h, w, 4), 1e-38, np.float32)
    src[::3, ::2, :3] = 1e-45                        # denormals
    src[1::4, 1::3, :3] = -1e-30
    src[..., 3] = 1.0
    src[5:9, 30:36, :3] = 1e38
    src[20:24, 4:10, :3] = -1e38
    src[30:33, 40:44, :3] = (1e38, -1e38, 1e38)
    src[12, 12, :3] = big
    src[14, 50, :3] = (big, 0.0, big)
    src[25:28, 20:30, :3] = 65504.0
    src[35, 10, :] = 1e38                            # alpha too
    src[2, 2, 0], src[37, 50, 1], src[18, 40, :] = np.nan, np.inf, -np.inf
    return src


@pytest.mark.parametrize("effect,params", [
    ("lens_flare", {}),
    ("glare", {"size": 0.5}), ("glare", {"size": 0.1}),
    ("bleed", {"size": 0.05}), ("bleed", {"size": 0.1}),
    ("soft_focus", {"size": 0.5}),
    ("corona", {"size": 0.05}),
    ("streaks", {}), ("streaks", {"length": 1.0, "intensity": 100.0}),
])
@pytest.mark.parametrize("quality", ["draft", "preview", "final", "reference"])
def test_finite_input_gives_finite_output(rt, effect, params, quality):
    # the light-spreading effects saturate at +-FLT_MAX instead of overflowing to inf (and
    # inf - inf to NaN): finite input, finite output, at every level
    from clfx.plugins import get_plugin

    cls = get_plugin(effect)
    src = wide_range_frame()
    got = render_effect(rt, cls(), cls.params(**params), src, quality=quality, camera=CAM,
                        read_lens=read_lens)
    finite = np.isfinite(src)
    assert np.isfinite(got[finite]).all(), np.argwhere(~np.isfinite(got) & finite)[:5]


def test_wide_float_range_exr_flares_finite(rt, exr_images):
    from clfx.io.read import read_frame

    f = read_frame(exr_images / "TestImages" / "WideFloatRange.exr")
    assert np.isfinite(f.rgba).all()
    for quality in ("draft", "reference"):
        got = render_effect(rt, LensFlare(), LensFlare.params(), f.rgba, quality=quality,
                            data_window=f.data_window, display_window=f.display_window,
                            read_lens=read_lens)
        assert np.isfinite(got).all()


# -- the physical model ----------------------------------------------------------------------
from clfx.fx import flare, spectral  # noqa: E402
from clfx.host import RenderContext  # noqa: E402
from tests.reference import lens_flare as oracle  # noqa: E402

LENSES = ("double-gauss-50mm", "retrofocus-28mm", "zoom-80-200mm")
CAM_P = Camera(blades=6, blade_rotation=10.0, f_number=8.0)


def physical_scene(h=72, w=120):
    src = np.full((h, w, 4), 0.01, np.float32)
    src[..., 3] = 1.0
    src[14:17, 92:95, :3] = (2e4, 1.8e4, 1.5e4)    # a light near a corner
    src[50, 20, :3] = 5e3
    return src


def planned(rt, p, src, camera=CAM_P, quality="reference"):
    ctx = RenderContext(rt, rt.upload(src), camera=camera, quality=quality, read_lens=read_lens)
    return ctx, LensFlare().ghost_plan(rt, p, ctx)


@pytest.mark.parametrize("lens", LENSES)
def test_physical_ghosts_match_reference(rt, lens):
    src = physical_scene()
    p = LensFlare.params(light_level=0.0, lens=lens, gain=100.0, cull=0.0)
    got = render_effect(rt, LensFlare(), p, src, camera=CAM_P, quality="reference",
                        read_lens=read_lens)
    _, (entries, levels, _, _) = planned(rt, p, src)
    # >= 10 drawn (the double Gauss's ten: ghosts wider than VEIL_FROM = 5 % of the diagonal
    # fade out since issue 32); reference: all at full resolution
    assert len(entries) >= 10 and (levels == 0).all()
    table = flare.edge_table()
    want = src[..., :3] + oracle.physical_ghosts(src.shape[:2], entries,
                                                 flare.aperture_normals(6, 10.0), table,
                                                 reach=flare.EDGE_REACH)
    ghosts = want - src[..., :3]
    # float32 distances, table lookups and sums of ~100 entries: ~1e-5 of the brightest ghost
    np.testing.assert_allclose(got[..., :3], want, rtol=1e-4, atol=2e-5 * ghosts.max())
    assert np.array_equal(got[..., 3], src[..., 3])


def test_physical_lights_match_reference(rt):
    src = physical_scene()
    p = LensFlare.params(threshold=5.0)
    ctx = RenderContext(rt, rt.upload(src), camera=CAM_P, read_lens=read_lens)
    got = LensFlare().measure(rt, p, ctx, LensFlare().candidate_sources(p, ctx), full=True)
    want = oracle.lights(src, 5.0)
    assert len(got) == len(want) == 2
    for g, (x, y, f, r) in zip(got, want):
        assert abs(g.x - x) < 1e-3 and abs(g.y - y) < 1e-3 and abs(g.rms_px - r) < 1e-3
        np.testing.assert_allclose(g.flux, f, rtol=1e-6)


def test_final_levels_close_to_full_resolution(rt):
    # final draws soft ghosts at reduced resolution: bilinear upsampling of edges at least
    # 2 px wide costs ~1 % of a ghost's brightness
    # 144 x 240: since issue 32 ghosts wider than 5 % of the diagonal fade out, and at
    # 96 x 160 none left was soft enough to be drawn at reduced resolution
    src = physical_scene(144, 240)
    p = LensFlare.params(light_level=0.0, lens="zoom-80-200mm", gain=100.0, cull=0.0)
    ctx, (entries, levels, _, _) = planned(rt, p, src, camera=Camera(blades=6, f_number=2.8),
                                           quality="final")
    assert levels.max() >= 1
    got = rt.download(LensFlare().draw(rt, ctx, entries, levels, ctx.source.window, 6, 0.0))
    want = src[..., :3] + oracle.physical_ghosts(src.shape[:2], entries,
                                                 flare.aperture_normals(6, 0.0), flare.edge_table(),
                                                 reach=flare.EDGE_REACH)
    err = np.abs(got[..., :3] - want)
    peak = (want - src[..., :3]).max()
    assert err.max() < 0.03 * peak and err.mean() < 0.003 * peak


def test_ghost_positions_and_energies_for_a_point_light(rt):
    # one pixel light: every unclipped ghost lands on the line through the optical centre
    # and the light, at its centre factor c times the light's offset, and carries the
    # light's flux times its coated reflections (energy / T_p): the table's physics
    h, w = 240, 320
    src = np.zeros((h, w, 4), np.float32)
    lx, ly = 200, 90
    src[ly, lx, :3] = 1e6
    p = LensFlare.params(light_level=0.0, lens="double-gauss-50mm", cull=0.0)
    cam = Camera(blades=0, f_number=16.0, sensor_width=36.0)
    ctx, (entries, levels, rows, lights) = planned(rt, p, src, camera=cam)
    plugin = LensFlare()
    key, lens = plugin.prescription(p, ctx)
    from clfx.plugins.lens_flare import flare_wavelengths

    wl = flare_wavelengths(11)
    table = plugin.ghost_table(ctx, key, lens, 16.0, wl)
    weights = spectral.channel_weights(wl)
    cx, cy = w / 2, h / 2
    x_px = math.hypot(lx + 0.5 - cx, ly + 0.5 - cy)
    ux, uy = (lx + 0.5 - cx) / x_px, (ly + 0.5 - cy) / x_px
    ys, xs = np.mgrid[0:h, 0:w] + 0.5
    checked = 0
    for i in np.argsort(-entries[:, 15])[:12]:
        e = entries[i]
        g = rows[i]
        if e[19] > 0 or e[21] > 0:
            continue                                        # cut by a clip disc: cat's eye
        r = (e[7:10] * e[22]).max() + flare.EDGE_REACH / e[10:13].min()
        if not (r < e[0] < w - r and r < e[1] < h - r):
            continue                                        # partly outside the frame
        if e[7:10].max() > flare.VEIL_FROM * math.hypot(w, h):
            continue                                        # fading: per-channel radii differ
        one = rt.download(plugin.draw(rt, ctx, entries[i:i + 1], levels[i:i + 1],
                                      ctx.source.window, 0, 0.0))[..., :3] - src[..., :3]
        power = flare.ghost_power(table, flare.Optics((cx, cy), w / 36.0, 0, lens.stop_index,
                                                      gain=p.gain))[g]
        # times the default gain; ghosts past VEIL_FROM of the diagonal fade
        want = 1e6 * weights.T @ power * flare.veil_fade(e[8] / math.hypot(w, h))
        np.testing.assert_allclose(one.sum(axis=(0, 1)), want, rtol=0.01)
        gsum = one[..., 1].sum()
        mx, my = (one[..., 1] * xs).sum() / gsum, (one[..., 1] * ys).sum() / gsum
        c = table.centre[g, len(wl) // 2]
        # on the line, at c x (spectral spread inside the green band: ~0.5 % of c x)
        assert abs((mx - cx) * uy - (my - cy) * ux) < 0.05
        assert abs(((mx - cx) * ux + (my - cy) * uy) - c * x_px) < 0.01 * abs(c) * x_px + 0.1
        checked += 1
    assert checked >= 3


def tint_kinds(power):
    """Per ghost, which family its channel shares (power / sum) put it in: green (G the
    largest, > 0.4), amber (R > 0.45 and G > B), magenta (R and B > 0.35 each), blue
    (B > 0.42); others (near-white, cyan, yellow) are left out."""
    share = power / power.sum(axis=1, keepdims=True)
    kinds = {}
    for r, g, b in share:
        k = ("green" if g > 0.4 and g >= max(r, b) else "amber" if r > 0.45 and g > b
             else "magenta" if min(r, b) > 0.35 else "blue" if b > 0.42 else None)
        if k:
            kinds[k] = kinds.get(k, 0) + 1
    return kinds


def test_ghosts_are_dim_by_the_physics_and_gain_multiplies(rt):
    src = physical_scene()
    added = []
    for gain in (1.0, 10.0):
        p = LensFlare.params(light_level=0.0, lens="zoom-80-200mm", gain=gain, cull=0.0)
        out = render_effect(rt, LensFlare(), p, src, camera=CAM_P, read_lens=read_lens,
                            quality="reference")
        added.append((out[..., :3] - src[..., :3]).sum())
    flux = oracle.lights(src, 5.0)[0][2].sum()
    # two coated reflections per ghost, 210 ghosts (most leave this small frame): 1e-5..1e-2
    assert 1e-5 < added[0] / flux < 1e-2
    assert abs(added[1] / added[0] - 10.0) < 1e-3


def test_ghosts_are_coloured_and_fringed(rt):
    src = physical_scene()
    p = LensFlare.params(light_level=0.0, lens="zoom-80-200mm", cull=0.0, coatings="lens")
    _, (entries, _, _, _) = planned(rt, p, src, quality="final")
    # the lens's one coating on every surface: a quarter-wave MgF2 layer at 550 nm reflects
    # blue and red more than green: every ghost violet
    power = entries[:, 13:16] * entries[:, 7:10] ** 2
    assert (power[:, 2] > power[:, 1]).mean() > 0.7
    # multi-coated (the default): each surface its own multilayer stack, so the ghosts'
    # tints differ: green ones (broadband stacks' hump) beside amber, magenta and blue ones
    _, (multi, _, _, _) = planned(rt, LensFlare.params(light_level=0.0, lens="zoom-80-200mm", cull=0.0), src,
                                  quality="final")
    power = multi[:, 13:16] * multi[:, 7:10] ** 2
    kinds = tint_kinds(power)
    assert {"green", "amber", "magenta", "blue"} <= set(kinds), kinds
    # dispersion: the channels' ghosts differ in size (coloured fringes)
    assert np.median(np.abs(entries[:, 7] - entries[:, 9]) / entries[:, 8]) > 1e-3


def test_f_number_beyond_the_lens_warns(rt):
    src = physical_scene()
    ctx = RenderContext(rt, rt.upload(src), camera=Camera(f_number=1.0), read_lens=read_lens)
    LensFlare().render(rt, LensFlare.params(), ctx)
    assert any("opens to f/2" in w for w in ctx.warnings)


def test_unknown_lens_and_lens_files(rt, tmp_path):
    from clfx.core.errors import ClfxError

    src = physical_scene()
    with pytest.raises(ClfxError, match="did you mean 'zoom-80-200mm'"):
        render_effect(rt, LensFlare(), LensFlare.params(lens="zoom-80-200"), src,
                      read_lens=read_lens)
    from clfx.pipeline.presets import find_lens

    path = tmp_path / "mine.yaml"
    path.write_text(find_lens("double-gauss-50mm").read_text())
    bare = RenderContext(rt, rt.upload(src), camera=CAM_P)   # made without a lens reader
    with pytest.raises(ClfxError, match="no lens reader"):   # (a render always has one)
        LensFlare().render(rt, LensFlare.params(lens=str(path)), bare)
    a = render_effect(rt, LensFlare(),
                      LensFlare.params(light_level=0.0, lens=str(path), gain=100.0), src,
                      read_lens=read_lens)
    b = render_effect(rt, LensFlare(), LensFlare.params(light_level=0.0, gain=100.0), src,
                      read_lens=read_lens)
    assert np.array_equal(a, b) and not np.array_equal(a, src)


def test_the_ghost_table_is_built_once_per_lens_and_stop(rt, monkeypatch):
    """The physical model's ghost table (clfx.fx.optics.ghosts: 210 ghosts of the zoom, its
    time is the bench's) is built once per lens, f-number and wavelengths, not per frame."""
    from clfx.plugins import lens_flare as module

    calls = []
    ghosts = module.optics.ghosts
    monkeypatch.setattr(module.optics, "ghosts", lambda *a, **k: calls.append(a) or ghosts(*a, **k))
    rt.cache.clear()
    src = physical_scene()
    p = LensFlare.params(light_level=0.0, lens="zoom-80-200mm", gain=10.0)
    first = render_effect(rt, LensFlare(), p, src, camera=CAM_P, read_lens=read_lens)
    again = render_effect(rt, LensFlare(), p, src, camera=CAM_P, read_lens=read_lens)
    assert len(calls) == 1 and np.array_equal(first, again)
    render_effect(rt, LensFlare(), p, src, camera=Camera(blades=6, blade_rotation=10.0, f_number=4.0),
                  read_lens=read_lens)
    assert len(calls) == 2                                # another stop: another table


def test_physical_is_deterministic_and_keeps_alpha(rt, rng):
    src = physical_scene()
    src[..., 3] = rng.uniform(0, 1, src.shape[:2])
    p = LensFlare.params(light_level=0.0, lens="zoom-80-200mm", gain=10.0)
    a = render_effect(rt, LensFlare(), p, src, camera=CAM_P, read_lens=read_lens)
    b = render_effect(rt, LensFlare(), p, src, camera=CAM_P, read_lens=read_lens)
    assert np.array_equal(a, b)
    assert np.array_equal(a[..., 3], src[..., 3])
    assert (a[..., :3] >= src[..., :3]).all()


@pytest.mark.parametrize("shape", hard_shapes())
def test_physical_hard_shapes(rt, rng, shape):
    src = rng.uniform(0.0, 0.5, shape + (4,)).astype(np.float32)
    src[0, -1, :3] = 1e6                                     # a light in the corner
    for quality in ("draft", "reference"):
        got = render_effect(rt, LensFlare(),
                            LensFlare.params(light_level=0.0, lens="zoom-80-200mm", gain=1e3), src,
                            camera=CAM_P, quality=quality, read_lens=read_lens)
        assert np.isfinite(got).all() and (got[..., :3] >= src[..., :3]).all()
        assert np.array_equal(got[..., 3], src[..., 3])


def test_working_space_luminance_and_channel_weights(rt, rng):
    from clfx.io.colour import rgb_to_xyz

    aces = rgb_to_xyz("ACEScg")
    src = scene(rng, (64, 256))
    src[40, 128, :3] = (0.0, 0.0, 60.0)   # Y 4.3 in Rec.709, 3.5 in ACEScg; tiles of its own
    p = LensFlare.params(**{**PARAMS, "threshold": 4.0})
    lights = sources(src, p.threshold, rgb_to_xyz=aces)
    assert len(lights) == len(sources(src, p.threshold)) - 1    # the blue pixel is no light
    table = parse_ghosts(p.ghosts, p.ghost_count)
    kw = p.as_dict() | {"blades": CAM.blades, "rotation": CAM.blade_rotation + p.rotation}
    want = reference(src, lights, table, **kw)
    got = render_effect(rt, LensFlare(), p, src, camera=CAM, working_space="ACEScg")
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-5 * want.max())
    # the physical model: the light's centroid is ACEScg-luminance weighted, and channels
    # spread over the wavelengths by ACEScg's primaries (3 samples: one per channel anyway)
    phys = physical_scene()
    ctx = RenderContext(rt, rt.upload(phys), camera=CAM_P, read_lens=read_lens, rgb_to_xyz=aces)
    p = LensFlare.params(threshold=5.0)
    got = LensFlare().measure(rt, p, ctx, LensFlare().candidate_sources(p, ctx), full=True)
    for g, (x, y, f, r) in zip(got, oracle.lights(phys, 5.0, rgb_to_xyz=aces)):
        assert abs(g.x - x) < 1e-3 and abs(g.y - y) < 1e-3 and abs(g.rms_px - r) < 1e-3
    from clfx.plugins.lens_flare import flare_channel_weights

    np.testing.assert_array_equal(flare_channel_weights((610.0, 550.0, 465.0), aces), np.eye(3))
    w = flare_channel_weights(tuple(np.linspace(420.0, 680.0, 7)), aces)
    np.testing.assert_allclose(w, spectral.channel_weights(np.linspace(420.0, 680.0, 7), aces))
    assert not np.allclose(w, spectral.channel_weights(np.linspace(420.0, 680.0, 7)))


def test_physical_plan_is_made_once_per_frame(rt, monkeypatch):
    """is_identity's cull check and the render share one ghost plan (a measure kernel, the
    cull and the entries), the step's plan; a new step (`for_step`) or another source
    (`with_source`) plans again."""
    calls = []
    real = LensFlare.ghost_plan
    monkeypatch.setattr(LensFlare, "ghost_plan",
                        lambda self, *a: calls.append(1) or real(self, *a))
    src = physical_scene()
    p = LensFlare.params(light_level=0.0, gain=100.0)
    ctx = RenderContext(rt, rt.upload(src), camera=CAM_P, read_lens=read_lens).for_step("final")
    fx = LensFlare()
    assert fx.is_identity(p, ctx) is None
    first = rt.download(fx.render(rt, p, ctx))
    assert len(calls) == 1
    again = rt.download(fx.render(rt, p, ctx))          # the same step: the same plan
    assert len(calls) == 1 and np.array_equal(first, again)
    anew = rt.download(fx.render(rt, p, ctx.for_step("final")))   # a new step plans again
    assert len(calls) == 2 and np.array_equal(first, anew)
    other = ctx.with_source(rt.upload(src * 2.0))     # another source: its own plan
    fx.is_identity(p, ctx)
    fx.render(rt, p, other)
    assert len(calls) == 3


def test_physical_render_of_a_frame_without_a_light_reads_no_lens(rt, monkeypatch):
    """Without a light the plan is the identity with no ghosts: a render called anyway (as
    the pipeline never does) draws none and builds no ghost plan (it used to build one)."""
    monkeypatch.setattr(LensFlare, "ghost_plan", lambda *a: pytest.fail("ghost plan built"))
    src = np.full((40, 60, 4), 0.01, np.float32)
    src[..., 3] = 1.0
    p = LensFlare.params(light_level=0.0, gain=100.0)
    ctx = RenderContext(rt, rt.upload(src), camera=CAM_P, read_lens=read_lens).for_step("final")
    fx = LensFlare()
    assert fx.is_identity(p, ctx) is not None
    out = rt.download(fx.render(rt, p, ctx))
    assert np.array_equal(out, src)


def point_light_frame(h=270, w=480, background=0.01, ratio=2000.0, at=(360, 70)):
    """A flat background and a 3 x 3 px light ``ratio`` times brighter near a corner."""
    src = np.full((h, w, 4), background, np.float32)
    src[..., 3] = 1.0
    src[at[1] - 1:at[1] + 2, at[0] - 1:at[0] + 2, :3] = ratio * background
    return src


@pytest.mark.parametrize("lens", LENSES)
def test_physical_flare_is_visible_varied_and_veil_free_at_defaults(rt, lens):
    """Issue 25: a light 2000 times the background at the defaults (gain 1 left ghosts of
    ~1e-4 of the background: invisible; one film on every surface made them all violet; ghosts
    wider than the frame laid a polygonal veil over it)."""
    bg = 0.01
    h, w, (lx, ly) = 270, 480, (360, 70)
    src = point_light_frame(h, w, bg)
    cam = Camera()                                           # defaults: f/2.8, round
    p = LensFlare.params(lens=lens)
    out = render_effect(rt, LensFlare(), p, src, camera=cam, read_lens=read_lens, quality="final")
    added = out[..., :3] - src[..., :3]
    ys, xs = np.mgrid[0:h, 0:w] + 0.5
    away = np.hypot(xs - lx - 0.5, ys - ly - 0.5) > 12      # not the light itself
    # visible: the brightest ghost adds at least 0.1 of the background (+10 %: seen on a
    # flat field; 0.19-0.45 at the defaults of issue 32, faint as a multi-coated lens's
    # ghosts of a lamp; 1.2-4.4 at the gain 500 before); nowhere more than 10 times it
    peak = added[away].max()
    assert 0.1 * bg <= peak <= 10 * bg
    ctx, (entries, _, _, _) = planned(rt, p, src, camera=cam, quality="final")
    # at a strong gain (500 on every light, the default until issue 32) at least 2 ghosts
    # above 5 % of the background (a patch that much brighter than a flat field is seen; 3
    # before issue 32, when the double Gauss's ghosts wider than 5 % of the diagonal were
    # drawn instead of fading into veiling glare), of clearly different tints (their power's
    # channel shares differ by > 0.15: green or amber beside violet, magenta)
    _, (strong, _, _, _) = planned(rt, LensFlare.params(lens=lens, gain=500.0, light_level=0.0),
                                   src, camera=cam, quality="final")
    seen = strong[strong[:, 13:16].max(axis=1) >= 0.05 * bg]
    assert len(seen) >= 2
    power = seen[:, 13:16] * seen[:, 7:10] ** 2
    share = power / power.sum(axis=1, keepdims=True)
    distinct = [share[0]]
    for s in share[1:]:
        if all(np.abs(s - d).max() > 0.15 for d in distinct):
            distinct.append(s)
    # > 0.15 (the distinct tints' own margin; 0.2 when three or more ghosts were seen: the
    # double Gauss's two differ by 0.198)
    assert len(distinct) >= 2 and np.ptp(share, axis=0).max() > 0.15
    # no veil: every drawn ghost's radius is at most VEIL_TO (0.2) of the diagonal, and far
    # from the axis through the centre and the light (> 0.35 of the diagonal) nothing is added
    diag = math.hypot(w, h)
    assert (entries[:, 7:10].max(axis=1) <= flare.VEIL_TO * diag).all()
    cx, cy = w / 2, h / 2
    ux, uy = lx + 0.5 - cx, ly + 0.5 - cy
    n = math.hypot(ux, uy)
    off = np.abs((xs - cx) * uy / n - (ys - cy) * ux / n)
    assert added[off > 0.35 * diag].max(initial=0.0) <= 1e-6
    # the lens's own single film (coatings="lens") gives one tint: the old look
    one = planned(rt, LensFlare.params(lens=lens, coatings="lens"), src, camera=cam,
                  quality="final")[1][0]
    power = one[:, 13:16] * one[:, 7:10] ** 2
    assert (power[:, 0] / power.sum(axis=1) < 0.5).all()


def test_artistic_ghosts_differ_in_size_sharpness_rim_and_tint(rt):
    from clfx.plugins.lens_flare import DEFAULT_GHOSTS

    table = parse_ghosts("", 8)
    sizes = [g[1] for g in table]
    soft = [g[3] for g in table]
    rims = [g[4] for g in table]
    tints = np.array([g[2] for g in table])
    assert max(sizes) / min(sizes) > 5 and max(soft) - min(soft) > 0.4
    assert max(rims) - min(rims) > 0.5
    hue = tints / tints.sum(axis=1, keepdims=True)
    assert np.ptp(hue[:, 0]) > 0.3 and np.ptp(hue[:, 1]) > 0.3 and np.ptp(hue[:, 2]) > 0.3
    ks = sorted(abs(g[0]) for g in table)                   # no mirrored pairs k, -k
    assert all(abs(g[0] + h[0]) > 0.05 for g in table for h in table if g is not h)
    assert len(DEFAULT_GHOSTS) == 8 and ks[0] > 0
    # per-ghost softness and rim from the table, else the parameters
    got = parse_ghosts("0.5:0.05:1,1,1:0.3:0.9; -0.4:0.02:1,0,0", 2)
    assert got[0][3:] == (0.3, 0.9) and got[1][3:] == (None, None)
    with pytest.raises(ParamError):
        parse_ghosts("0.5:0.05:1,1,1:2", 1)
    # drawn: a crisp ring and a soft blob differ (rim: the ring's edge outshines its centre)
    src = np.zeros((120, 160, 4), np.float32)
    src[30, 130, :3] = 1e4
    p = LensFlare.params(model="artistic", threshold=5.0, halo_intensity=0.0,
                         ghosts="-1:0.12:1,1,1:0.05:0.95; 0.5:0.06:1,1,1:0.9:0.0")
    out = render_effect(rt, LensFlare(), p, src, camera=Camera(blades=0))[..., 1]
    cx, cy = 80.0, 60.0
    gx, gy = cx - (130.5 - cx), cy - (30.5 - cy)             # the ring, k = -1
    r = 0.12 * math.hypot(160, 120)
    centre = out[int(gy), int(gx)]
    rim_px = out[int(gy), int(gx + 0.9 * r)]
    assert rim_px > 3 * centre > 0
    np.testing.assert_allclose(out, expected(src, p, Camera(blades=0))[..., 1], rtol=1e-4,
                               atol=1e-5 * out.max())


def test_unclipped_bright_lights_take_less_gain(rt):
    """A light recorded at peak P takes min(gain, max(3, light_level / P)) of the gain: a
    clipped lamp at 20 the whole default gain (50), an HDR flame at 200 5, a sun at 1e5 3
    (CandleGlass's flame at the whole gain laid ghosts far brighter than the real ghosts in
    that photograph)."""
    from clfx.plugins.lens_flare import DEFAULT_GAIN, DEFAULT_LIGHT_LEVEL, GAIN_FLOOR, light_gain

    assert DEFAULT_LIGHT_LEVEL / 20.0 >= DEFAULT_GAIN
    assert light_gain(DEFAULT_GAIN, DEFAULT_LIGHT_LEVEL, 20.0) == 1.0
    # 1e3 / 200 since issue 32 (1e4 / 200 = 50 before: ghosts 10 times the real ones)
    assert light_gain(DEFAULT_GAIN, DEFAULT_LIGHT_LEVEL, 200.0) * DEFAULT_GAIN == pytest.approx(5)
    assert light_gain(DEFAULT_GAIN, DEFAULT_LIGHT_LEVEL, 1e5) * DEFAULT_GAIN == GAIN_FLOOR
    assert light_gain(2.0, DEFAULT_LIGHT_LEVEL, 1e5) == 1.0        # below the floor: all of it
    assert light_gain(10.0, 0.0, 1e5) == 1.0                       # 0: the whole gain
    bg = 0.01
    added = []
    for ratio in (2000.0, 20000.0):               # the light at 20 and at 200
        src = point_light_frame(background=bg, ratio=ratio)
        p = LensFlare.params(lens="zoom-80-200mm", cull=0.0)
        _, (entries, _, _, lights) = planned(rt, p, src, camera=Camera(), quality="draft")
        added.append(entries[:, 13:16].max())
        assert len(lights) == 1
    # ten times the recorded light, a tenth of the gain: the same ghosts
    assert added[1] == pytest.approx(added[0], rel=1e-6)


def test_defaults_on_a_sun_lay_faint_ghosts_and_no_veil_disc(rt):
    """Issue 32 item 6: the gallery's sunny day at the defaults (through the production path)
    laid a pink veil disc round the sun (a ghost 0.1 of the diagonal wide) and a ghost at 17
    times diffuse white (1.7e-4 of the sun's peak: the gain floor 30).  A multi-coated
    lens's ghost of an unclipped sun carries R1 R2 ~1e-5-2.5e-5 of its light (Fresnel, the
    stacks' 0.3-0.5 % per surface): now at most 5e-5 of the sun's peak, still seen against
    the dark ground (> 0.1 of diffuse white); no ghost wider than 10 % of the diagonal."""
    from clfx.api import render_array
    from clfx.gallery import sun_scene

    w, h = 320, 180
    src = sun_scene(w, h).rgba
    out = render_array(src, {"name": "t", "schema": 1, "effects": [{"effect": "lens_flare"}]})
    added = (out.rgba[..., :3] - src[..., :3]) @ np.array([0.2126, 0.7152, 0.0722])
    lum = src[..., :3] @ np.array([0.2126, 0.7152, 0.0722])
    ys, xs = np.mgrid[0:h, 0:w] + 0.5
    sun = np.hypot(xs - 0.78 * w, ys - 0.3 * h)
    away = sun > 0.008 * w + 4
    assert 0.1 <= added[away].max() <= 5e-5 * lum.max()
    # the veil disc: the sky round the sun (1-6 % of the diagonal out) gained 168 %, now 8 %
    ring = (sun > 0.01 * math.hypot(w, h)) & (sun < 0.06 * math.hypot(w, h))
    assert np.median(added[ring] / lum[ring]) < 0.15
    ctx, (entries, _, _, _) = planned(rt, LensFlare.params(), src, camera=Camera())
    assert (entries[:, 7:10].max(axis=1) <= 0.1 * math.hypot(w, h)).all()
