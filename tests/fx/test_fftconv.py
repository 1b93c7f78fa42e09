import threading

import numpy as np
import pytest

from clfx.fx import fftconv
from clfx.core.rect import Rect
from tests.fx.blocks import force_blocks
from tests.reference.glare import convolve as reference

CASES = [
    ("fft", "float64", None), ("fft", "float32", 0.9),
    ("direct", "float64", None), ("direct", "float32", None),
]


def run(rt, src, psf, window, out, **kw):
    img = rt.upload(src, window)
    return fftconv.convolve(rt, img, psf, out_window=out, **kw).download()


@pytest.mark.parametrize("shape,kshape", [((1, 1), (9, 9)), ((1, 7), (3, 4)), ((7, 1), (5, 5)),
                                          ((3, 5), (31, 30)), ((17, 31), (5, 7)),
                                          ((40, 50), (64, 61))])
@pytest.mark.parametrize("method,precision,split", CASES)
def test_convolve_matches_reference(rt, rng, shape, kshape, method, precision, split):
    src = rng.uniform(0.0, 1.0, shape + (4,)).astype(np.float32)
    psf = rng.uniform(0.0, 1.0, kshape)
    win = Rect(3, -2, 3 + shape[1], -2 + shape[0])
    for out in (win, fftconv.full_region(win, *kshape), Rect(0, 0, 20, 9)):
        got = run(rt, src, psf, win, out, method=method, precision=precision,
                  threshold_split=split)
        want = reference(src[..., :3], psf, (win.x0, win.y0), (out.x0, out.y0, out.x1, out.y1))
        assert got.shape == (out.height, out.width, 4)
        # float32 input/output and float32 FFT: ~1e-6 of the peak (sums of <= 4000 terms)
        np.testing.assert_allclose(got[..., :3], want, rtol=0, atol=3e-6 * max(want.max(), 1e-30))
        assert not got[..., 3].any()   # alpha of the spread light is 0


def test_colour_psf_planes(rt, rng):
    src = rng.uniform(0.0, 1.0, (20, 24, 4)).astype(np.float32)
    psf = rng.uniform(0.0, 1.0, (25, 25, 3))
    win = Rect.from_size(24, 20)
    out = fftconv.full_region(win, 25, 25)
    want = reference(src[..., :3], psf, (0, 0), (out.x0, out.y0, out.x1, out.y1))
    for method in ("fft", "direct"):
        got = run(rt, src, psf, win, out, method=method)
        np.testing.assert_allclose(got[..., :3], want, atol=1e-6 * want.max())


def hdr_scene(rng, h=96, w=128):
    """A 1e5 light next to 1e-2 shadows (hard-cases.md case 1) and a power-law PSF."""
    src = np.zeros((h, w, 4), np.float32)
    src[..., :3] = rng.uniform(0.005, 0.02, (h, w, 3))
    src[40:43, 50:53, :3] = 1e5
    r = 60
    y, x = np.mgrid[-r:r + 1, -r:r + 1]
    psf = 1.0 / (np.hypot(x, y) + 0.5) ** 3
    return src, psf / psf.sum()


@pytest.mark.parametrize("kw", [dict(precision="float64"),
                                dict(precision="float32", threshold_split=100.0),
                                dict(method="direct", precision="float64")])
def test_hdr_shadows_accurate_and_non_negative(rt, rng, kw):
    src, psf = hdr_scene(rng)
    win = Rect.from_size(src.shape[1], src.shape[0])
    got = run(rt, src, psf, win, win, **kw)[..., :3].astype(np.float64)
    want = reference(src[..., :3], psf, (0, 0), (0, 0, win.x1, win.y1))
    m = want >= 1e-3
    rel = np.abs(got - want)[m] / want[m]
    assert rel.max() <= 1e-4          # hard-cases.md case 1 (float32 output rounding: ~1e-7)
    assert got.min() >= -1e-6 * want.max()


def test_split_falls_back_to_float64_with_many_bright_pixels(rt, rng):
    src, psf = hdr_scene(rng)
    win = Rect.from_size(src.shape[1], src.shape[0])
    info = fftconv.ConvolveInfo()
    run(rt, src, psf, win, win, precision="float32", threshold_split=1e-3, info=info)
    assert info.fallback and info.precision == "float64"


