import math

import numpy as np
import pytest

from clfx.bench import metrics
from clfx.bench.groundtruth import render_truth
from clfx.bench.scene import demo_scene, render_sharp
from clfx.core.camera import Camera
from clfx.core.plugin import QUALITY_LEVELS
from clfx.core.rect import Rect
from clfx.plugins import dof as dof_module
from clfx.plugins.dof import LEVELS, Dof, quantised_radius, tap_counts, tap_table
from tests.conftest import hard_shapes
from tests.reference import dof as reference
from tests.effects import render_effect

# 50 mm f/2 on a 36 mm sensor focused at 3 m: K (CoC at infinity) = 0.424 mm.
CAM = Camera(focal_length=50.0, f_number=2.0, sensor_width=36.0, focus_distance=3.0)


def lens(width, height, p=None, cam=CAM):
    """(k_half, focus, clamp_r) as the plugin computes them."""
    p = p or Dof.params()
    f = cam.focal_length
    k = (f / cam.f_number) * f / (cam.focus_distance * 1000 - f) * width / cam.sensor_width
    return 0.5 * k, cam.focus_distance, 0.5 * p.max_coc * math.hypot(width, height)


def ca_offsets(width, cam, p):
    """Red and blue signed CoC radius offsets (px) of the axial CA: -delta / N on the
    sensor (delta: the channel's focus behind green, um), half of it in radius."""
    n = p.f_number or cam.f_number
    px_per_mm = width / cam.sensor_width
    return tuple(-0.5 * (c + d) * 1e-3 / n * px_per_mm
                 for c, d in ((cam.axial_ca_red, p.axial_ca_red),
                              (cam.axial_ca_blue, p.axial_ca_blue)))


def tables(radius, near, lvl, aspect=1.0, blades=0, first=-0.5 * math.pi, roundness=0.0,
           squeeze=1.0):
    """The oracle's ``taps`` and sharp table (``sharp_taps``, ``sharp_radius``) of a frame
    whose tiles all gather over ``radius`` with the largest near-field radius ``near``, as
    the plugin builds them (its sharp table: the radius ``max(near, sharp_radius)``, with
    every pixel of the sharp radius a far-field tap)."""
    taps = tap_table(radius, lvl.lattice, aspect, blades, first, roundness,
                     dense=lvl.dense_radius, squeeze=squeeze)
    sharp = min(float(quantised_radius(max(near, lvl.sharp_radius))), radius)
    return dict(taps=taps, sharp_radius=lvl.sharp_radius,
                sharp_taps=tap_table(sharp, lvl.lattice, aspect, blades, first, roundness,
                                     dense=lvl.dense_radius, squeeze=squeeze,
                                     core=lvl.sharp_radius))


def oracle(src, depth, quality, cam=CAM, **params):
    """The float64 oracle with the plugin's taps for one neighbourhood radius (images of up to
    3 x 3 tiles, where the tile dilation makes the radius uniform)."""
    h, w = depth.shape
    p = Dof.params(**params)
    k_half, focus, clamp_r = lens(w, h, p, cam)
    offsets = ca_offsets(w, cam, p)
    radius = max(float(quantised_radius(np.abs(reference.coc_radius(
        depth, k_half=k_half, focus=focus, clamp_r=clamp_r, offset=o)).max()))
        for o in (0.0, *offsets))
    near = max(float(np.maximum(-reference.coc_radius(
        depth, k_half=k_half, focus=focus, clamp_r=clamp_r, offset=o), 0.0).max())
        for o in (0.0, *offsets))
    lvl = LEVELS[quality]
    blades = cam.blades if p.blades < 0 else p.blades
    squeeze = p.anamorphic_squeeze or cam.anamorphic_squeeze
    ov = cam.optical_vignetting if p.optical_vignetting < 0 else p.optical_vignetting
    fr = (cam.optical_vignetting_front if p.optical_vignetting_front < 0
          else p.optical_vignetting_front)
    kw = dict(k_half=k_half, focus=focus, clamp_r=clamp_r,
              **tables(radius, near, lvl, 1.0, blades,
                       -0.5 * math.pi + math.radians(cam.blade_rotation + p.blade_rotation),
                       p.roundness, squeeze),
              cateye=reference.cateye_centres((h, w), ov) if ov > 0 else None,
              cateye_front=reference.cateye_centres((h, w), -fr) if fr > 0 else None)
    if any(offsets):
        return reference.dof_chromatic(src, depth, offsets=offsets, **kw)
    return reference.dof(src, depth, **kw)


def run(rt, src, depth, quality="final", cam=CAM, **params):
    return render_effect(rt, Dof(), Dof.params(**params), src, depth=depth, camera=cam,
                         quality=quality)


def random_case(rng, shape, zmin=0.8, zmax=40.0):
    src = rng.uniform(0.0, 2.0, shape + (4,)).astype(np.float32)
    depth = np.exp(rng.uniform(math.log(zmin), math.log(zmax), shape)).astype(np.float32)
    # blocky depth: layers with edges, like a real depth pass
    depth = np.repeat(np.repeat(depth[::4, ::4], 4, 0), 4, 1)[:shape[0], :shape[1]]
    return src, np.ascontiguousarray(depth)


# -- taps that add nothing -----------------------------------------------------------------
@pytest.mark.parametrize("table", [
    tap_table(10.0, 32, dense=32.0),
    tap_table(12.5, 32, 1.0, 6, -0.5 * math.pi, 0.3, dense=32.0, squeeze=1.5),
    tap_table(60.0, 12, 2.0, dense=16.0, core=6.0),
], ids=["disk", "hexagon-anamorphic", "lattice-core"])
def test_tap_counts_hold_every_tap_a_radius_reaches(table):
    counts = tap_counts(table)
    far = np.minimum(table[:, 2].astype(np.float64), table[:, 3]) - 0.5 * np.exp2(table[:, 7])
    assert counts[-1] == len(table) and np.all(np.diff(counts) >= 0)
    for k, n in enumerate(counts):
        # every tap left out lies beyond radius k / 2 plus its coverage ramp's half width
        assert np.all(far[n:] >= 0.5 * k)
        assert n == 0 or far[n - 1] < 0.5 * k

def test_tap_counts_of_a_disk():
    counts = tap_counts(tap_table(10.0, 32, dense=32.0))
    assert counts[2] == 9      # radii up to 1 px: the 3 x 3 taps around the pixel
    assert counts[0] == counts[1] == 1   # up to 1/2 px: the pixel itself


def test_lattice_levels_of_a_tile_grid_are_each_radius_lattice_level():
    """The per-tile table's lattice levels (issue 37: once per distinct radius, not per
    tile) are :func:`lattice_level` of each tile's radius, the dense boundary and exact
    powers of two included."""
    radii = quantised_radius(np.linspace(0.0, 300.0, 4002)).reshape(58, 69)
    radii[0, :6] = (0.0, 16.0, 16.5, 32.0, 64.0, 256.0)
    for lattice, dense in ((12, 16.0), (32, 32.0), (8, 0.0)):
        levels = dof_module.lattice_levels(radii, lattice, dense)
        want = [[dof_module.lattice_level(float(r), lattice, dense) for r in row] for row in radii]
        assert levels.shape == radii.shape and levels.dtype == np.int64
        np.testing.assert_array_equal(levels, want)


def test_gather_mask_tests_match_any_and_all(rt, tmp_path):
    """lib/common.h's clfx_any4 / clfx_all4 (the dof and motion gathers' branch-free
    per-tap tests) agree with OpenCL's any() / all() on every mask of 4 lanes."""
    from pathlib import Path

    from clfx.device.runtime import Runtime

    dof_cl = Path(__file__).resolve().parents[2] / "kernels" / "dof.cl"
    (tmp_path / "probe.cl").write_text(
        f'#include "{dof_cl}"\n'
        "kernel void probe(global int *out) {\n"
        "  const int i = get_global_id(0);\n"
        "  const int4 m = -(int4)(i & 1, (i >> 1) & 1, (i >> 2) & 1, (i >> 3) & 1);\n"
        "  out[2 * i] = clfx_any4(m) == any(m); out[2 * i + 1] = clfx_all4(m) == all(m); }\n")
    probe = Runtime(device=rt.device)
    probe.kernel_dir = tmp_path
    knl = probe.kernel("probe.cl", "probe", arg_types="buf out")
    out = probe.to_device(np.zeros(32, np.int32))
    probe.launch(knl, (16,), out, wait=True)
    assert probe.from_device(out, np.int32, 32).tolist() == [1] * 32