def test_nonfinite_input_does_not_spread(rt, rng):
    src = rng.uniform(0.0, 1.0, (20, 30, 4)).astype(np.float32)
    clean = src.copy()
    src[5, 7, 0], src[9, 20, 2] = np.nan, np.inf
    clean[5, 7, 0], clean[9, 20, 2] = 0.0, 0.0
    psf = rng.uniform(0.0, 1.0, (31, 31))
    win = Rect.from_size(30, 20)
    for method in ("fft", "direct", "half"):
        got = run(rt, src, psf, win, win, method=method)
        want = run(rt, clean, psf, win, win, method=method)
        assert np.isfinite(got).all()
        np.testing.assert_array_equal(got, want)


def test_half_resolution_conserves_energy_and_is_close(rt, rng):
    src = np.zeros((64, 80, 4), np.float32)
    src[30:34, 38:42, :3] = rng.uniform(1, 10, (4, 4, 3))
    r = 20
    y, x = np.mgrid[-r:r + 1, -r:r + 1]
    psf = np.exp(-0.5 * (x * x + y * y) / 36.0)
    psf /= psf.sum()
    win = Rect.from_size(80, 64)
    got = run(rt, src, psf, win, win, method="half")[..., :3]
    want = reference(src[..., :3], psf, (0, 0), (0, 0, 80, 64))
    np.testing.assert_allclose(got.sum(axis=(0, 1)), want.sum(axis=(0, 1)), rtol=1e-5)
    assert np.abs(got - want).max() <= 0.05 * want.max()   # approximation: <= 0.5 px shift


def test_tent_downsample_keeps_sum_and_centre():
    k = np.random.default_rng(1).uniform(0, 1, (9, 12))
    k2 = fftconv.tent_downsample(k)[..., 0]
    assert abs(k2.sum() - k.sum()) < 1e-12
    c, c2 = np.array(k.shape) // 2, np.array(k2.shape) // 2
    yy, xx = np.mgrid[0:k.shape[0], 0:k.shape[1]]
    y2, x2 = np.mgrid[0:k2.shape[0], 0:k2.shape[1]]
    assert abs(((xx - c[1]) * k).sum() / k.sum() / 2 - ((x2 - c2[1]) * k2).sum() / k2.sum()) < 1e-12


def test_fft_sizes_are_smooth_and_cover():
    for n in (1, 2, 17, 1081, 1592, 2433, 4999):
        m = fftconv.fft_size(n, even=True)
        assert m >= n and m % 2 == 0 and fftconv.is_smooth(m)


def spectra(rt) -> int:
    """PSF spectra held in the runtime's cache."""
    return rt.cache.stats()["owners"].get("fftconv.spectrum", 0)


def test_spectrum_and_plans_live_in_the_runtime_cache(rt, rng):
    src = rng.uniform(0.0, 1.0, (16, 16, 4)).astype(np.float32)
    psf = rng.uniform(0.0, 1.0, (33, 33))
    win = Rect.from_size(16, 16)
    fftconv.clear_caches(rt)
    assert spectra(rt) == 0
    a = run(rt, src, psf, win, win)
    held = spectra(rt)
    hits = rt.cache.hits
    b = run(rt, src, psf, win, win)
    assert spectra(rt) == held > 0 and rt.cache.hits > hits   # reused, not rebuilt
    run(rt, src, psf, win, win, precision="float32")              # VkFFT (float64: the host's
    assert rt.cache.stats()["owners"].get("fftconv.plan", 0) > 0   # on PoCL); plans count bytes
    assert np.array_equal(a, b)       # determinism: identical bytes
    fftconv.clear_caches(rt)
    assert spectra(rt) == 0 and "fftconv.plan" not in rt.cache.stats()["owners"]


def test_float64_transforms_of_a_cpu_device_run_on_the_host(rt, rng, monkeypatch):
    # PoCL's buffers are host memory: NumPy's pocketfft transforms the image's rows into the
    # work buffer (no packed copy) and it in place (55-65 % of VkFFT's CPU time for glare at
    # 1080p), in row and column chunks; the same convolution as VkFFT's to float64
    # rounding, every chunk size, one spectrum or three
    assert rt.shares_host_cores                      # the tests run on PoCL
    src, psf = hdr_scene(rng, 40, 56)
    colour = np.stack([psf, psf[::-1], psf.T], -1)
    win = Rect(2, 1, 58, 41)
    launch = rt.launch
    for k in (psf, colour):
        out = fftconv.full_region(win, *k.shape[:2])
        want = reference(src[..., :3], k, (win.x0, win.y0), (out.x0, out.y0, out.x1, out.y1))
        fftconv.clear_caches(rt)
        monkeypatch.setattr(fftconv, "HOST_FFT", False)
        vkfft = run(rt, src, k, win, out, precision="float64")
        monkeypatch.setattr(fftconv, "HOST_FFT", True)
        launched = []
        monkeypatch.setattr(rt, "launch", lambda knl, *a, **kw: launched.append(
            knl.function_name) or launch(knl, *a, **kw))
        for chunk in (fftconv.HOST_CHUNK_BYTES, 1):      # 1: a row or column per task
            monkeypatch.setattr(fftconv, "HOST_CHUNK_BYTES", chunk)
            monkeypatch.setattr(fftconv, "HOST_COLUMN_BYTES", min(chunk, fftconv.HOST_COLUMN_BYTES))
            fftconv.clear_caches(rt)
            got = run(rt, src, k, win, out, precision="float64")
            assert "fftconv.plan" not in rt.cache.stats()["owners"]   # no VkFFT plan
            assert "fftconv_pack" not in launched     # the rows are read from the image
            assert "fftconv_unpack" not in launched   # and the kept rows written to the output
            assert rt.cache.stats()["owners"]["fftconv.host_plane"] > 0   # one plane, kept
            np.testing.assert_allclose(got, vkfft, rtol=1e-6, atol=1e-12 * want.max())
            np.testing.assert_allclose(got[..., :3], want, rtol=1e-5, atol=1e-12 * want.max())


def test_spectrum_over_the_byte_bound_is_not_kept(rt, rng, monkeypatch):
    monkeypatch.setattr(fftconv, "SPECTRUM_CACHE_BYTES", 1024)
    src = rng.uniform(0.0, 1.0, (16, 16, 4)).astype(np.float32)
    psf = rng.uniform(0.0, 1.0, (33, 33))
    win = Rect.from_size(16, 16)
    fftconv.clear_caches(rt)
    got = run(rt, src, psf, win, win)
    assert spectra(rt) == 0                                    # used for this call only
    want = reference(src[..., :3], psf, (0, 0), (0, 0, 16, 16))
    np.testing.assert_allclose(got[..., :3], want, atol=1e-6 * want.max())


def test_support_limits_the_input(rt, rng):
    src = rng.uniform(0.0, 1.0, (20, 30, 4)).astype(np.float32)
    psf = rng.uniform(0.0, 1.0, (11, 11))
    win = Rect.from_size(30, 20)
    sup = Rect(5, 4, 15, 12)
    img = rt.upload(src, win)
    got = fftconv.convolve(rt, img, psf, out_window=win, support=sup).download()[..., :3]
    masked = np.zeros_like(src)
    masked[4:12, 5:15] = src[4:12, 5:15]
    want = reference(masked[..., :3], psf, (0, 0), (0, 0, 30, 20))
    np.testing.assert_allclose(got, want, atol=1e-6 * want.max())


@pytest.mark.parametrize("kh, kw, planes, n1, n2", [(5, 7, 1, 8, 10), (6, 4, 3, 9, 12),
                                                    (4, 6, 3, 4, 6), (1, 1, 1, 4, 6),
                                                    (9, 9, 1, 6, 6)])