def dof_scene(shape=(96, 128)):
    """A far background (CoC ~10 px), an in-focus subject and a blurred near blob, with
    highlights on each."""
    h, w = shape
    yy, xx = np.mgrid[:h, :w]
    depth = np.full(shape, 60.0, np.float32)
    depth[h // 4:3 * h // 4, w // 3:2 * w // 3] = 3.0                        # in focus
    depth[(yy - h // 2) ** 2 + (xx - w // 6) ** 2 < (h // 6) ** 2] = 1.2      # near
    src = np.full(shape + (4,), 0.2, np.float32)
    src[::9, ::11, :3] = 40.0
    src[..., 3] = 1.0
    return src, depth


@pytest.mark.parametrize("quality", ["draft", "final", "reference"])
@pytest.mark.parametrize("params", [{}, {"optical_vignetting": 0.8, "anamorphic_squeeze": 1.5},
                                    {"axial_ca_red": 60.0, "blades": 6}],
                         ids=["plain", "cateye-anamorphic", "axial-ca"])
def test_gather_leaves_out_only_taps_that_add_nothing(rt, monkeypatch, quality, params):
    """The gather stops each table at the taps the pixels' radii and the near field reach
    (tap_counts): the same bits as every tap of the table, on a frame with in-focus pixels
    beside a far background and a near blob."""
    src, depth = dof_scene()
    cam = CAM.updated(sensor_width=8.0)
    got = run(rt, src, depth, quality, cam, **params)
    monkeypatch.setattr(dof_module, "tap_counts", lambda table: np.array([len(table)], np.int32))
    every = run(rt, src, depth, quality, cam, **params)
    assert np.array_equal(got.view(np.uint32), every.view(np.uint32))


@pytest.mark.parametrize("quality", ["draft", "final", "reference"])
@pytest.mark.parametrize("params", [{}, {"optical_vignetting": 0.8, "anamorphic_squeeze": 1.5},
                                    {"optical_vignetting": 0.6, "optical_vignetting_front": 0.6,
                                     "axial_ca_red": 60.0, "blades": 6}],
                         ids=["plain", "cateye-anamorphic", "both-rims-axial-ca"])
def test_blocks_of_four_taps_give_the_bits_of_tap_by_tap(rt, monkeypatch, quality, params):
    """The gather adds 4 taps at a time (float16 weights, each tap's sums in table order)
    where no mixed edge pixel is within reach: the same bits as its build that goes tap by
    tap (DOF_TAP_BY_TAP), on a frame with in-focus pixels beside a far background and a
    near blob (near and far fields, the hidden background's cap, tables stopped mid-block,
    sparse lattices, both resolutions, the cat-eye variants)."""
    src, depth = dof_scene((96, 160))
    depth[60:, 100:] = 0.6              # a large near blur: sparse lattice tables
    cam = CAM.updated(sensor_width=8.0)
    blocks = run(rt, src, depth, quality, cam, **params)
    kernel = rt.kernel

    def tap_by_tap(file, name, *args, **defines):
        if name == "dof_gather":
            defines["DOF_TAP_BY_TAP"] = 1
        return kernel(file, name, *args, **defines)
    monkeypatch.setattr(rt, "kernel", tap_by_tap)
    every = run(rt, src, depth, quality, cam, **params)
    assert np.array_equal(blocks.view(np.uint32), every.view(np.uint32))


@pytest.mark.parametrize("refine", [0.15, 0.5, 1.0, 100.0, math.inf])
def test_refine_bounds_decide_as_the_logarithm(refine):
    """dof_gather takes a logarithm only for luminance ratios within 1e-4 of exp(refine)
    (refine_bounds): below the lower bound the ratio always passes the refine test, above
    the upper one it always fails, as log(ratio) <= refine decides (infinite ratios too)."""
    _, lo, hi, _ = (np.float32(v) for v in dof_module.refine_bounds(refine))
    e = math.exp(min(refine, 80.0))
    ratios = np.concatenate([np.float32(e) * np.linspace(0.99, 1.01, 2001, dtype=np.float32),
                             np.array([1.0, 3.4e38, np.inf], np.float32)])
    with np.errstate(over="ignore"):
        for ratio in ratios:
            want = bool(np.log(np.float64(ratio)) <= refine)
            if ratio <= lo:
                assert want, (ratio, lo)
            elif ratio > hi:
                assert not want, (ratio, hi)


@pytest.mark.parametrize("case", ["hostile-depths", "pixel-aspect-2", "grown", "tiled"])
def test_gather_leaves_out_only_taps_that_add_nothing_anywhere(rt, monkeypatch, case):
    """The tiles' bound of the near-field radii holds for invalid depths (in focus, with an
    axial-CA offset in front of it), non-square pixels (taps twice as far in rows), a data
    window inside the display window (the render grown past it) and bands of a tiled
    render: the same bits as every tap."""
    src, depth = dof_scene()
    kw, params = {}, {"axial_ca_red": 200.0}
    if case == "hostile-depths":
        # every valid depth ~1 px of CoC behind the focus plane, 0.2 px in red (its axial CA
        # focuses 0.8 px in front): only the invalid depths lie in front of it, in red
        depth[:] = 4.26
        depth[5:20, 70:90] = np.nan
        depth[30:40, 5:15] = 0.0
        depth[60:70, 100:120] = -2.0
        depth[80:, :30] = np.inf
    elif case == "pixel-aspect-2":
        kw = {"pixel_aspect": 2.0}
    elif case == "grown":
        h, w = depth.shape
        kw = {"data_window": Rect(20, 10, 20 + w, 10 + h),
              "display_window": Rect(0, 0, w + 40, h + 20)}
    else:
        kw = {"tile_pixels": 3000}
    cam = CAM.updated(sensor_width=8.0)

    def render():
        return render_effect(rt, Dof(), Dof.params(**params), src, depth=depth, camera=cam,
                             quality="final", **kw)
    got = render()
    monkeypatch.setattr(dof_module, "tap_counts", lambda table: np.array([len(table)], np.int32))
    assert np.array_equal(got.view(np.uint32), render().view(np.uint32))


def _near_bound_oracle(near, table, tile):
    """Per tile, the largest near radius of a tile a tap can read (within 2 px of where it
    lands from any pixel of the tile: a group of 4 lies in one tile) and light from it:
    that tile's radius above the tap's near distance less half its lattice spacing."""
    h, w = near.shape
    reach = table[:, 2].astype(np.float64) - 0.5 * np.exp2(table[:, 7])
    out = np.zeros_like(near)
    for ty in range(h):
        for tx in range(w):
            for (ox, oy), e in zip(table[:, :2].astype(int), reach):
                for y in range(max(0, (ty * tile + oy - 2) // tile),
                               min(h - 1, (ty * tile + tile - 1 + oy + 2) // tile) + 1):
                    for x in range(max(0, (tx * tile + ox - 2) // tile),
                                   min(w - 1, (tx * tile + tile - 1 + ox + 2) // tile) + 1):
                        if near[y, x] > e:
                            out[ty, tx] = max(out[ty, tx], near[y, x])
    return out


@pytest.mark.parametrize("table", [
    tap_table(40.0, 32, dense=64.0),
    tap_table(30.0, 12, 2.0, 6, -0.5 * math.pi, 0.3, dense=8.0, squeeze=1.5, core=4.0),
    tap_table(12.0, 32, dense=32.0),
], ids=["disk", "lattice-hexagon-anamorphic-core", "within-the-neighbours"])
def test_near_bounds_hold_every_near_radius_a_tap_can_take(rng, table):
    """The tiles' bound of the near radii their taps can be lit by (near_bounds) is at least
    every such radius (a brute-force walk over taps and the tiles they read), and leaves out
    a small near blur that no tap reaching it lets light."""
    near = np.where(rng.uniform(size=(6, 9)) < 0.3, rng.uniform(0.0, 40.0, (6, 9)), 1e-3)
    near[0, 0] = 3.0                                  # small, 8 tiles from the far corner
    for tile in (16, 32):
        got = dof_module.near_bounds(near, table, tile)
        assert np.all(got >= _near_bound_oracle(near, table, tile))
        assert np.all(got <= near.max())
    lone = np.full((6, 9), 1e-3)
    lone[0, 0] = 3.0
    got = dof_module.near_bounds(lone, table, 16)
    assert got[0, 4] == 1e-3    # within the old bound's span (_span_bound: 3.0), out of its light
    if np.abs(table[:, :2]).max() > 60:               # the table reaches it, its light not
        assert got[0, 0] == 3.0 and got[5, 8] == 1e-3


def _span_bound(near, table, tile):
    """The bound before near_bounds: every tile within the table's span."""
    span = math.ceil((float(np.abs(table[:, :2]).max()) + 2.0) / tile)
    grown = dof_module.dilate_tiles(np.pad(near, span), span)
    return grown[span:-span, span:-span]


def test_gather_leaves_out_a_small_near_blur_far_away(rt, monkeypatch):
    """A wide background blur (taps 2 tiles out) and a small near blur at the frame's far
    side: the tiles between take fewer taps (near_bounds), the same bits as every tap."""
    src, depth = dof_scene((64, 256))
    depth[:] = 60.0
    depth[16:48, 96:200] = 3.0                  # in focus
    depth[28:36, 240:248] = 2.8                 # a small near blur (~4 px)
    cam = CAM.updated(sensor_width=1.0)         # the background: taps 2 tiles out
    seen = []
    bounds = dof_module.near_bounds
    monkeypatch.setattr(dof_module, "near_bounds",
                        lambda near, table, tile: seen.append(
                            (bounds(near, table, tile), _span_bound(near, table, tile)))
                        or seen[-1][0])
    got = run(rt, src, depth, "final", cam)
    assert any(np.any(new < old) for new, old in seen)
    monkeypatch.setattr(dof_module, "tap_counts", lambda table: np.array([len(table)], np.int32))
    assert np.array_equal(got.view(np.uint32), run(rt, src, depth, "final", cam).view(np.uint32))


def test_down2_gives_the_bits_of_its_pixel_by_pixel_build(rt, rng):
    """dof_down2 takes 4 half-resolution pixels a work-item (float16 colours, float4
    luminance weights, dot(w, r) as PoCL's): the same bits as its build that goes pixel by
    pixel (DOF_DOWN2_PIXELWISE), over lit, dark, even and huge boxes, the rows' clamped
    ends and an odd height."""
    h, w = 9, 62
    col = rng.uniform(0.0, 4.0, (h, w, 4)).astype(np.float32)
    col[:, :8] = 0.0                                    # dark boxes: the plain mean
    col[2:4, 8:16] = 0.7                                # even boxes
    col[4:6, 16:24, :3] = np.float32(3e38)              # near FLT_MAX
    col[::3, 30:50:3, :3] *= 1e4                        # lights beside dim pixels
    coc = rng.uniform(-30.0, 30.0, (h, w)).astype(np.float32)
    src, radii = rt.upload(col), rt.upload(coc)
    assert src.pitch == radii.pitch

    def down2(**defines):
        half = (-(-h // 2), -(-w // 2) + 2)     # past the row's end: clamped reads
        hcol, hcoc = rt.image(half, 4), rt.image(half, 1)
        rt.launch(rt.kernel("dof.cl", "dof_down2", **defines),
                  (-(-hcol.pitch // 4), hcol.height), src, radii, src.pitch, h, hcol, hcoc,
                  hcol.pitch, hcol.height)
        return (rt.from_device(hcol, np.float32, hcol.pitch * hcol.height * 4),
                rt.from_device(hcoc, np.float32, hcoc.pitch * hcoc.height))
    for got, want in zip(down2(), down2(DOF_DOWN2_PIXELWISE=1)):
        assert np.array_equal(got.view(np.uint32), want.view(np.uint32))


# -- oracle --------------------------------------------------------------------------------
@pytest.mark.parametrize("quality", ["preview", "reference"])
@pytest.mark.parametrize("shape", [(17, 31), (40, 52), (64, 48)])
def test_dof_matches_reference(rt, rng, shape, quality):
    src, depth = random_case(rng, shape)
    cam = CAM.updated(sensor_width=8.0)      # CoCs up to ~20 px on these small frames
    got = run(rt, src, depth, quality, cam)
    want = oracle(src, depth, quality, cam)
    # float32 taps and weights, normalised sums of <= 3169 terms: ~1e-5 relative; a pixel whose
    # CoC sits within float32 rounding of a coverage edge can move one tap (one weight of
    # many), hence the small absolute allowance
    tol = 1e-9 if quality == "reference" else 1e-4
    np.testing.assert_allclose(got, want, rtol=max(tol, 2e-6), atol=2e-3 * src.max())
    assert np.abs(got - want).mean() < 1e-4 * src.max()


def test_dof_polygon_and_rotation_match_reference(rt, rng):
    src, depth = random_case(rng, (33, 45))
    cam = CAM.updated(sensor_width=8.0, blades=6, blade_rotation=10.0)
    got = run(rt, src, depth, "final", cam, roundness=0.3, blade_rotation=5.0)
    want = oracle(src, depth, "final", cam, roundness=0.3, blade_rotation=5.0)
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=2e-3 * src.max())  # as above
    assert np.abs(got - want).mean() < 1e-4 * src.max()


def test_uniform_plane_is_a_normalised_disk_blur_that_keeps_energy(rt, rng):
    src = np.zeros((64, 64, 4), np.float32)
    src[32, 32] = (1e4, 5e3, 1e3, 1.0)                   # a 1e4 HDR highlight
    depth = np.full((64, 64), 30.0, np.float32)
    cam = CAM.updated(sensor_width=8.0)
    got = run(rt, src, depth, "reference", cam)
    r = abs(reference.coc_radius(30.0, k_half=lens(64, 64, cam=cam)[0], focus=3.0, clamp_r=1e9))
    # energy: the same normalised kernel everywhere (float64 accumulation)
    assert abs(got[..., 0].sum() / 1e4 - 1) < 1e-5
    # a disk of the CoC radius (coverage edge of +-0.5 px)
    lit = np.nonzero(got[..., 0] > 1e-3)
    extent = np.hypot(lit[0] - 32, lit[1] - 32).max()
    assert r - 1 <= extent <= r + 1.5, (extent, r)
    # weights are float32 even at the reference level (sums are float64): a few ulps
    np.testing.assert_allclose(got, oracle(src, depth, "reference", cam), rtol=5e-6, atol=1e-6)


def test_constant_image_stays_constant(rt, rng):
    src = np.full((40, 70, 4), 0.37, np.float32)
    _, depth = random_case(rng, (40, 70))
    for q in QUALITY_LEVELS:
        got = run(rt, src, depth, q, CAM.updated(sensor_width=8.0))
        np.testing.assert_allclose(got, 0.37, rtol=2e-6)   # normalised float32 sums


# -- edges ---------------------------------------------------------------------------------
def test_in_focus_edge_does_not_bleed_and_stays_sharp(rt, rng):
    # left: in focus; right: far behind; nothing in front of the focus plane
    src = rng.uniform(0.0, 1.0, (32, 64, 4)).astype(np.float32)
    src[:, 32:, :3] += 50.0                             # bright blurred background
    depth = np.full((32, 64), 3.0, np.float32)
    depth[:, 32:] = 1e4
    got = run(rt, src, depth, "final", CAM.updated(sensor_width=8.0))
    # every far tap is rejected for an in-focus pixel: it is exactly the input
    np.testing.assert_array_equal(got[:, :32], src[:, :32])
    # the background next to the edge does not take the sharp side's (dark) colour
    assert got[:, 32:36, 0].min() > 40.0


def test_blurred_foreground_spreads_over_the_sharp_background(rt):
    src = np.zeros((32, 64, 4), np.float32)
    src[..., 3] = 1.0
    src[:, :32, 0] = 10.0                               # near red plane, left
    src[:, 32:, 1] = 1.0                                # in-focus green, right
    depth = np.full((32, 64), 3.0, np.float32)
    depth[:, :32] = 1.0
    cam = CAM.updated(sensor_width=3.0)
    got = run(rt, src, depth, "final", cam, max_coc=0.25)
    r = abs(reference.coc_radius(1.0, k_half=lens(64, 32, cam=cam)[0], focus=3.0, clamp_r=1e9))
    assert r > 8
    # the foreground's light reaches into the in-focus side, fading with distance
    assert got[16, 33, 0] > 2.0 and got[16, 33, 0] > got[16, 36, 0] > got[16, 39, 0]
    assert got[16, 32 + int(r) + 2, 0] == 0.0
    # naive per-pixel-CoC blur keeps the sharp side clean: the defect this fixes
    naive = reference.naive_dof(src, depth, k_half=lens(64, 32, cam=cam)[0], focus=3.0, clamp_r=1e9)
    assert naive[16, 33, 0] == 0.0


# -- against ground truth --------------------------------------------------------------------
@pytest.fixture(scope="module")
def gt_case():
    cam = Camera(focal_length=50.0, f_number=1.4, sensor_width=36.0 / 3, focus_distance=3.0)
    scene = demo_scene(12, 240, 136)
    sharp = render_sharp(scene, ss=2)
    truth = render_truth(scene, cam, samples=1024, ss=2)
    return cam, sharp, truth


def test_gather_beats_naive_in_the_edge_band(rt, gt_case):
    cam, sharp, truth = gt_case
    band = metrics.edge_band(sharp.depth, None, 4)
    w, h = sharp.rgba.shape[1], sharp.rgba.shape[0]
    k_half, focus, clamp_r = lens(w, h, cam=cam)
    naive = reference.naive_dof(sharp.rgba, sharp.depth, k_half=k_half, focus=focus,
                                clamp_r=clamp_r)
    e_naive = metrics.psnr_log(naive, truth, band)
    for q in ("preview", "final", "reference"):
        got = run(rt, sharp.rgba, sharp.depth, q, cam)
        assert metrics.psnr_log(got, truth, band) > e_naive + 0.5, q   # dB (measured 0.8-2.2)
        assert metrics.psnr_log(got, truth) > metrics.psnr_log(naive, truth), q


def test_error_falls_with_quality(rt, gt_case):
    cam, sharp, truth = gt_case
    err = {q: metrics.rmse(metrics.log_tonemap(run(rt, sharp.rgba, sharp.depth, q, cam)),
                           metrics.log_tonemap(truth)) for q in QUALITY_LEVELS}
    assert err["draft"] >= err["final"] and err["preview"] >= err["final"], err
    assert err["reference"] <= err["final"] * 1.05, err      # ground truth noise ~ a few %


@pytest.fixture(scope="module")
def large_case():
    """Large circles of confusion over each other (the bench's dof:large at 192 x 108, the
    same CoC in pixels): a lit wall blurred 45 px, a sign 30 px, an in-focus subject,
    foreground posts -40 and -22 px, lights on the frame's top edge; its thin-lens truth
    (2048 renders)."""
    from clfx.bench.cases.dof import large_scene, render_case
    scene, cam = large_scene(192, 108)
    cam = cam.updated(sensor_width=cam.sensor_width * 192 / 320)
    return render_case(scene, cam, ss=2, samples=2048)


def test_large_circles_of_confusion_beat_naive_at_every_level(rt, large_case):
    """Issue 35: at 20-45 px of CoC every level beats the naive gather by 1 dB overall and
    in the edge band.  Before: an in-focus subject beside a 40 px foreground blur took its
    own far field from the sparse lattice (blurred by its tent), and a light on the frame's
    edge row was repeated into a streak past the edge (clamp-to-edge): every level lost to
    the naive gather (draft -0.65 dB overall, -0.66 dB in the edge band; now +1.5, +1.6)."""
    case = large_case
    src, depth, truth, cam = case["source"], case["depth"], case["truth"], case["camera"]
    h, w = depth.shape
    k_half, focus, clamp_r = lens(w, h, cam=cam)
    assert 40 < k_half * (1 - focus / 12.0) < 50          # the wall's CoC radius
    naive = reference.naive_dof(src, depth, k_half=k_half, focus=focus, clamp_r=clamp_r)
    band = metrics.edge_band(depth, None, 4)
    base = metrics.psnr_log(naive, truth), metrics.psnr_log(naive, truth, band)
    for q in QUALITY_LEVELS:
        got = run(rt, src, depth, q, cam)
        score = metrics.psnr_log(got, truth), metrics.psnr_log(got, truth, band)
        assert score[0] > base[0] + 1.0 and score[1] > base[1] + 1.0, (q, score, base)


def test_in_focus_pixels_beside_a_large_near_blur_stay_sharp(rt):
    """An in-focus 1-px checker in a tile within reach of a 30 px foreground blur, beyond
    that blur's own reach: unchanged at every level (their far field is their own radius's
    every pixel, not the sparse lattice that the near field needs; before, draft and preview
    read them through the lattice's prefilter tent: a soft copy of the checker)."""
    ys, xs = np.mgrid[0:64, 0:128]
    src = np.zeros((64, 128, 4), np.float32)
    src[..., :3] = (((xs + ys) % 2) * 0.8 + 0.1)[..., None]
    src[..., 3] = 1.0
    depth = np.full((64, 128), 3.0, np.float32)          # in focus
    depth[:, :8] = 1.5                                   # a foreground post
    cam = CAM.updated(sensor_width=0.9)
    r = reference.coc_radius(1.5, k_half=lens(128, 64, cam=cam)[0], focus=3.0, clamp_r=1e9)
    assert -34 < r < -26
    for q in QUALITY_LEVELS:
        got = run(rt, src, depth, q, cam)
        np.testing.assert_allclose(got[:, 44:64], src[:, 44:64], rtol=1e-5, err_msg=q)


def test_in_focus_pixels_in_a_group_with_far_blurred_ones_stay_sharp(rt):
    """An in-focus checker whose edge against a wall blurred 40 px falls inside a group of 4
    (2 pixels in focus, 2 far): its edge pixels are unchanged at every level.  Before, the
    group gathered with the wall's sparse lattice, whose centre tap gave the in-focus
    pixels their own pixel through the prefilter tent: Cycles' dof_large subject lost up to
    0.34 of 0.75 two pixels inside its edge at draft, 0.03-0.12 at final."""
    ys, xs = np.mgrid[0:64, 0:128]
    src = np.zeros((64, 128, 4), np.float32)
    src[..., :3] = (((xs + ys) % 2) * 0.8 + 0.1)[..., None]
    src[:, 66:, :3] = (0.05, 0.1, 1.5)                    # a blue wall, off the grey line
    src[..., 3] = 1.0
    depth = np.full((64, 128), 3.0, np.float32)          # in focus
    depth[:, 66:] = 30.0                                 # the wall: the group 64..67 straddles
    cam = CAM.updated(sensor_width=0.6)
    r = reference.coc_radius(30.0, k_half=lens(128, 64, cam=cam)[0], focus=3.0, clamp_r=1e9)
    assert 36 < r < 44
    for q in QUALITY_LEVELS:
        got = run(rt, src, depth, q, cam, max_coc=1.0)
        np.testing.assert_allclose(got[:, :66], src[:, :66], rtol=1e-5, err_msg=q)


def test_sparse_lattice_groups_straddling_the_focus_match_reference(rt, rng):
    """Groups of 4 with pixels in focus beside out-of-focus ones under a sparse lattice
    (preview, radii up to 40 px) match the oracle: the in-focus ones take the sharp table."""
    src, depth = random_case(rng, (48, 64), zmin=0.3)
    depth[:, 2::8] = 3.0                     # in-focus columns inside the groups of 4
    depth[::8] = 3.0
    cam = CAM.updated(sensor_width=2.0)
    got = run(rt, src, depth, "preview", cam, max_coc=1.0)
    want = oracle(src, depth, "preview", cam, max_coc=1.0)
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=2e-3 * src.max())
    assert np.abs(got - want).mean() < 1e-4 * src.max()


def test_a_light_on_the_frame_edge_is_not_repeated_past_it(rt):
    """A light on the top row of a far wall: past the frame edge the clamp-to-edge copies
    of it are capped like hidden background, so the frame receives about the half of its
    bokeh that falls inside (not a streak of lights a CoC radius tall)."""
    src = np.full((64, 64, 4), 0.01, np.float32)
    src[..., 3] = 1.0
    src[0, 32, :3] = 1000.0
    depth = np.full((64, 64), 1e4, np.float32)
    cam = CAM.updated(sensor_width=0.7)                  # CoC radius ~ 20 px
    r = lens(64, 64, cam=cam)[0]
    assert 15 < r < 25
    for q in QUALITY_LEVELS:
        got = run(rt, src, depth, q, cam)
        excess = float((got[..., 1] - 0.01).sum())
        assert 0.3 * 1000 < excess < 0.7 * 1000, (q, excess)


# -- hard cases ------------------------------------------------------------------------------
@pytest.mark.parametrize("shape", hard_shapes())
def test_dof_hard_shapes(rt, rng, shape):
    src, depth = random_case(rng, shape)
    got = run(rt, src, depth, "final", CAM.updated(sensor_width=4.0))
    assert got.shape == src.shape and np.isfinite(got).all()
    if max(shape) <= 48:   # one neighbourhood radius: the oracle applies
        want = oracle(src, depth, "final", CAM.updated(sensor_width=4.0))
        np.testing.assert_allclose(got, want, rtol=1e-4, atol=2e-3 * src.max())


def test_bad_depths_and_colours(rt, rng):
    src = rng.uniform(0.0, 1.0, (24, 40, 4)).astype(np.float32)
    src[3, 5, 0] = np.nan
    src[10, 20, 1] = np.inf
    depth = np.full((24, 40), 20.0, np.float32)
    depth[0:4, 0:8] = 0.0
    depth[5:9, 0:8] = -3.0
    depth[10:14, 0:8] = np.nan
    depth[15:19, 0:8] = np.inf
    got = run(rt, src, depth, "final", CAM.updated(sensor_width=8.0))
    assert np.isfinite(got).all()
    depth2 = depth.copy()
    depth2[15:19, 0:8] = 1e30
    got2 = run(rt, src, depth2, "final", CAM.updated(sensor_width=8.0))
    np.testing.assert_array_equal(got, got2)          # z = inf equals z = 1e30
    # the CoC never exceeds the clamp: a tiny max_coc leaves a blur of at most its radius
    pt = np.zeros((32, 32, 4), np.float32)
    pt[16, 16] = 1e5
    small = run(rt, pt, np.full((32, 32), 1e3, np.float32), "final",
                CAM.updated(sensor_width=1.0), max_coc=4.0 / math.hypot(32, 32))
    assert np.ptp(np.nonzero(small[..., 0])[1]) <= 5


def test_huge_coc_and_pixel_aspect(rt, rng):
    src, depth = random_case(rng, (20, 30), zmin=0.06, zmax=0.1)   # CoC >> frame
    got = run(rt, src, depth, "draft", CAM, max_coc=0.25)
    assert np.isfinite(got).all()
    pt = np.zeros((40, 40, 4), np.float32)
    pt[20, 20] = 1e3
    d = np.full((40, 40), 1e3, np.float32)
    out = render_effect(rt, Dof(), Dof.params(), pt, depth=d, camera=CAM.updated(sensor_width=6.0),
                        pixel_aspect=2.0, quality="reference")
    ys, xs = np.nonzero(out[..., 0] > 1e-3)
    assert np.ptp(ys) > 1.5 * np.ptp(xs)      # wide pixels: the bokeh spans twice the rows


def test_identity_cases(rt, rng):
    src, depth = random_case(rng, (16, 16))
    from clfx.host import RenderContext

    p = Dof.params(coc_source="max_blur", max_blur=0.0)
    ctx = RenderContext(rt, rt.upload(src), depth=rt.upload(depth), camera=CAM)
    assert "is 0" in Dof().is_identity(p, ctx)
    got = render_effect(rt, Dof(), p, src, depth=depth, camera=CAM)
    assert np.array_equal(got, src)
    focus = np.full((16, 16), 3.0, np.float32)
    got = render_effect(rt, Dof(), Dof.params(), src, depth=focus, camera=CAM)
    assert np.array_equal(got, src)
    # small CoC everywhere: the reason names it
    ctx = RenderContext(rt, rt.upload(src), depth=rt.upload(focus), camera=CAM)
    assert "half a pixel" in Dof().is_identity(Dof.params(), ctx)


def test_max_blur_mode(rt, rng):
    src, depth = random_case(rng, (24, 24))
    diag = math.hypot(24, 24)
    got = run(rt, src, depth, "reference", CAM, coc_source="max_blur", max_blur=8.0 / diag)
    # max_blur: K = max_blur * diagonal; same geometry as a camera with that K
    h, w = depth.shape
    r = reference.coc_radius(depth, k_half=4.0, focus=3.0, clamp_r=0.5 * Dof.params().max_coc * diag)
    lvl = LEVELS["reference"]
    taps = tap_table(float(quantised_radius(np.abs(r).max())), lvl.lattice,
                     dense=lvl.dense_radius)
    want = reference.dof(src, depth, k_half=4.0, focus=3.0, clamp_r=0.5 * Dof.params().max_coc * diag, taps=taps)
    np.testing.assert_allclose(got, want, rtol=5e-6, atol=1e-6)   # float32 weights, float64 sums


def test_tiles_in_focus_are_copied_and_far_tiles_blurred(rt, rng):
    src = rng.uniform(0.0, 1.0, (96, 160, 4)).astype(np.float32)
    depth = np.full((96, 160), 3.0, np.float32)
    depth[:, 128:] = 100.0
    got = run(rt, src, depth, "final", CAM.updated(sensor_width=8.0))
    np.testing.assert_array_equal(got[:, :64], src[:, :64])   # beyond any reach: copied
    assert not np.allclose(got[:, 140:], src[:, 140:])


def test_bench_case_shape(monkeypatch):
    from clfx.bench.cases import dof as dof_case

    render_case = dof_case.render_case      # the shapes, not the truth: 16 renders, not 2048

    def few(*args, **kw):
        return render_case(*args, **{**kw, "samples": 16})

    monkeypatch.setattr(dof_case, "render_case", few)
    case = dof_case.CASE.make(64, 36, None)
    assert case["truth"].shape == case["source"].shape == (36, 64, 4)
    assert case["depth"].shape == (36, 64)


def test_half_resolution_tiles_match_full_resolution_on_smooth_content(rt):
    from clfx.host import RenderContext

    ys, xs = np.mgrid[0:96, 0:128].astype(np.float32)
    src = np.stack([xs / 128, ys / 96, 0.5 + 0.2 * np.sin(xs / 9.0), np.ones_like(xs)], axis=2)
    depth = np.full((96, 128), 50.0, np.float32)        # CoC radius ~ 8 px everywhere
    cam = CAM.updated(sensor_width=4.0)
    ctx = RenderContext(rt, rt.upload(src), depth=rt.upload(depth), camera=cam, quality="final")
    Dof().render(rt, Dof.params(max_coc=0.2), ctx)
    assert any("12 at half resolution" in n for n in ctx.notes), ctx.notes
    half = run(rt, src, depth, "final", cam, max_coc=0.2)
    full = run(rt, src, depth, "reference", cam, max_coc=0.2)
    inner = np.s_[16:-16, 16:-16]
    # a disk blur of a smooth image is smooth: 2x2 box + bilinear upsampling costs ~1e-3
    np.testing.assert_allclose(half[inner], full[inner], atol=5e-3)


@pytest.mark.parametrize("quality", ["draft", "final"])
def test_half_resolution_tiles_do_not_upsample_a_sharp_tile_beside_them(rt, quality):
    """A half-resolution tile's edge pixels sample the half-resolution pixels of the tile
    beside it; where that tile is not gathered at half resolution they hold its unblurred
    source: a sharp light in focus there came out as a streak of copies of the light along
    the tile's edge (up to 10x the truth on the Cycles case's lamps, issue 35: 0.45 dB and
    20 % more error at final than at reference).  A sparse table (the radius over the
    level's dense radius) does not gather such pixels again."""
    from clfx.host import RenderContext

    h, w = 96, 160
    src = np.zeros((h, w, 4), np.float32)
    src[..., :3], src[..., 3] = 0.5, 1.0
    depth = np.full((h, w), 1e4, np.float32)
    depth[:, :32] = 3.0                      # tile column 0 in focus
    src[:, :32, :3] = 0.2
    src[40:56, 30, :3] = 1e3                 # sharp lights on its last column
    cam = CAM.updated(sensor_width=1.6 if quality == "draft" else 1.0)
    p = Dof.params(max_coc=0.45)
    radius = lens(w, h, p, cam)[0]
    assert LEVELS[quality].dense_radius < radius < lens(w, h, p, cam)[2]
    ctx = RenderContext(rt, rt.upload(src), depth=rt.upload(depth), camera=cam, quality=quality)
    Dof().render(rt, p, ctx)
    assert any(" at half resolution" in n and " 0 at half" not in n for n in ctx.notes)
    got = run(rt, src, depth, quality, cam, max_coc=0.45)
    want = run(rt, src, depth, "reference", cam, max_coc=0.45)
    # the blurred tile beside: the light in front of it does not reach it (old: ~60 at x 32)
    np.testing.assert_allclose(got[36:60, 32:40], want[36:60, 32:40], atol=0.02)


def far_light(radius, lamp=0.0):
    """A frame of black with one light at its centre (a 1e4 pixel, or a disk of ``lamp`` px
    radius at 100) far out of focus: CoC radius ``radius`` px (depth at infinity)."""
    n = int(6 * radius + 8) // 4 * 4          # max_blur = 2 r / diagonal stays <= 0.25
    src = np.zeros((n, n, 4), np.float32)
    src[..., 3] = 1.0
    c = n // 2
    ys, xs = np.mgrid[0:n, 0:n]
    d = np.hypot(xs - c, ys - c)
    if lamp:
        src[d <= lamp, :3] = 100.0
    else:
        src[c, c, :3] = 1e4
    depth = np.full((n, n), np.inf, np.float32)
    p = dict(coc_source="max_blur", max_blur=2.0 * radius / math.hypot(n, n))
    return src, depth, p, d


def bokeh_structure(img, d, radius):
    """(coefficient of variation, pattern) of a light's bokeh interior (d <= 0.7 radius):
    std / mean, and the largest power of the Hann-windowed interior's spectrum away from 0
    over the power at 0 (a sampling pattern is a peak at its spacing's frequency)."""
    g = img[..., 1].astype(np.float64)
    inner = g[d <= 0.7 * radius]
    c, h = g.shape[0] // 2, int(0.45 * radius)
    crop = g[c - h:c + h, c - h:c + h]
    win = np.outer(np.hanning(2 * h), np.hanning(2 * h))
    f = np.abs(np.fft.fft2((crop - crop.mean()) * win)) ** 2
    return inner.std() / inner.mean(), f.max() / (crop.mean() * win.sum()) ** 2


@pytest.mark.parametrize("radius", [20, 40, 60])
def test_a_far_light_is_an_evenly_lit_disk_at_every_level(rt, radius):
    """issue 25: no sampling pattern in the bokeh.  A light far out of focus is an evenly lit
    disk (the float64 truth: exactly flat inside), at every level and radius: the sparse taps
    beyond the dense radius sample a prefiltered copy on a lattice whose tents sum to 1.
    Before (ring taps): interior std / mean up to 1.3 (draft), 0.67 (preview), 0.78
    (reference) at r = 40; 2.2, 1.2, 1.6 at r = 60 (a stippled lattice of rings)."""
    src, depth, p, d = far_light(radius)
    want = 1e4 / (math.pi * radius ** 2)          # the truth's flat interior
    for q in QUALITY_LEVELS:
        if q == "reference" and radius > 40:
            continue          # float64 at full resolution: 40 px already has sparse taps
        out = run(rt, src, depth, q, **p)
        cv, pattern = bokeh_structure(out, d, radius)
        assert cv < 0.01 and pattern < 1e-6, (q, cv, pattern)    # float32 sums: ~1e-4
        inner = out[..., 1][d <= 0.7 * radius]
        np.testing.assert_allclose(inner.mean(), want, rtol=0.03, err_msg=q)
        np.testing.assert_allclose(out[..., 1].sum(), 1e4, rtol=3e-3, err_msg=q)


def test_a_far_lamp_is_an_evenly_lit_disk_at_every_level(rt):
    """A lamp (a disk of 4 px radius) 50 px out of focus: its bokeh's interior (the disk of
    radius r - 4 where the truth, lamp x aperture, is flat) is flat at every level.  Before:
    std / mean 0.31 (draft), 0.20 (preview), 0.11 (reference) at r = 60."""
    src, depth, p, d = far_light(50, lamp=4.0)
    for q in ("draft", "preview", "final"):
        out = run(rt, src, depth, q, **p)
        cv, pattern = bokeh_structure(out, d, 50 - 4)
        assert cv < 0.01 and pattern < 1e-6, (q, cv, pattern)


def test_sparse_lattice_taps_match_reference(rt, rng):
    """The prefiltered lattices (levels 1 and 2 at preview: radii 16-32 and 32-64 px) match
    the oracle's plain float64 pyramid and gather."""
    src, depth = random_case(rng, (48, 64), zmin=0.3)
    depth[::8] = 3.0                         # every tile has sharp pixels: no half resolution
    cam = CAM.updated(sensor_width=2.0)      # CoC radii up to the clamp, 40 px
    got = run(rt, src, depth, "preview", cam, max_coc=1.0)
    want = oracle(src, depth, "preview", cam, max_coc=1.0)
    taps = tap_table(40.0, LEVELS["preview"].lattice, dense=LEVELS["preview"].dense_radius)
    assert taps[:, 7].max() == 2
    # as test_dof_matches_reference: float32 sums; a coverage edge within rounding moves a tap
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=2e-3 * src.max())
    assert np.abs(got - want).mean() < 1e-4 * src.max()


def test_bokeh_leaves_a_tight_data_window(rt):
    """dof spreads light: a far-out-of-focus light near the edge of a data window tighter
    than the display window lands past it (the region of definition grows by the largest
    CoC radius), with its energy kept."""
    from clfx.core.rect import Rect

    display, data = Rect(0, 0, 96, 64), Rect(32, 16, 64, 48)
    src = np.zeros((32, 32, 4), np.float32)
    src[16, 29] = 1e3
    depth = np.full((32, 32), 100.0, np.float32)
    cam = CAM.updated(sensor_width=3.0)            # CoC radius ~6.6 px at 100 m
    p = Dof.params(max_coc=0.25)
    k_half, focus, clamp_r = lens(display.width, display.height, p, cam)
    r = abs(reference.coc_radius(100.0, k_half=k_half, focus=focus, clamp_r=clamp_r))
    for q in ("draft", "reference"):
        out, window = render_effect(rt, Dof(), p, src, depth=depth, camera=cam, quality=q,
                                    data_window=data, display_window=display, keep_rod=True)
        assert window == data.grown(math.ceil(r) + 1), (window, r)
        right = out[:, data.x1 - window.x0:, 0]
        assert right.sum() > 0.15 * 1e3, q         # a good part of the disk is outside
        np.testing.assert_allclose(out[..., 0].sum(), 1e3, rtol=0.05)   # energy kept
        assert np.isfinite(out).all()
    # data window = display window: nothing to grow into
    out, window = render_effect(rt, Dof(), p, src, depth=depth, camera=cam, keep_rod=True)
    assert window == Rect(0, 0, 32, 32)


def test_tap_tables_live_in_the_runtime_cache(rt, rng):
    src, depth = random_case(rng, (24, 24))
    plugin, cam = Dof(), CAM.updated(sensor_width=4.0)
    got = render_effect(rt, plugin, Dof.params(), src, depth=depth, camera=cam, quality="preview")
    assert not np.array_equal(got, src)
    assert not vars(plugin)                          # no state on the instance
    assert rt.cache.stats()["owners"].get("dof.taps", 0) > 0


# -- renders: antialiased beauty, point-sampled depth ---------------------------------------
def _bar_scene():
    """A light 0.5 px beside a 7 px bar at 1 m (CoC 15 px) over a sharp wall at 3 m, another
    one 0.2 px beside the other edge, a third well away from the bar."""
    from clfx.bench.cases.dof import lens_for
    from clfx.bench.scene import Layer, Light, Scene, Texture

    lights = (Light((-4.0, -10.0), (1500.0, 1200.0, 900.0), 0.8),
              Light((3.7, 12.0), (400.0, 320.0, 240.0), 0.8),
              Light((20.0, 0.0), (900.0, 900.0, 900.0), 0.8))
    wall = Layer(depth=3.0, texture=Texture("noise", (0.45, 0.4, 0.32), (0.08, 0.08, 0.1),
                                            period=4.0, seed=9),
                 center=(48.0, 32.0), lights=lights, name="wall")
    bar = Layer(depth=1.0, texture=Texture("flat", (0.5, 0.45, 0.4)), shape="rect",
                center=(48.0, 32.0), size=(7.0, 80.0), name="bar")
    return Scene(96, 64, (wall, bar)), lens_for(7.5 * 320 / 96, 96)


@pytest.fixture(scope="module")
def bar_case():
    from clfx.bench.cases.dof import render_case

    scene, cam = _bar_scene()
    return render_case(scene, cam, ss=4, samples=4096)


def test_a_sharp_light_beside_a_blurred_bar_stays_a_sharp_light(rt, bar_case):
    """The beauty is supersampled, the depth taken at pixel centres: the light's pixels
    sampled on the bar carry the bar's depth.  They must not be spread with the bar's CoC
    (a bright half-disk); the light stays sharp, partly covered by the bar's blur."""
    c = bar_case
    src, depth, truth = c["source"], c["depth"], c["truth"]
    got = run(rt, src, depth, "final", c["camera"])
    lum = lambda a: a[..., :3].mean(axis=-1)
    for lx, ly in ((44, 22), (51, 44)):          # the lights beside the bar's edges
        win = np.s_[ly - 1:ly + 2, lx - 1:lx + 2]
        assert lum(got)[win].max() > 0.5 * lum(truth)[win].max()      # still a sharp light
        # around it, 3-7 px away, no disk of its light (the truth holds the blurred bar)
        yy, xx = np.mgrid[0:64, 0:96]
        ring = (np.hypot(xx - lx, yy - ly) >= 3) & (np.hypot(xx - lx, yy - ly) <= 7)
        excess = lum(got)[ring] - lum(truth)[ring]
        assert excess.max() < 0.3, (lx, ly, excess.max())
    band = metrics.edge_band(depth, None, 4)
    assert metrics.psnr_log(got, truth) > metrics.psnr_log(src, truth) + 1.0
    assert metrics.psnr_log(got, truth, band) > metrics.psnr_log(src, truth, band)


def test_edge_pixels_take_the_sharper_layer_only_when_they_look_like_it(rng):
    # the oracle's rule on a tiny case: a bright pixel on the blurred side of an edge whose
    # sharp side holds the same light moves; an ordinary texture pixel does not
    src = np.full((5, 6, 4), 0.3, np.float32)
    src[:, 3:, :3] = 0.5                          # blurred bar on the right
    src[2, 2, :3] = 600.0                         # light on the sharp side
    src[2, 3, :3] = 450.0                         # its part sampled on the bar
    r = np.zeros((5, 6))
    r[:, 3:] = -7.5
    out = reference.edge_radius(src, r)
    assert out[2, 3] == 0.0                       # the light's pixel joins the sharp wall
    changed = out != r
    changed[2, 3] = False
    assert not changed.any()


# -- the clamp -------------------------------------------------------------------------------
def test_a_clamp_warning_reaches_stderr_once_naming_effect_frame_and_coc(tmp_path):
    import subprocess
    import sys

    from clfx.core.frame import Frame
    from clfx.core.rect import Rect
    from clfx.io.write import write_frame

    rgba = np.zeros((32, 48, 4), np.float32)
    rgba[16, 24] = 1e3
    frame = Frame(rgba, Rect.from_size(48, 32), Rect.from_size(48, 32),
                  depth=np.full((32, 48), 1e3, np.float32))
    write_frame(frame, tmp_path / "in.0001.exr", write_passes=True)
    write_frame(frame, tmp_path / "in.0002.exr", write_passes=True)
    r = subprocess.run([sys.executable, "-m", "clfx.cli", "-q", "render",
                        str(tmp_path / "in.#.exr"), str(tmp_path / "out.#.exr"),
                        "--look", "default", "--set", "dof.max_coc=0.1",
                        "--set", "camera.sensor_width=1"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if "clamped" in ln]
    # the same text on both frames: said once, naming the first
    assert [ln.split(": dof:")[0] for ln in lines] == ["clfx: warning: frame 1"], r.stderr
    assert all("a CoC of" in ln and "max_coc = 0.1" in ln for ln in lines)


def test_a_clamp_that_bites_warns_once_naming_effect_frame_and_coc(rt):
    from clfx.host import RenderContext

    src = np.zeros((32, 48, 4), np.float32)
    src[16, 24] = 1e3
    depth = np.full((32, 48), 1e3, np.float32)
    cam = CAM.updated(sensor_width=1.0)          # K = 70 px at 48 px wide: far past max_coc
    p = Dof.params(max_coc=0.1)
    ctx = RenderContext(rt, rt.upload(src), depth=rt.upload(depth), camera=cam, frame=17)
    asked = abs(float(cam.coc_signed_px(1e3, 48)))
    Dof().render(rt, p, ctx)
    Dof().render(rt, p, ctx)                     # the same frame again: still one line
    assert len(ctx.warnings) == 1
    line = ctx.warnings[0]
    assert line.startswith("a CoC of") and "\n" not in line
    assert f"{asked:.1f} px" in line and f"{0.1 * math.hypot(48, 32):.1f} px" in line
    assert any(line in n for n in ctx.notes)
    # a lens inside max_coc: no warning
    ctx = RenderContext(rt, rt.upload(src), depth=rt.upload(depth), camera=CAM, frame=17)
    Dof().render(rt, Dof.params(), ctx)
    assert ctx.warnings == []


def test_the_default_max_coc_lets_a_physical_lens_through(rt):
    """85 mm f/1.35 focused at 1.2 m: a 40 px CoC at 320 px wide, no clamp by default."""
    from clfx.host import RenderContext

    assert Dof.params().max_coc >= 0.25
    cam = Camera(focal_length=85.0, f_number=1.35, sensor_width=36.0, focus_distance=1.2)
    src = np.zeros((180, 320, 4), np.float32)
    src[90, 160] = 1e4
    depth = np.full((180, 320), 1e4, np.float32)
    ctx = RenderContext(rt, rt.upload(src), depth=rt.upload(depth), camera=cam, frame=3)
    out = rt.download(Dof().render(rt, Dof.params(), ctx))
    assert ctx.warnings == []
    coc = abs(float(cam.coc_signed_px(1e4, 320)))
    assert coc > 40
    ys, xs = np.nonzero(out[..., 0] > 1e-3)
    assert np.ptp(xs) + 1 >= coc - 2              # the whole bokeh, not a clamped one


# -- overflow, real files ------------------------------------------------------------------
def test_wide_float_range_stays_finite_at_every_level(rt, exr_images):
    from clfx.io.read import read_frame

    fr = read_frame(exr_images / "TestImages" / "WideFloatRange.exr")   # +-1.7e38
    src = fr.rgba
    assert np.isfinite(src).all() and np.abs(src).max() > 1e38
    h, w = src.shape[:2]
    depth = np.repeat(np.linspace(1.0, 40.0, w, dtype=np.float32)[None], h, 0)
    cam = Camera(focal_length=50.0, f_number=1.4, sensor_width=36.0 * w / 320, focus_distance=3.0)
    for q in QUALITY_LEVELS:
        out = run(rt, src, depth, q, cam)
        assert np.isfinite(out).all(), q


def test_beachball_edge_widens_without_a_dark_outline(rt, exr_images):
    """The Beachball stores its background as Z = 0 (read as +inf by clfx.io; done here by
    hand): through the cinema look's lens the ball's soft edge gets wider and nowhere
    darker than the darker side, also over an opaque grey background."""
    from clfx.io.read import read_frame

    fr = read_frame(exr_images / "Beachball" / "multipart.0001.exr")
    depth = np.where(fr.depth == 0, np.inf, fr.depth).astype(np.float32)
    cam = Camera(focal_length=35.0, f_number=2.0, sensor_width=24.89, focus_distance=3.0,
                 blades=9)
    fg = np.isfinite(depth)
    ys, xs = np.nonzero(fg)
    cy, cx, R = ys.mean(), xs.mean(), math.sqrt(fg.sum() / math.pi)
    lum = lambda a: 0.2126 * a[..., 0] + 0.7152 * a[..., 1] + 0.0722 * a[..., 2]
    # the ball fills its data window but for the corners: profiles along the diagonals
    angles = [math.radians(a + d) for a in (45, 135, 225, 315) for d in range(-20, 21, 10)]
    t = np.arange(R - 20, R + 20)
    for grey in (0.0, 0.2):
        src = fr.rgba.copy()
        src[..., :3] += (1 - src[..., 3:4]) * grey
        if grey:
            src[..., 3] = 1.0
        out = render_effect(rt, Dof(), Dof.params(roundness=0.6), src, depth=depth, camera=cam,
                            data_window=fr.data_window, display_window=fr.display_window)
        for ang in angles:
            px = np.round(cx + t * math.cos(ang)).astype(int)
            py = np.round(cy + t * math.sin(ang)).astype(int)
            po = lum(out)[py, px]
            darker = min(po[:3].min(), po[-3:].min())
            assert po.min() >= darker - 2e-3, (grey, math.degrees(ang))
        if not grey:
            # wider: light lands outside the silhouette, where the source is black
            ring = ~fg & (np.hypot(*np.mgrid[0:fg.shape[0], 0:fg.shape[1]][::-1]
                                   - np.array([cx, cy])[:, None, None]) < R + 20)
            assert lum(src)[ring].max() == 0.0
            assert (lum(out)[ring] > 1e-3).sum() > 1000


# -- ground truth: bokeh rims ------------------------------------------------------------
@pytest.fixture(scope="module")
def bokeh_case():
    from clfx.bench.cases.dof import make_scene

    return make_scene("bokeh", 160, 90, ss=4, samples=4096)


def test_final_bokeh_is_as_crisp_as_the_reference_and_every_level_beats_naive(rt, bokeh_case):
    c = bokeh_case
    score, base = scores_against_truth(rt, c)
    assert score["final"] > score["reference"] - 1.0, score
    assert min(score.values()) > base, (score, base)


def test_bench_naive_is_the_reference_naive_gather(rt, rng):
    from clfx.bench.cases.dof import naive_dof

    src, depth = random_case(rng, (30, 41))
    k_half, focus, clamp_r = lens(41, 30, cam=CAM.updated(sensor_width=8.0))
    got = naive_dof(src, depth, k_half=k_half, focus=focus, clamp_r=clamp_r)
    want = reference.naive_dof(src, depth, k_half=k_half, focus=focus, clamp_r=clamp_r)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)


# -- lens geometry in the bokeh: cat-eye, anamorphic, axial chromatic aberration ------------
OPTIONS = {
    "cateye": dict(optical_vignetting=1.2),
    "cateye_front": dict(optical_vignetting_front=1.2),
    "cateye_both": dict(optical_vignetting=0.9, optical_vignetting_front=0.8),
    "anamorphic": dict(anamorphic_squeeze=1.8),
    "axial_ca": dict(axial_ca_red=60.0, axial_ca_blue=45.0),
}


@pytest.mark.parametrize("option", list(OPTIONS))
@pytest.mark.parametrize("quality", ["preview", "reference"])
def test_lens_geometry_options_match_reference(rt, rng, option, quality):
    src, depth = random_case(rng, (40, 52))
    cam = CAM.updated(sensor_width=8.0, blades=6 if option.startswith("cateye") else 0)
    got = run(rt, src, depth, quality, cam, **OPTIONS[option])
    want = oracle(src, depth, quality, cam, **OPTIONS[option])
    tol = 1e-9 if quality == "reference" else 1e-4
    # as test_dof_matches_reference: float32 weights, one tap may move at a coverage edge
    np.testing.assert_allclose(got, want, rtol=max(tol, 2e-6), atol=2e-3 * src.max())
    assert np.abs(got - want).mean() < 1e-4 * src.max()


def test_camera_block_drives_the_options_and_params_override_it(rt, rng):
    src, depth = random_case(rng, (33, 45))
    cam = CAM.updated(sensor_width=8.0, optical_vignetting=1.5, anamorphic_squeeze=1.33,
                      axial_ca_red=40.0, axial_ca_blue=40.0)
    got = run(rt, src, depth, "final", cam)
    want = oracle(src, depth, "final", cam)
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=2e-3 * src.max())
    # dof's overrides: 0 vignetting and squeeze 1 turn the camera's off; CA adds to it
    off = run(rt, src, depth, "final", cam, optical_vignetting=0.0, anamorphic_squeeze=1.0,
              axial_ca_red=-40.0, axial_ca_blue=-40.0)
    np.testing.assert_array_equal(off, run(rt, src, depth, "final", CAM.updated(sensor_width=8.0)))


def test_options_off_by_default_change_nothing(rt, rng):
    src, depth = random_case(rng, (40, 70))
    cam = CAM.updated(sensor_width=8.0)
    base = run(rt, src, depth, "final", cam)
    for kw in (dict(optical_vignetting=0.0), dict(anamorphic_squeeze=1.0),
               dict(axial_ca_red=0.0, axial_ca_blue=0.0)):
        np.testing.assert_array_equal(run(rt, src, depth, "final", cam, **kw), base)
    assert Camera().optical_vignetting == 0 and Camera().anamorphic_squeeze == 1
    assert Camera().axial_ca_red == Camera().axial_ca_blue == 0


def test_squeeze_below_one_and_camera_ranges_are_refused(rt):
    from clfx.core.errors import ParamError

    with pytest.raises(ParamError, match="anamorphic_squeeze"):
        Dof.params(anamorphic_squeeze=3.5)
    with pytest.raises(ParamError, match="anamorphic_squeeze"):
        run(rt, np.zeros((8, 8, 4), np.float32), np.full((8, 8), 9.0, np.float32), "final",
            CAM, anamorphic_squeeze=0.5)
    for name, bad in (("optical_vignetting", 2.5), ("anamorphic_squeeze", 0.9),
                      ("axial_ca_red", 2000.0)):
        with pytest.raises(ValueError):
            Camera.validate(name, bad)


def _lights_frame(h=96, w=144, depth=200.0, near=None):
    """HDR point lights near the corners, at the edges' middles and the centre."""
    src = np.zeros((h, w, 4), np.float32)
    src[..., :3] = 0.01
    src[..., 3] = 1.0
    pts = [(h // 2, w // 2), (14, 14), (14, w - 15), (h - 15, 14), (h - 15, w - 15),
           (h // 2, 14), (14, w // 2)]
    for y, x in pts:
        src[y, x, :3] = 1e3
    d = np.full((h, w), depth, np.float32)
    return src, d, pts


def _moments(img, y, x, rad):
    """Second moments of the light around (y, x): (along x, along y, mean offset)."""
    ys, xs = np.mgrid[-rad:rad + 1, -rad:rad + 1]
    a = img[y - rad:y + rad + 1, x - rad:x + rad + 1, 1] - 0.01
    a = np.maximum(a, 0)
    m = a.sum()
    mx, my = (a * xs).sum() / m, (a * ys).sum() / m
    return (a * (xs - mx) ** 2).sum() / m, (a * (ys - my) ** 2).sum() / m, (mx, my)


def test_cateye_bokeh_is_round_at_the_centre_and_tangential_at_the_edges(rt):
    src, d, pts = _lights_frame()
    cam = CAM.updated(sensor_width=4.0)           # CoC radius ~10 px at 200 m
    out = run(rt, src, d, "reference", cam, optical_vignetting=1.0)
    vx, vy, _ = _moments(out, *pts[0], 13)
    assert abs(vx / vy - 1) < 0.02                # round at the optical centre
    vx, vy, _ = _moments(out, *pts[5], 13)        # left edge: long axis vertical
    assert vy > 1.5 * vx
    vx, vy, _ = _moments(out, *pts[6], 13)        # top edge (nearer the centre): horizontal
    assert vx > 1.2 * vy
    for y, x in pts[1:5]:                         # corners: long axis across the radius
        ys, xs = np.mgrid[-13:14, -13:14]
        a = np.maximum(out[y - 13:y + 14, x - 13:x + 14, 1] - 0.01, 0)
        cov = np.cov(np.stack([xs.ravel(), ys.ravel()]), aweights=a.ravel())
        evals, evecs = np.linalg.eigh(cov)
        radial = np.array([x + 0.5 - 72, y + 0.5 - 48])
        radial /= np.hypot(*radial)
        assert evals[1] > 1.5 * evals[0] and abs(evecs[:, 1] @ radial) < 0.1, (y, x)
    # a flat field stays flat (the clipped aperture is normalised; darkening is vignette's)
    flat = run(rt, np.full_like(src, 0.5), d, "reference", cam, optical_vignetting=1.0)
    np.testing.assert_allclose(flat, 0.5, rtol=1e-6)


def _bokeh_profile(img, y, x, rad):
    """The bokeh of the light at pixel (y, x) in its radial / tangential frame (the radial
    axis from the frame's centre): the half-maximum mask sampled every 1/4 px, its width
    (px, across the tangential axis) per tangential position, those positions (px) and
    the centroid's radial offset from the light (px, + away from the centre)."""
    from scipy.ndimage import map_coordinates

    h, w = img.shape[:2]
    u = np.array([x + 0.5 - 0.5 * w, y + 0.5 - 0.5 * h])
    u /= np.hypot(*u)
    v = np.array([-u[1], u[0]])
    t = np.arange(-rad, rad + 0.01, 0.25)
    tt, ss = np.meshgrid(t, t, indexing="ij")       # [tangential, radial]
    px = x + tt * v[0] + ss * u[0]
    py = y + tt * v[1] + ss * u[1]
    g = map_coordinates(img[..., 1].astype(np.float64), [py, px], order=1)
    g = np.maximum(g - 0.01, 0.0)
    mask = g > 0.5 * np.percentile(g[g > 0], 90)
    radial = (g * ss).sum() / g.sum()
    return mask.sum(axis=1) * 0.25, t, radial


def test_both_rims_give_a_lemon_pointed_at_both_ends(rt):
    """Rear and front rim together: the corner's bokeh is the aperture cut by two circles on
    either side, a lemon whose width falls to a point at both ends (an ellipse keeps 60 %
    of its width at 80 % of its half length, this lemon 42 %, 46 % once blurred by the
    pixels), centred on the light;
    the rear rim alone shifts the bokeh away from the frame's centre, the front rim alone
    towards it."""
    h, w, y, x = 120, 200, 30, 160
    src = np.zeros((h, w, 4), np.float32)
    src[..., :3] = 0.01
    src[..., 3] = 1.0
    src[y, x, :3] = 1e3
    d = np.full((h, w), 200.0, np.float32)
    cam = CAM.updated(sensor_width=3.5)                 # CoC radius ~16 px
    both = run(rt, src, d, "reference", cam, optical_vignetting=1.0,
               optical_vignetting_front=1.0)
    width, t, radial = _bokeh_profile(both, y, x, 20)
    inside = np.nonzero(width > 0)[0]
    lo, hi = t[inside[0]], t[inside[-1]]
    half, mid = 0.5 * (hi - lo), 0.5 * (hi + lo)
    w0 = width[np.argmin(np.abs(t - mid))]
    ends = [width[np.argmin(np.abs(t - (mid + k * 0.8 * half)))] for k in (-1, 1)]
    assert half > 1.5 * w0 / 2, (half, w0)               # elongated across the radius
    # measured 0.475 and 0.45 of w0 (a disk or an ellipse: 0.6), half 9.4 px, w0 10 px
    assert max(ends) < 0.53 * w0 and min(ends) > 0.8 * max(ends), (ends, w0)
    assert abs(radial) < 1.0, radial
    _, _, rear = _bokeh_profile(run(rt, src, d, "reference", cam, optical_vignetting=1.0),
                                y, x, 20)
    _, _, front = _bokeh_profile(run(rt, src, d, "reference", cam,
                                     optical_vignetting_front=1.0), y, x, 20)
    assert rear > 2.0 and front < -2.0, (rear, front)


def test_front_rim_matches_its_truth_better_than_a_round_gather(rt):
    """The front rim's cat-eye against its thin-lens truth (the bench's ``cateye_front``
    scene, small): clipping with the front rim beats the round aperture and the rear rim."""
    from clfx.bench.cases.dof import make_scene

    c = make_scene("cateye_front", 160, 90, ss=2, samples=1024)
    assert c["camera"].optical_vignetting_front == 1.0
    score = {k: metrics.psnr_log(run(rt, c["source"], c["depth"], "final", c["camera"], **kw),
                                 c["truth"])
             for k, kw in (("front", {}), ("round", dict(optical_vignetting_front=0.0)),
                           ("rear", dict(optical_vignetting_front=0.0,
                                         optical_vignetting=1.0)))}
    assert score["front"] > score["round"] + 2.0 and score["front"] > score["rear"], score


def test_front_rim_is_validated_and_plumbed_from_the_camera_block(rt, rng):
    from clfx.core.errors import ParamError

    with pytest.raises(ValueError):
        Camera.validate("optical_vignetting_front", 2.5)
    with pytest.raises(ParamError, match="optical_vignetting_front"):
        Dof.params(optical_vignetting_front=2.5)
    assert Camera().optical_vignetting_front == 0
    src, depth = random_case(rng, (33, 45))
    plain = CAM.updated(sensor_width=8.0)
    cam = plain.updated(optical_vignetting_front=1.5)
    got = run(rt, src, depth, "final", cam)
    np.testing.assert_array_equal(got, run(rt, src, depth, "final", plain,
                                           optical_vignetting_front=1.5))
    np.testing.assert_allclose(got, oracle(src, depth, "final", cam), rtol=1e-4,
                               atol=2e-3 * src.max())
    assert np.abs(got - run(rt, src, depth, "final", plain)).max() > 0.05
    # dof's 0 turns the camera's off: the round gather, bit for bit
    np.testing.assert_array_equal(run(rt, src, depth, "final", cam, optical_vignetting_front=0.0),
                                  run(rt, src, depth, "final", plain))


def test_anamorphic_bokeh_is_a_vertical_oval_with_the_thin_lens_height(rt):
    src, d, pts = _lights_frame()
    cam = CAM.updated(sensor_width=4.0)
    out = run(rt, src, d, "reference", cam, anamorphic_squeeze=2.0)
    y, x = pts[0]
    lit = out[y - 14:y + 15, x - 14:x + 15, 1] > 0.5
    ys, xs = np.nonzero(lit)
    r = abs(reference.coc_radius(200.0, k_half=lens(144, 96, cam=cam)[0], focus=3.0,
                                 clamp_r=1e9))
    assert abs((np.ptp(ys) + 1) - 2 * r) <= 2           # height: the thin-lens CoC
    assert abs((np.ptp(xs) + 1) - r) <= 2               # width: CoC / squeeze
    np.testing.assert_allclose(out[..., 1].sum(), src[..., 1].sum(), rtol=1e-4)   # energy


def test_axial_ca_rims_are_green_behind_focus_and_magenta_in_front(rt):
    cam = CAM.updated(sensor_width=4.0)
    p = dict(axial_ca_red=80.0, axial_ca_blue=80.0)     # an achromat: red, blue behind green
    for depth, rim in ((200.0, "green"), (1.6, "magenta")):
        src, d, pts = _lights_frame(depth=depth)
        out = run(rt, src, d, "reference", cam, **p)
        y, x = pts[0]
        k = lens(144, 96, cam=cam)[0]
        r = abs(reference.coc_radius(depth, k_half=k, focus=3.0, clamp_r=1e9))
        ring = out[y, x + int(r) - 1: x + int(r) + 2, :3]   # along the bokeh's rim
        g_minus_rb = ring[:, 1].sum() - 0.5 * (ring[:, 0] + ring[:, 2]).sum()
        assert (g_minus_rb > 0) == (rim == "green"), (depth, ring)
        # each channel keeps its energy
        np.testing.assert_allclose(out[..., :3].sum(axis=(0, 1)), src[..., :3].sum(axis=(0, 1)),
                                   rtol=2e-3)


@pytest.mark.parametrize("option", list(OPTIONS))
def test_lens_geometry_options_hard_cases(rt, rng, option):
    """The contract's hard cases with each option on (the contract suite runs dof at its
    defaults): tiny and odd shapes, NaN/Inf/1e38 pixels, transparent pixels, determinism."""
    from tests.contract import effects as E

    p = Dof.params(**OPTIONS[option])
    for shape in hard_shapes():
        src, depth = random_case(rng, shape)
        got = run(rt, src, depth, "final", CAM.updated(sensor_width=4.0), **OPTIONS[option])
        assert got.shape == src.shape and np.isfinite(got).all(), shape
    for q in ("draft", "final", "reference"):
        for value in E.HARD_VALUES.values():
            out = E.apply(rt, "dof", E.with_value(value), p, quality=q)
            assert np.isfinite(out).all(), (q, value)
        src = E.with_value(E.NONFINITE)
        out = E.apply(rt, "dof", src, p, quality=q)
        zeroed = E.apply(rt, "dof", np.where(np.isfinite(src), src, np.float32(0)), p, quality=q)
        np.testing.assert_allclose(out, zeroed, rtol=1e-5, atol=1e-6)
        t = E.transparent_scene()
        out = E.apply(rt, "dof", t, p, quality=q)
        assert np.isfinite(out).all() and out[..., 3].min() >= 0 and out[..., 3].max() <= 1 + 1e-6
    a = E.apply(rt, "dof", E.scene(), p)
    b = E.apply(rt, "dof", E.scene(), p)
    assert a.tobytes() == b.tobytes()


def test_options_grow_the_reach(rt):
    """Axial CA makes red larger in front of focus: the region of definition and the tiles
    cover it; a squeeze narrows the reach in x."""
    from clfx.core.rect import Rect
    from clfx.host import RenderContext

    src = np.zeros((32, 32, 4), np.float32)
    src[16, 16] = 1e3
    depth = np.full((32, 32), 1.5, np.float32)
    cam = CAM.updated(sensor_width=3.0)
    ctx = RenderContext(rt, rt.upload(src), depth=rt.upload(depth), camera=cam,
                        display_window=Rect(-32, -32, 64, 64))
    base = Dof().spread_px(Dof.params(), ctx)
    ca = Dof().spread_px(Dof.params(axial_ca_red=150.0), ctx)
    sq = Dof().spread_px(Dof.params(anamorphic_squeeze=2.0), ctx)
    assert ca[0] > base[0] and ca[1] > base[1]
    assert sq[0] < base[0] and sq[1] == base[1]


@pytest.mark.parametrize("option", ["cateye", "cateye_front", "cateye_both", "anamorphic",
                                    "axial_ca"])
def test_lens_geometry_beats_naive_and_input_on_ground_truth(rt, option):
    """The bench's lens-geometry cases at 160x90: every level beats the naive gather (with
    the same aperture) and the unchanged input; final is within 1 dB of reference."""
    from clfx.bench.cases.dof import make_scene

    c = make_scene(option, 160, 90, ss=4, samples=4096)
    score, base = scores_against_truth(rt, c)
    assert score["final"] > score["reference"] - 1.0, score
    assert min(score.values()) > base + 1.0, (score, base)


def test_naive_gather_with_the_lens_geometry_matches_a_direct_loop(rng):
    from clfx.bench.cases.dof import CATEYE_STEP, _naive_shaped

    h, w = 14, 19
    src = rng.uniform(0.0, 2.0, (h, w, 4)).astype(np.float32)
    r = np.round(rng.uniform(-4.0, 4.0, (h, w)) * 4) / 4
    cx = np.round(rng.uniform(-0.8, 0.8, (h, w)) / CATEYE_STEP) * CATEYE_STEP
    cy = np.round(rng.uniform(-0.5, 0.5, (h, w)) / CATEYE_STEP) * CATEYE_STEP
    got = _naive_shaped(src, r, 1.5, (cx, cy))
    want = np.zeros((h, w, 4))
    for y in range(h):
        for x in range(w):
            acc, n = 0.0, 0
            for oy in range(-6, 7):
                for ox in range(-6, 7):
                    a = ox * 1.5
                    if (math.hypot(a, oy) <= abs(r[y, x]) + 0.5 and
                            math.hypot(a + cx[y, x] * r[y, x], oy + cy[y, x] * r[y, x])
                            <= abs(r[y, x]) + 0.5):
                        acc = acc + src[min(max(y + oy, 0), h - 1), min(max(x + ox, 0), w - 1)]
                        n += 1
            want[y, x] = acc / n
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)


def test_cateye_and_squeeze_with_pixel_aspect_match_reference(rt, rng):
    src, depth = random_case(rng, (36, 30))
    cam = CAM.updated(sensor_width=8.0)
    p = Dof.params(optical_vignetting=1.5, anamorphic_squeeze=1.33)
    got = render_effect(rt, Dof(), p, src, depth=depth, camera=cam, pixel_aspect=1.5,
                        quality="reference")
    k_half, focus, clamp_r = lens(30, 36, p, cam)
    r = reference.coc_radius(depth, k_half=k_half, focus=focus, clamp_r=clamp_r)
    lvl = LEVELS["reference"]
    taps = tap_table(float(quantised_radius(np.abs(r).max())), lvl.lattice, 1.5,
                     dense=lvl.dense_radius, squeeze=1.33)
    want = reference.dof(src, depth, k_half=k_half, focus=focus, clamp_r=clamp_r, taps=taps,
                         cateye=reference.cateye_centres((36, 30), 1.5, aspect=1.5))
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=2e-3 * src.max())
    assert np.abs(got - want).mean() < 1e-5 * src.max()


def test_cateye_half_resolution_gather_follows_the_full_resolution_one(rt):
    """Tiles far out of focus are gathered at half resolution with the barrel of the
    half-resolution pixel: on smooth content whose blur depends on the bokeh's shape, final
    (half resolution) stays as close to reference with a strong cat-eye as without."""
    ys, xs = np.mgrid[0:96, 0:128].astype(np.float32)
    src = np.stack([0.5 + 0.2 * np.sin(xs / 2.5), 0.5 + 0.2 * np.sin(ys / 2.5),
                    0.5 + 0.2 * np.sin((xs + ys) / 3.0), np.ones_like(xs)], axis=2)
    depth = np.full((96, 128), 50.0, np.float32)        # CoC radius ~ 8 px everywhere
    cam = CAM.updated(sensor_width=4.0)
    err = {}
    for ov in (0.0, 2.0):
        half = run(rt, src, depth, "final", cam, max_coc=0.2, optical_vignetting=ov)
        full = run(rt, src, depth, "reference", cam, max_coc=0.2, optical_vignetting=ov)
        err[ov] = np.abs(half - full)[16:-16, 16:-16].mean()
        if ov:
            plain = run(rt, src, depth, "reference", cam, max_coc=0.2)
            shape = np.abs(full - plain)[16:-16, 16:-16].mean()
    assert err[2.0] < 2 * err[0.0] + 1e-4 and err[2.0] < 0.2 * shape, (err, shape)


def scores_against_truth(rt, c):
    """log-PSNR of every level against a ground-truth case, and the better of the naive
    gather and the unchanged input."""
    from clfx.bench.cases.dof import naive
    from clfx.host import RenderContext

    truth = c["truth"]
    ctx = RenderContext(rt, rt.upload(c["source"]), depth=rt.upload(c["depth"]),
                        camera=c["camera"])
    base = max(metrics.psnr_log(naive(c, Dof.params(), ctx), truth),
               metrics.psnr_log(c["source"], truth))
    score = {q: metrics.psnr_log(run(rt, c["source"], c["depth"], q, c["camera"]), truth)
             for q in QUALITY_LEVELS}
    return score, base


def test_draft_light_against_the_sky_has_no_ring_of_dots(rt):
    # issue 25: a light at 8 m against the sky (inf), its antialiased edge pixels carrying the
    # sky's depth, as renderers write them (the demo scene's sky lights).  The half-resolution
    # gather took each 2 x 2 box's mean radius, so a box holding an edge pixel spread the
    # light at a radius between the light's and the sky's: a broken ring of 2 px dots around
    # the light at draft (measured 3.6 x the sky beside it).  A box's radius is now weighted
    # by its pixels' light: nothing shows around the light beyond its own blur.
    cam = Camera(focal_length=50.0, f_number=0.7, sensor_width=36.0, focus_distance=3.0)
    h, w = 180, 320
    y, x = np.mgrid[0:h, 0:w] + 0.5
    cy, cx = 90.3, 160.6
    d = np.hypot(x - cx, y - cy)
    cover = np.clip(3.5 - d, 0.0, 1.0)                      # an antialiased disc, radius 3.5
    src = np.zeros((h, w, 4), np.float32)
    src[..., 3] = 1.0
    src[..., :3] = (0.044 + 395.0 * cover)[..., None]
    depth = np.where(cover >= 0.5, 8.0, np.inf).astype(np.float32)
    k_half = lens(w, h, cam=cam)[0]                        # the sky's radius, 5.4 px
    # beyond the light's own blur and the half-resolution upsample's 3 px (measured at draft,
    # from the light's centre: up to 0.33 at 7-9 px, the sky's 0.044 from 10 px on; the mean
    # radius gave 0.15-0.27 out to 11 px)
    ring = (d > 3.5 + k_half * (1 - 3.0 / 8.0) + 3) & (d < 3.5 + k_half + 3)
    for q in ("draft", "final"):
        out = run(rt, src, depth, q, cam).astype(np.float64)
        lum = out[..., :3] @ [0.2126, 0.7152, 0.0722]
        assert lum[ring].max() < 1.5 * 0.044, (q, k_half, lum[ring].max())


# -- mixed edge pixels (issue 32) -------------------------------------------------------------
SKY = np.array([0.05, 0.053, 0.068, 1.0])
CARD_LIGHT, CARD_DARK = np.array([0.9, 0.85, 0.7, 1.0]), np.array([0.06, 0.05, 0.05, 1.0])


def card_over_sky(h=48, w=64, edge=20.6, ss=4, period=8):
    """A sharp card (3 m, in focus) with vertical light and dark stripes below ``edge`` (y,
    px) over a flat sky at infinity, as a renderer writes it: the beauty the ``ss x ss`` box
    mean of sub-samples (the edge row mixes card and sky), the depth the surface at each
    pixel centre."""
    ys = (np.arange(h * ss) + 0.5) / ss
    xs = (np.arange(w * ss) + 0.5) / ss
    light = (xs // period) % 2 == 0
    card = np.where(light[:, None], CARD_LIGHT, CARD_DARK)[None]        # (1, w*ss, 4)
    sub = np.where((ys >= edge)[:, None, None], card, SKY)
    src = sub.reshape(h, ss, w, ss, 4).mean(axis=(1, 3)).astype(np.float32)
    depth = np.where((np.arange(h) + 0.5 >= edge)[:, None], 3.0, np.inf)
    return src, np.ascontiguousarray(np.broadcast_to(depth, (h, w)), dtype=np.float32)


@pytest.mark.parametrize("quality", QUALITY_LEVELS)
def test_an_antialiased_in_focus_edge_leaves_no_soft_copy_over_the_sky(rt, quality):
    """The card's edge row is half card, half sky under the sky's depth: gathered as sky it
    put a soft copy of the card's light stripes 1-4 px above the edge (0.085 off the sky of
    0.05; 1e-4 split).  Split by coverage, the sky above stays the flat sky and the edge row
    keeps its card part, sharp."""
    src, depth = card_over_sky()
    got = run(rt, src, depth, quality, coc_source="max_blur", max_blur=0.1)   # CoC 8 px at inf
    above = got[20 - 6:20, 4:-4, :3]               # 1-6 px above the mixed row (20)
    assert np.abs(above - SKY[:3]).max() < 2e-3 * CARD_LIGHT.max()
    a = 0.5                          # the mixed row's card coverage (2 of 4 sub-sample rows)
    want = a * np.where(((np.arange(64) + 0.5) // 8) % 2 == 0, 1, 0)[:, None] \
        * (CARD_LIGHT - CARD_DARK)[:3] + a * CARD_DARK[:3] + (1 - a) * SKY[:3]
    np.testing.assert_allclose(got[20, 4:-4, :3], want[4:-4], atol=0.03)
    np.testing.assert_array_equal(got[21:], src[21:])    # the card itself: sharp, untouched


def halo_above_top_edge(out, src, depth, x0, x1):
    """Per column x0..x1 of the demo card, the largest difference of ``out`` from the sky
    (the source's mean 8-11 px above) in the 6 rows above the card's first row at its depth
    (the mixed edge row and the 5 sky rows above it)."""
    dev = []
    for x in range(x0, x1):
        y = int(np.argmax(depth[100:200, x] == 3.0)) + 100
        sky = src[y - 12:y - 8, x, :3].mean(axis=0)
        dev.append(np.abs(out[y - 7:y - 1, x, :3] - sky).max())
    return np.array(dev)


def test_the_demo_card_has_no_halo_above_its_top_edge(rt):
    """``clfx demo``'s scene.0001.exr (the sharp demo frame, 640 x 360) through the default
    look's lens: the checker card's light squares made a soft copy 1-4 px above its top edge
    over the flat sky (mean 0.035 over the card's columns, 122 of 175 columns over 0.01).
    Split, only the few columns where a light square's sliver lies along the edge (its
    colour nowhere among the pixel's neighbours) keep some."""
    from clfx.pipeline.presets import load_look

    sharp = render_sharp(demo_scene(1, 640, 360))
    src, depth = sharp.rgba.astype(np.float32), sharp.depth.astype(np.float32)
    got = run(rt, src, depth, "final", load_look("default").camera)
    dev = halo_above_top_edge(got, src, depth, 170, 345)
    assert dev.mean() < 0.01 and (dev > 0.01).mean() < 0.15, (dev.mean(), (dev > 0.01).sum())


def test_explain_and_json_say_how_many_mixed_edge_pixels_were_split(rt, tmp_path):
    """One line of the step's report: the card's edge row (64 pixels), split."""
    import json

    from clfx.core.frame import Frame
    from clfx.io.write import write_frame
    from tests.clirun import run as cli

    src, depth = card_over_sky()
    write_frame(Frame.from_array(src, depth=depth), tmp_path / "in.exr")
    args = ("apply", "dof", tmp_path / "in.exr", tmp_path / "out.exr", "coc_source=max_blur",
            "max_blur=0.1", "--overwrite")
    said = [ln for ln in cli(*args, "--explain").stderr.splitlines() if "mixed edge" in ln]
    assert len(said) == 1 and "dof: 64 mixed edge pixels split" in said[0], said
    lines = [json.loads(ln) for ln in cli(*args, "--json").output.splitlines() if ln.strip()]
    notes = [n for ln in lines for s in ln.get("steps", []) for n in s.get("notes", [])]
    assert "dof: 64 mixed edge pixels split" in notes, lines


# -- no negative light from the split of mixed edge pixels (QC) ------------------------------
def shaded_ball_over_nothing(h=48, w=48, radius=14.3, ss=4, bg_depth=np.inf):
    """A ball (3 m, in focus through ``CAM``) over transparent black at ``bg_depth``, as a
    renderer writes it: premultiplied RGBA, the ``ss x ss`` box mean of sub-samples, the
    depth at each pixel centre.  Its colour is yellow with the blue fading out over its last
    4 px (the Beachball's rim: R = G, B much lower at the edge than one pixel in), so an
    edge pixel is off the segment between its neighbours and its residual is negative in
    blue."""
    ys, xs = np.mgrid[0:h * ss, 0:w * ss]
    rho = np.hypot((xs + 0.5) / ss - w / 2, (ys + 0.5) / ss - h / 2)
    inside = rho <= radius
    blue = np.clip((radius - rho) / 4.0, 0.0, 1.0)
    sub = np.stack([0.5 * inside, 0.5 * inside, 0.3 * blue * inside, 1.0 * inside], -1)
    src = sub.reshape(h, ss, w, ss, 4).mean(axis=(1, 3)).astype(np.float32)
    yc, xc = np.mgrid[0:h, 0:w] + 0.5
    depth = np.where(np.hypot(xc - w / 2, yc - h / 2) <= radius, 3.0, bg_depth)
    return src, depth.astype(np.float32)


def lowest_allowed(src):
    """The least value a gather of ``src`` may give: min(0, the input's least) less float32
    round-off of sums of the input's scale (a few ulps of its largest magnitude)."""
    return min(0.0, float(src.min())) - 1e-6 * float(np.abs(src).max())


@pytest.mark.parametrize("quality", QUALITY_LEVELS)
def test_an_antialiased_edge_over_transparent_black_makes_no_negative_light(rt, quality):
    """The ball's rim pixels mix it with transparent black at infinity: split into a near and
    a far part, the far part (C - a (n - f), f = 0) was the projection residual, negative in
    blue (-0.004), spread into the blurred background at the sky's CoC: output below 0 where
    the input has nothing below 0 (the Beachball at defaults: 247 pixels, QC).  Each part
    now stays at or above min(0, the colours it is estimated from) and they still mix back
    to the pixel: no value below 0, the in-focus ball untouched."""
    src, depth = shaded_ball_over_nothing()
    assert src.min() == 0.0
    got = run(rt, src, depth, quality, coc_source="max_blur", max_blur=0.12)   # 8 px at inf
    assert got.min() >= lowest_allowed(src), (quality, got.min())
    inner = np.hypot(*(np.mgrid[0:48, 0:48] + 0.5 - 24.0)) < 14.3 - 1.5
    np.testing.assert_array_equal(got[inner], src[inner])


def test_a_negative_input_keeps_its_negative_values_through_the_split(rt):
    """Negative input (a grade's negative blue in the background) is the user's: the split's
    bound is min(0, the colours a part is estimated from), so the background's negative
    blue passes as before, and nothing goes below the input's least value."""
    src, depth = shaded_ball_over_nothing()
    src[..., 2] -= 0.05 * (1.0 - src[..., 3])       # the background's blue at -0.05
    assert src.min() == pytest.approx(-0.05)
    got = run(rt, src, depth, "final", coc_source="max_blur", max_blur=0.12)
    assert got.min() >= lowest_allowed(src), got.min()
    np.testing.assert_allclose(got[:4, :4], src[:4, :4], atol=1e-6)   # far corner: as it was


def test_the_mixed_split_bound_matches_the_reference(rt):
    """The oracle's split carries the same bound (float64): the ball over transparent black
    at the reference level."""
    src, depth = shaded_ball_over_nothing(40, 40, radius=11.3)
    cam = CAM.updated(sensor_width=3.0)                    # 2.8 px of CoC radius at inf
    got = run(rt, src, depth, "reference", cam)
    want = oracle(src, depth, "reference", cam)
    assert want.min() >= lowest_allowed(src)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("zero", ["far", "invalid"])
def test_beachball_rim_at_defaults_makes_no_negative_light(rt, exr_images, zero):
    """``clfx apply dof`` at defaults on Beachball 0001 wrote 247 pixels below -1e-5 (min
    -0.00105, R = G > 0, B < 0) just outside the ball's silhouette, over a background of
    RGBA 0 and Z = 0 (read as no hit: +inf; 32 pixels with ``--depth-zero invalid``, Z = 0
    in focus); the input's least value is 0.  A 96 x 96 crop around the worst of them,
    placed in the frame's display window, at draft and final."""
    from clfx.core.rect import Rect
    from clfx.io.read import read_frame

    with pytest.warns(UserWarning, match="read as no hit"):
        fr = read_frame(exr_images / "Beachball" / "singlepart.0001.exr")
    assert np.isinf(fr.depth).any() and not (fr.depth == 0).any()
    depth = fr.depth if zero == "far" else np.where(np.isinf(fr.depth), 0.0, fr.depth)
    y0, x0 = 175 - 48, 770 - 48                    # (770, 175) of the data window
    crop = (slice(y0, y0 + 96), slice(x0, x0 + 96))
    src = np.ascontiguousarray(fr.rgba[crop])
    assert src.min() >= 0.0
    dw = fr.data_window
    window = Rect(dw.x0 + x0, dw.y0 + y0, dw.x0 + x0 + 96, dw.y0 + y0 + 96)
    for quality in ("draft", "final"):
        got = render_effect(rt, Dof(), Dof.params(), src, depth=np.ascontiguousarray(
            depth[crop], np.float32), camera=Camera(), quality=quality, data_window=window,
            display_window=fr.display_window)
        assert got.min() >= lowest_allowed(src), (quality, got.min(), (got < -1e-5).sum())