@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_psf_placed_on_the_grid_without_a_grid_sized_host_plane(rt, rng, monkeypatch, kh, kw,
                                                                 planes, n1, n2, precision):
    """Issue 10 item 10: the PSF's wrapped quadrants are copied into the zeroed device grid
    (no float64 plane of the grid on the host: 392 MiB twice at 8K); the same values as
    adding the taps modulo the grid (the last case: a grid smaller than the PSF)."""
    import types

    k = rng.uniform(size=(kh, kw, planes))
    real = fftconv._real(precision)
    monkeypatch.setattr(fftconv, "_plan", lambda *a, **kw: types.SimpleNamespace(fft=lambda a: 0))
    holder, _ = fftconv._spectrum(rt, k, n1, n2, precision)     # the placement, no FFT
    got = np.empty((planes, n1, n2 + 2), real)
    rt.cl.enqueue_copy(rt.queue, got, holder.buffer)
    want = np.zeros((planes, n1, n2 + 2))
    ys, xs = (np.arange(kh) - kh // 2) % n1, (np.arange(kw) - kw // 2) % n2
    for p in range(planes):
        np.add.at(want[p], (ys[:, None], xs[None, :]), k[..., p])
    assert np.array_equal(got, want.astype(real))


BLOCK_CASES = [("fft", "float64", None), ("fft", "float32", 100.0), ("direct", "float32", None),
               ("direct", "float64", None), ("half", "float32", None)]


@pytest.mark.parametrize("method,precision,split", BLOCK_CASES)
def test_blocks_give_the_one_grid_convolution(rt, rng, monkeypatch, method, precision, split):
    """Output blocks (overlap-save) give the exact linear convolution: direct blocks the same
    bits as one gather, FFT blocks the same up to FFT rounding, also from a loader."""
    src = rng.uniform(0.0, 1.0, (60, 90, 4)).astype(np.float32)
    src[20, 30, :3] = 500.0                       # one pixel above the split
    win = Rect(3, -2, 93, 58)
    psf = rng.uniform(0.0, 1.0, (41, 37))
    psf /= psf.sum()
    out = fftconv.full_region(win, 41, 37).intersect(Rect(-10, -10, 100, 50))
    img = rt.upload(src, win)
    kw = dict(method=method, precision=precision, threshold_split=split)
    one = fftconv.convolve(rt, img, psf, out_window=out, **kw).download()
    calls = force_blocks(monkeypatch, cells=900)
    info = fftconv.ConvolveInfo()
    got = fftconv.convolve_blocks(rt, img, psf, out_window=out, info=info, **kw).download()
    loaded = fftconv.convolve_blocks(rt, lambda r: rt.reframe(img, r), psf, support=win,
                                     out_window=out, **kw).download()
    assert len(calls) == 2 and info.blocks > 20 and info.precision == precision
    assert np.array_equal(loaded.view(np.uint32), got.view(np.uint32))
    if method == "direct":
        assert np.array_equal(got.view(np.uint32), one.view(np.uint32))
    else:   # FFT rounding: float32 transforms ~1e-7 of the peak, float64 below float32 output
        np.testing.assert_allclose(got, one, rtol=0, atol=1e-6 * one.max())
    if method != "half":
        want = reference(src[..., :3], psf, (win.x0, win.y0), (out.x0, out.y0, out.x1, out.y1))
        np.testing.assert_allclose(got[..., :3], want, rtol=0, atol=3e-6 * want.max())
    if split:
        assert info.bright_pixels == 1 and not info.fallback


def test_blocks_fall_back_to_float64_once_for_many_bright_pixels(rt, rng, monkeypatch):
    src, psf = hdr_scene(rng)
    win = Rect.from_size(src.shape[1], src.shape[0])
    img = rt.upload(src, win)
    force_blocks(monkeypatch, cells=12000, min_block=16)
    info = fftconv.ConvolveInfo()
    got = fftconv.convolve_blocks(rt, img, psf, out_window=win, precision="float32",
                                  threshold_split=1e-3, info=info).download()
    f64 = fftconv.convolve_blocks(rt, img, psf, out_window=win, precision="float64").download()
    assert info.fallback and info.precision == "float64" and info.blocks > 1
    assert info.bright_pixels == src.shape[0] * src.shape[1]   # counted over every block
    assert np.array_equal(got, f64)


def test_block_shape_bounds_the_grid_and_keeps_small_frames_whole():
    assert fftconv.block_shape(540, 960, 331, 331) == (540, 960)
    for h, w, k in ((4320, 7680, 2641), (4320, 7680, 331), (8640, 15360, 2641),
                    (50, 90000, 31)):
        b1, b2 = fftconv.block_shape(h, w, k, k)
        n1, n2 = fftconv.fft_size(b1 + k - 1), fftconv.fft_size(b2 + k - 1, even=True)
        assert n1 * n2 <= fftconv.MAX_BLOCK_CELLS and b1 <= h and b2 <= w
        assert min(b1, b2) >= min(fftconv.MIN_BLOCK, h, w)
    # a PSF too large for the cap keeps MIN_BLOCK sides: the smallest such grid, past the cap
    b1, b2 = fftconv.block_shape(12000, 12000, 6001, 6001)
    n = fftconv.fft_size(6000 + fftconv.MIN_BLOCK)
    assert n * n > fftconv.MAX_BLOCK_CELLS and b1 == n - 6000 and b1 >= fftconv.MIN_BLOCK


def test_host_transform_zeroes_what_it_does_not_write_without_a_fill(rt, rng, monkeypatch):
    # the host convolution writes the kept pixels' colour and zeroes the rest of its output
    # (alpha, the rows and columns no light reaches, the row padding) in its own tasks: no
    # fill of the whole output before (8 ms of one core at 1080p), whatever the pool's
    # buffer held
    src, psf = hdr_scene(rng, 21, 30)
    win = Rect(2, 1, 32, 22)
    out = fftconv.full_region(win, *psf.shape).grown(3)
    out = Rect(out.x0, out.y0, out.x1 + 2, out.y1)          # width 2 past a multiple of 4
    want = reference(src[..., :3], psf, (win.x0, win.y0), (out.x0, out.y0, out.x1, out.y1))
    image, fills = rt.image, []

    def poisoned(window, channels=4):                       # a reused buffer's old contents
        img = image(window, channels)
        rt.cl.enqueue_fill_buffer(rt.queue, img.buffer, np.float32(np.nan), 0, img.nbytes)
        return img

    monkeypatch.setattr(rt, "image", poisoned)
    monkeypatch.setattr(rt, "fill", lambda img, value=0.0: fills.append(img) or img)
    src_img = image(win, 4)
    rt.cl.enqueue_copy(rt.queue, src_img.buffer, np.ascontiguousarray(np.pad(
        src, ((0, 0), (0, src_img.pitch - src.shape[1]), (0, 0)))))
    dst = fftconv.convolve(rt, src_img, psf, out_window=out, precision="float64")
    assert fills == []
    raw = rt.from_device(dst, np.float32, dst.nbytes // 4).reshape(out.height, dst.pitch, 4)
    assert dst.pitch > out.width and not raw[:, out.width:].any()     # padding: 0
    assert not raw[..., 3].any()                                        # alpha: 0
    np.testing.assert_allclose(raw[:, :out.width, :3], want, rtol=1e-5,
                               atol=1e-12 * want.max())
    assert want[0].max() == 0.0 and not raw[0].any()                    # no light: 0


def test_host_lanes_overlap_keep_each_lanes_order_and_stop_at_an_error(monkeypatch):
    # the channels' passes run as lanes on one pool: a lane's next pass waits for its own
    # pass only, so another lane's tasks fill the cores meanwhile (no core idles at the end
    # of a pass); an error stops every lane and leaves no thread behind

    monkeypatch.setattr(fftconv, "available_cores", lambda: 2)
    met, order = threading.Event(), []

    def waits():         # lane 0's first pass ends only once lane 1's first pass has run
        assert met.wait(10)
        order.append("a0")

    lanes = [[[waits], [lambda: order.append("a1")] * 3],
             [[lambda: met.set() or order.append("b0")], [lambda: order.append("b1")]]]
    fftconv._run_lanes(lanes)
    assert sorted(order) == sorted(["a0", "a1", "a1", "a1", "b0", "b1"])
    assert order.index("b0") < order.index("a0") < order.index("a1")

    def fails():
        raise ValueError("bad chunk")

    ran = []
    with pytest.raises(ValueError, match="bad chunk"):
        fftconv._run_lanes([[[fails], [lambda: ran.append(1)]], [[lambda: None]]])
    assert ran == []
    assert not [t for t in threading.enumerate() if t.name.startswith("clfx-fft")]


def test_host_passes_take_every_channel_in_each_row_task(monkeypatch):
    # issue 37: a row task reads its rows of the image for every channel and an inverse row
    # task writes every channel of its output rows (one pass over the RGBA rows while they
    # are in cache, not one a channel); the channels are transformed at once whatever the
    # cores (within HOST_PLANE_BYTES: 1080p glare's three 24.7 MiB planes); the same bits as
    # one plane transformed alone
    monkeypatch.setattr(fftconv, "available_cores", lambda: 2)
    assert fftconv.host_planes_in_flight(1372, 2250, 3) == 3
    assert fftconv.host_planes_in_flight(3300, 4950, 3) == 1      # 4K: one at a time
    rng = np.random.default_rng(5)
    n1, n2, rows = 12, 10, 7
    src = rng.uniform(size=(3, rows, n2 - 3))
    src[:, 2] = 0.0                                               # a dark row
    specs = [np.ascontiguousarray(rng.uniform(size=(n1, n2 // 2 + 1)).T + 0j)
             for _ in range(3)]
    calls, got = [], np.zeros((3, n1, n2))

    def source(c):
        def load(r0, r1, x):
            calls.append(("load", c, r0, threading.get_ident()))
            x[:, :src.shape[2]] = src[c, r0:r1]
        return load

    def sink(c):
        def put(r0, r1, values):
            calls.append(("put", c, r0, threading.get_ident()))
            got[c, r0:r1] = values
        return put

    monkeypatch.setattr(fftconv, "HOST_CHUNK_BYTES", 2 * 6 * 16 * 3)   # two rows a task
    planes = [np.zeros((n1, n2 // 2 + 1), np.complex128) for _ in range(3)]
    passes = fftconv._host_passes(planes, rows, specs, [source(c) for c in range(3)],
                                  ([(0, n1)], [sink(c) for c in range(3)]))
    assert len(passes[0]) == 4 and len(passes[2]) == 6         # row chunks, not x 3
    fftconv._run_lanes([passes])
    for kind in ("load", "put"):   # each task (the tasks run at once on 2 threads, their
        for r0 in {r for k, _, r, _ in calls if k == kind}:   # calls interleaved): every
            task = [(c, t) for k, c, r, t in calls if k == kind and r == r0]   # channel in
            assert [c for c, _ in task] == [0, 1, 2]                           # order, on
            assert len({t for _, t in task}) == 1                              # one thread
    for c in range(3):
        x = np.zeros((n1, n2))
        x[:rows, :src.shape[2]] = src[c]
        want = np.fft.irfft2(np.fft.rfft2(x) * specs[c].T, s=(n1, n2))
        np.testing.assert_allclose(got[c], want, rtol=0, atol=1e-13)


def test_host_spectrum_is_transposed_for_the_column_tasks(rt, rng):
    # the column tasks multiply contiguous values: the host spectrum is kept as (planes,
    # N2 / 2 + 1, N1), each column's values side by side, made in the transforms' own
    # planes (taken from and put back on the runtime's shelf)
    k = rng.uniform(size=(5, 7, 3))
    n1, n2 = 12, 16
    spec, planes = fftconv._host_spectrum(rt, k, n1, n2, "float64")
    assert planes == 3 and spec.shape == (3, n2 // 2 + 1, n1) and spec.flags.c_contiguous
    for p in range(3):
        grid = np.zeros((n1, n2))
        np.add.at(grid, ((np.arange(5) - 2)[:, None] % n1, (np.arange(7) - 3)[None] % n2),
                  k[..., p])
        np.testing.assert_allclose(spec[p], np.fft.rfft2(grid).T, rtol=0, atol=1e-13)


@pytest.mark.parametrize("quality", ["final", "draft", "preview"])
def test_a_named_psf_is_hashed_once_per_name_and_its_spectra_follow_its_values(rt, rng,
                                                                             monkeypatch,
                                                                             quality):
    """Issue 37: a PSF that its caller names (``psf_key``: the key the glare family caches it
    under) is hashed once per name, not on every frame (3 ms of SHA-1 at 1080p); the
    spectra stay keyed by the PSF's values, so another PSF under another name, or the same
    name cut to a smaller reach, gets its own, bit for bit the unnamed call's."""
    hashed = []
    digest = fftconv.psf_digest
    monkeypatch.setattr(fftconv, "psf_digest", lambda k: hashed.append(k.shape) or digest(k))
    src = rng.uniform(0.0, 1.0, (6, 40, 4)).astype(np.float32)
    src[3, 11, :3] = 40.0
    win = Rect.from_size(40, 6)
    img = rt.upload(src, win)
    y, x = np.mgrid[-16:17, -16:17]
    a = 1.0 / (np.hypot(x, y) + 0.5) ** 3
    b = np.exp(-np.hypot(x, y) / 4.0)
    level = fftconv.LEVELS[quality]

    def spread(k, out=fftconv.full_region(win, 33, 33), **kw):
        return fftconv.spread(rt, img, k, level, out_window=out, split_level=10.0,
                              **kw).download().view(np.uint32)

    fftconv.clear_caches(rt)
    plain_a, plain_b = spread(a), spread(b)
    plain_cut = spread(a, win)          # 6 rows reach only the PSF's central 15: a cut PSF
    assert len(plain_a.shape) == 3 and not np.array_equal(plain_a, plain_b)
    fftconv.clear_caches(rt)
    del hashed[:]
    assert np.array_equal(spread(a, psf_key=("test.psf", "a")), plain_a)
    first = len(hashed)                 # the PSF (and draft's half-resolution one)
    assert first >= 1
    for _ in range(2):                  # named again: no hash, the same spectra
        assert np.array_equal(spread(a, psf_key=("test.psf", "a")), plain_a)
    assert len(hashed) == first
    # another PSF under another name: its own spectra, not a's
    assert np.array_equal(spread(b, psf_key=("test.psf", "b")), plain_b)
    # the same name, cut to a smaller reach: its own hash and spectrum
    assert np.array_equal(spread(a, win, psf_key=("test.psf", "a")), plain_cut)
    assert len(hashed) > first and (15, 33, 1) in hashed
