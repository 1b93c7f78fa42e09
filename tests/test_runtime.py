"""Device choice, program cache, device images."""
import numpy as np
import pyopencl as cl
import pytest

from clfx.device import runtime
from clfx.core.errors import DeviceError, KernelBuildError
from clfx.core.rect import Rect


class _FakeDevice:
    name = "Broken GPU"
    version = "OpenCL 3.0 broken"
    extensions = ""
    type = cl.device_type.GPU


class _BrokenPlatform:
    """A platform listed first whose device cannot even create a context."""

    name = "Broken ICD"
    version = "OpenCL 3.0"

    def get_devices(self):
        return [_FakeDevice()]


class _UnlistablePlatform:
    name = "Unlistable ICD"
    version = "OpenCL 1.2"

    def get_devices(self):
        raise cl.RuntimeError("clGetDeviceIDs failed: DEVICE_NOT_FOUND")


def test_working_device_chosen_when_broken_platforms_listed_first(monkeypatch):
    real = cl.get_platforms()
    monkeypatch.setattr(cl, "get_platforms", lambda: [_BrokenPlatform(), _UnlistablePlatform()] + real)
    reports, chosen = runtime.survey_devices()
    assert chosen is not None
    by_platform = {r.platform: r for r in reports}
    assert not by_platform["Broken ICD"].usable
    assert "test kernel failed" in by_platform["Broken ICD"].reason
    assert "cannot list devices" in by_platform["Unlistable ICD"].reason
    chosen_reports = [r for r in reports if r.chosen]
    assert len(chosen_reports) == 1 and chosen_reports[0].kind == "CPU"
    rt = runtime.Runtime(device=chosen)
    img = rt.upload(np.ones((3, 5, 4), np.float32))
    assert rt.download(img).shape == (3, 5, 4)


def test_no_usable_device_names_the_fix(monkeypatch):
    monkeypatch.setattr(cl, "get_platforms", lambda: [_BrokenPlatform()])
    with pytest.raises(DeviceError) as err:
        runtime.Runtime()
    msg = str(err.value)
    assert "pocl-opencl-icd" in msg and "Broken ICD" in msg and "\n" not in msg


def test_selector_that_matches_nothing_is_an_error():
    reports, chosen = runtime.survey_devices("no-such-device-xyz")
    assert chosen is None
    assert all("not selected" in r.reason for r in reports)


def test_selector_by_index_and_name():
    """Any usable device is found by its index and by a piece of its own name (not a name
    one implementation uses: PoCL 3 calls its CPU device "pthread-...", PoCL 5 "cpu-...")."""
    reports, chosen = runtime.survey_devices(None)
    assert chosen is not None
    _, by_index = runtime.survey_devices("0:0")
    _, by_name = runtime.survey_devices(chosen.name.strip()[-12:])
    assert by_index is not None and by_name is not None
    assert by_name.int_ptr == chosen.int_ptr


def test_program_built_once_and_kernels_reused(rt):
    k1 = rt.kernel("vignette.cl", "vignette_apply")
    k2 = rt.kernel("vignette.cl", "vignette_apply")
    assert k1 is k2
    assert rt.program("vignette.cl") is rt.program("vignette.cl")


def test_failed_build_shows_the_build_log(rt, tmp_path, monkeypatch):
    (tmp_path / "common.h").write_text("")
    (tmp_path / "bad.cl").write_text("kernel void bad(global float *x) { x[0] = undefined_name; }\n")
    monkeypatch.setattr(rt, "kernel_dir", tmp_path)
    with pytest.raises(KernelBuildError) as err:
        rt.program("bad.cl")
    assert "undefined_name" in str(err.value)


def test_cpu_device_builds_get_software_prefetch(rt, tmp_path, monkeypatch):
    """kernels/lib/common.h's clfx_prefetch is live where the device is the host's CPU (the
    runtime defines CLFX_HOST_CPU there) and nothing elsewhere; a kernel using it builds and
    runs either way."""
    import shutil

    (tmp_path / "lib").mkdir()
    shutil.copy(rt.kernel_dir / "lib" / "common.h", tmp_path / "lib" / "common.h")
    (tmp_path / "probe.cl").write_text(
        '#include "lib/common.h"\n'
        "kernel void probe(global int *o, global const float *s)\n"
        "{ clfx_prefetch(s + 16); o[0] = CLFX_CAN_PREFETCH; }\n")
    monkeypatch.setattr(rt, "kernel_dir", tmp_path)
    out, src = np.full(1, -1, np.int32), np.zeros(64, np.float32)
    o, s = rt.to_device(out), rt.to_device(src)
    rt.launch(rt.kernel("probe.cl", "probe", arg_types="buf o, buf s"), (1,), o, s)
    rt.cl.enqueue_copy(rt.queue, out, o.buffer)
    rt.finish()
    assert out[0] == int(rt.host_cpu_kernels)


def test_cpu_only_kernel_paths_follow_the_implementation_not_the_device_type(rt, monkeypatch):
    """CLFX_HOST_CPU (prefetch, streaming stores, out-of-line cold paths) is for PoCL's CPU
    device: Oclgrind reports every device type, CPU included, and cannot build a prefetch."""
    from types import SimpleNamespace

    from clfx.device.runtime import Runtime, is_pocl

    assert is_pocl("Portable Computing Language") and is_pocl("PoCL")
    assert not is_pocl("Oclgrind") and not is_pocl("Intel(R) OpenCL")
    cpu, all_types = int(rt.cl.device_type.CPU), int(rt.cl.device_type.ALL)
    for platform, kind, want in (("Portable Computing Language", cpu, True),
                                 ("Oclgrind", all_types, False),   # what Oclgrind reports
                                 ("Intel(R) OpenCL", cpu, False),
                                 ("Portable Computing Language", int(rt.cl.device_type.GPU), False)):
        fake = SimpleNamespace(cl=rt.cl, device=SimpleNamespace(
            type=kind, platform=SimpleNamespace(name=platform), global_mem_cache_size=1 << 20,
            mem_base_addr_align=1024))
        fake.shares_host_cores = Runtime.shares_host_cores.fget(fake)
        assert Runtime.host_cpu_kernels.fget(fake) is want, platform
        fake.host_cpu_kernels = want
        assert Runtime.streams_stores(fake, 1 << 30) is want, platform


@pytest.mark.parametrize("stream", [0, 1])
def test_streaming_stores_write_every_value_and_are_live_only_where_asked(rt, tmp_path,
                                                                         monkeypatch, stream):
    """kernels/lib/common.h's clfx_store16_streaming streams past the cache where the host
    asks (CLFX_STREAM_STORES=1) on the host's CPU, and is vstore16 elsewhere; either way every
    work-group's stores land (the group's last work-item fences), whatever the group size.
    A missing fence would not show here: on x86 the completion of PoCL's work-group already
    orders the stores in practice; the fence is what the ISA asks for."""
    import shutil

    (tmp_path / "lib").mkdir()
    shutil.copy(rt.kernel_dir / "lib" / "common.h", tmp_path / "lib" / "common.h")
    (tmp_path / "probe.cl").write_text(
        '#include "lib/common.h"\n'
        "kernel void probe(global float *o, global int *can)\n"
        "{ const int i = get_global_id(1) * get_global_size(0) + get_global_id(0);\n"
        "  clfx_store16_streaming((float16)(float)i + (float16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9,"
        " 10, 11, 12, 13, 14, 15) * 0.0625f, o + 16 * i);\n"
        "  if(i == 0) can[0] = CLFX_CAN_STREAM_STORE;\n  clfx_streaming_fence(); }\n")
    monkeypatch.setattr(rt, "kernel_dir", tmp_path)
    knl = rt.kernel("probe.cl", "probe", arg_types="buf o, buf can",
                   CLFX_STREAM_STORES=stream)
    for size, local in (((64, 9), None), ((16, 4), (8, 2)), ((1, 1), None)):
        n = size[0] * size[1]
        out = rt.to_device(np.full(16 * n, -1.0, np.float32))
        can = rt.to_device(np.full(1, -1, np.int32))
        rt.launch(knl, size, out, can, local=local)
        got, flag = np.empty(16 * n, np.float32), np.empty(1, np.int32)
        rt.cl.enqueue_copy(rt.queue, got, out.buffer)
        rt.cl.enqueue_copy(rt.queue, flag, can.buffer)
        rt.finish()
        want = np.repeat(np.arange(n, dtype=np.float32), 16) + np.tile(np.arange(16) / 16, n)
        np.testing.assert_array_equal(got, want.astype(np.float32))
        assert flag[0] == int(bool(stream) and rt.host_cpu_kernels)


def test_streaming_stores_are_asked_for_outputs_the_cache_cannot_keep(rt, monkeypatch):
    cache = int(rt.device.global_mem_cache_size)
    if not rt.host_cpu_kernels or cache <= 0:
        assert not rt.streams_stores(1 << 40)
        return
    assert rt.streams_stores(cache // 2) and not rt.streams_stores(cache // 2 - 1)


@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (5, 3), (17, 33)])
@pytest.mark.parametrize("channels", [1, 2, 4])
def test_upload_download_round_trip_with_padding(rt, rng, shape, channels):
    a = rng.standard_normal(shape + ((channels,) if channels > 1 else ())).astype(np.float32)
    img = rt.upload(a)
    assert img.pitch % runtime.ALIGN_PX == 0 and img.pitch >= shape[1]
    np.testing.assert_array_equal(rt.download(img), a)
    np.testing.assert_array_equal(rt.download(rt.copy(img)), a)


def test_reframe_zero_and_clamp(rt):
    a = np.arange(12, dtype=np.float32).reshape(3, 4)
    img = rt.upload(a, Rect(10, 10, 14, 13))
    grown = Rect(9, 9, 15, 14)
    z = rt.download(rt.reframe(img, grown, "zero"))
    c = rt.download(rt.reframe(img, grown, "clamp"))
    assert z[0].sum() == 0 and np.array_equal(z[1:4, 1:5], a)
    assert c[0, 0] == a[0, 0] and c[-1, -1] == a[-1, -1] and np.array_equal(c[1:4, 1:5], a)


def _reframe_reference(a, src: Rect, dst: Rect, border: str):
    """Every pixel of ``dst`` (frame coordinates) from ``a`` over ``src``: copied where
    covered, else 0 (zero) or the nearest source pixel (clamp)."""
    ys = np.arange(dst.y0, dst.y1) - src.y0
    xs = np.arange(dst.x0, dst.x1) - src.x0
    out = a[np.clip(ys, 0, src.height - 1)][:, np.clip(xs, 0, src.width - 1)]
    if border == "zero":
        inside = ((ys >= 0) & (ys < src.height))[:, None] & ((xs >= 0) & (xs < src.width))[None]
        out = np.where(inside if a.ndim == 2 else inside[..., None], out, 0.0)
    return out


@pytest.mark.parametrize("channels", [1, 2, 4])
@pytest.mark.parametrize("border", ["zero", "clamp"])
@pytest.mark.parametrize("dst", [Rect(9, 9, 36, 31), Rect(13, 12, 19, 15), Rect(11, 10, 29, 27),
                                 Rect(3, 20, 14, 33), Rect(40, 40, 45, 41), Rect(10, 10, 30, 23)])
def test_reframe_matches_reference_and_pads_with_zeros(rt, rng, channels, border, dst):
    # 4 pixels a work-item: quads fully inside copy as vectors, the rest pixel by pixel
    # (windows at every offset mod 4, partly outside, disjoint, and the source's own size)
    src = Rect(10, 10, 30, 23)
    a = rng.standard_normal(src.shape + ((channels,) if channels > 1 else ())).astype(np.float32)
    img = rt.upload(a, src)
    out = rt.reframe(img, dst, border)
    np.testing.assert_array_equal(rt.download(out), _reframe_reference(a, src, dst, border))
    raw = rt.from_device(out, np.float32, out.pitch * max(dst.height, 1) * channels)
    assert not raw.reshape(-1, out.pitch, channels)[:, dst.width:].any()   # the row padding


@pytest.mark.parametrize("shape", [(1, 1), (3, 37), (5, 64), (9, 130)])
def test_sanitize_zeroes_and_counts_nonfinite_pixels(rt, rng, shape):
    # 32 pixels a work-item: widths below, at and past a multiple of it; a clean frame too
    a = rng.standard_normal(shape + (4,)).astype(np.float32)
    img = rt.upload(a)
    assert rt.sanitize(img) == 0 and np.array_equal(rt.download(img), a)
    n = a.size // 4
    idx = rng.choice(n, size=max(1, n // 7), replace=False)
    bad = a.reshape(n, 4).copy()
    bad[idx, rng.integers(0, 4, idx.size)] = rng.choice([np.nan, np.inf, -np.inf], idx.size)
    bad[idx[:1], :] = np.nan                          # a pixel with every channel bad
    bad = bad.reshape(a.shape)
    img = rt.upload(bad)
    assert rt.sanitize(img) == idx.size
    np.testing.assert_array_equal(rt.download(img), np.where(np.isfinite(bad), bad, 0.0))


def test_buffers_return_to_the_pool_and_idle_memory_is_capped(rt):
    import gc

    from clfx.device.cache import DeviceCache

    img = rt.image((7, 9), 4)
    buf = img.buffer
    del img
    gc.collect()
    assert rt.image((7, 9), 4).buffer is buf  # reused, not re-created
    pool = DeviceCache(rt.ctx, max_bytes=1000)
    a, b, c = pool.take(400), pool.take(400), pool.take(300)
    pool.give(400, a)
    pool.give(400, b)
    pool.give(300, c)  # over the cap: the least recently freed (a) is released
    assert pool.idle_bytes == 700
    assert pool.take(300) is c and pool.take(400) is b


def test_small_uploads_are_queued_on_a_copy_and_large_ones_written_at_once(rt, monkeypatch):
    """Issue 37: `to_device` of a table does not wait for the kernels queued before it (a
    blocking write did: 19 waits a 1080p cinema frame, the device idle while the host went
    on); it uploads a copy, so the caller may reuse its array at once."""
    import numpy as np

    from clfx.device import runtime as runtime_module

    blocking = []
    copy = rt.cl.enqueue_copy
    monkeypatch.setattr(rt.cl, "enqueue_copy", lambda *a, **kw: blocking.append(
        kw.get("is_blocking", True)) or copy(*a, **kw))
    table = np.arange(1000, dtype=np.int32)
    held = rt.to_device(table)
    table[:] = -1                                   # reused before the upload ran
    assert blocking == [False] and held.pending is not None
    assert np.array_equal(rt.from_device(held, np.int32, 1000), np.arange(1000))
    monkeypatch.setattr(runtime_module, "QUEUED_UPLOAD_BYTES", 1024)
    del blocking[:]
    big = rt.to_device(np.ones(1000, np.float32))   # over the bound: written at once
    assert blocking == [True] and big.pending is None
    assert np.array_equal(rt.from_device(big, np.float32, 1000), np.ones(1000, np.float32))


def test_pocl_threads_pinned_by_default_where_every_core_is_ours(monkeypatch):
    import os

    monkeypatch.setattr(runtime, "_AFFINITY_DEFAULTED", False)
    monkeypatch.delenv("POCL_AFFINITY", raising=False)
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {1})       # confined: left alone
    runtime._ensure_pocl_affinity()
    assert "POCL_AFFINITY" not in os.environ
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    runtime._ensure_pocl_affinity()
    assert os.environ["POCL_AFFINITY"] == "1" and not runtime.user_set_pocl_affinity()
    monkeypatch.setattr(runtime, "_AFFINITY_DEFAULTED", False)
    monkeypatch.setenv("POCL_AFFINITY", "0")                              # the user's wins
    runtime._ensure_pocl_affinity()
    assert os.environ["POCL_AFFINITY"] == "0" and runtime.user_set_pocl_affinity()


def test_pocl_cache_dir_is_persistent_by_default():
    import os

    assert os.environ.get("POCL_CACHE_DIR")


def test_one_cache_evicts_what_is_worth_least_per_byte_then_least_recently_used(rt):
    import numpy as np

    from clfx.device.cache import BUFFER_COST_S, DeviceCache

    cache = DeviceCache(rt.ctx, max_bytes=1000)
    built = []

    def make(n):
        def build():
            built.append(n)
            return np.zeros(n, np.uint8)
        return build

    # equal cost per byte: least recently used goes first
    a = cache.get(("fx.a", 1), make(400), cost=4e-3)
    assert cache.get(("fx.a", 1), make(400)) is a and built == [400]  # a hit builds nothing
    cache.get(("fx.b", 1), make(300), cost=3e-3)
    cache.get(("fx.a", 1), make(400))                  # a is now the most recently used
    cache.get(("fx.c", 1), make(400), cost=4e-3)       # 1100 > 1000: b goes
    assert cache.peek(("fx.b", 1)) is None and cache.peek(("fx.a", 1)) is a
    # an expensive map outlives cheap entries used after it
    cache.clear()
    cache.get(("fx.map", 1), make(500), cost=1.0)
    cache.get(("fx.spectrum", 1), make(400), cost=1e-3)
    cache.get(("fx.spectrum", 2), make(400), cost=1e-3)  # over: the older spectrum goes
    assert cache.peek(("fx.map", 1)) is not None and cache.peek(("fx.spectrum", 1)) is None
    # idle buffers count in the same budget and are worth BUFFER_COST_S each
    buf = cache.take(200)
    cache.give(200, buf)
    # 1100 > 1000: the spectrum (1e-3 s for 400 B) is worth less than the buffer
    assert cache.idle_bytes == 200 and cache.nbytes == 700
    assert cache.stats()["owners"] == {"fx.map": 500, "buffer": 200}
    assert BUFFER_COST_S > 0
    big = cache.get(("fx.big", 1), make(5000))          # larger than the cap: not kept
    assert big.nbytes == 5000 and cache.peek(("fx.big", 1)) is None
    cache.get(("fx.prog", 1), lambda: "program", nbytes=0)
    cache.clear("fx.map")
    assert cache.peek(("fx.map", 1)) is None and cache.peek(("fx.prog", 1)) == "program"

def test_cache_counts_the_device_memory_it_allocated_and_its_peak(rt):
    """Issue 10 item 10: the pool's buffers live in host memory on PoCL; the cache says how
    many bytes it holds allocated (live and idle) and the most it held."""
    from clfx.device.cache import DeviceCache

    pool = DeviceCache(rt.ctx, max_bytes=1000)
    a, b = pool.take(400), pool.take(400)
    assert pool.device_bytes == pool.device_peak == 800
    pool.give(400, a)                       # idle: still allocated
    assert pool.device_bytes == 800 and pool.take(400) is a and pool.device_bytes == 800
    pool.give(400, a)
    pool.give(400, b)
    big = pool.take(2000)                   # over the cap: released when given back
    assert pool.device_peak == 2800
    pool.give(2000, big)
    pool.clear()                            # idle buffers released
    assert pool.device_bytes == 0 and pool.stats()["device_peak"] == 2800
    pool.reset_peak()
    assert pool.device_peak == 0


def test_a_device_without_float64_says_so_once_and_reference_still_renders(rt, monkeypatch,
                                                                         capfd):
    """Where the device lacks cl_khr_fp64 (simulated), the first float64 request says so in
    one line on stderr; the reference level renders in float32 and says nothing more."""
    from clfx import api

    monkeypatch.setattr(rt, "has_fp64", False)
    monkeypatch.setattr(rt, "_fp64_said", False)
    monkeypatch.setattr(rt, "_programs", {})
    monkeypatch.setattr(rt, "_kernels", {})
    assert rt.use_fp64(False) is False
    assert capfd.readouterr().err == ""
    rgba = np.full((9, 13, 4), 0.5, np.float32)
    rgba[4, 6, :3] = 1e4
    look = {"name": "fp64", "schema": 1,
            "effects": [{"effect": "glare", "params": {"strength": 0.1}},
                        {"effect": "grain", "params": {"amount": 0.02}}]}
    out = api.render_array(rgba, look, quality="reference", device=None)
    assert np.isfinite(out.rgba).all() and out.report.as_dict()["ran"] == ["glare", "grain"]
    assert rt.use_fp64(True) is False
    err = [line for line in capfd.readouterr().err.splitlines() if "float64" in line]
    assert len(err) == 1, err
    assert "has no float64 (cl_khr_fp64)" in err[0] and "reference" in err[0]


@pytest.mark.parametrize("size, want", [
    ((241, 1088), (241, 1)),     # grain_noise at 1080p: PoCL 3.1 chose (1, 136), columns
    ((493, 1128), (493, 1)),     # dof_prepare before round 1: PoCL chose (1, 1128)
    ((60, 34), (60, 1)),         # dof_tile_cap: PoCL ran the whole grid as one group
    ((8, 2255), (8, 5)),         # narrow rows stacked, up to GROUP_ITEMS work-items
    ((32, 10), (32, 1)),         # few rows: still one group per row
    ((4000, 2), (1000, 1)),      # two long rows: split so every core gets groups
    ((1920, 1080), (960, 1)),    # a row wider than the device's groups: its largest part
    ((4072,), (509,)), ((4071,), (177,)), ((7,), (1,)),
])
def test_row_groups_are_whole_rows_that_divide_the_grid(size, want):
    got = runtime.row_groups(size, 1024, (1024, 1024, 1024), 2)
    assert got == want
    assert all(g % l == 0 for g, l in zip(size, got))
    groups = np.prod([g // l for g, l in zip(size, got)])
    assert groups >= min(8, np.prod(size))


def test_row_groups_leave_3d_grids_to_the_device():
    assert runtime.row_groups((8, 8, 8), 4096, (4096,) * 3, 2) is None


def test_launch_without_a_local_size_runs_rows_in_groups_on_a_cpu(rt, tmp_path, monkeypatch):
    """A launch that names no work-group size gets row groups on a CPU device
    (runtime.row_groups): an odd width no longer makes PoCL 3.1 run one group for the whole
    grid (241 x 12 here: one thread) or groups one column wide; every work-item still runs
    once."""
    (tmp_path / "groups.cl").write_text(
        "kernel void groups_probe(global int *o)\n"
        "{ const int i = get_global_id(1) * get_global_size(0) + get_global_id(0);\n"
        "  o[4 * i] = get_local_size(0); o[4 * i + 1] = get_local_size(1);\n"
        "  o[4 * i + 2] = get_num_groups(0) * get_num_groups(1); o[4 * i + 3] = i; }\n")
    monkeypatch.setattr(rt, "kernel_dir", tmp_path)
    knl = rt.kernel("groups.cl", "groups_probe", arg_types="buf o")
    out = rt.to_device(np.full(4 * 241 * 12, -1, np.int32))
    rt.launch(knl, (241, 12), out)
    got = rt.from_device(out, np.int32, 4 * 241 * 12).reshape(-1, 4)
    np.testing.assert_array_equal(got[:, 3], np.arange(241 * 12))
    if rt.shares_host_cores:
        assert tuple(got[0, :2]) == (241, 1) and got[0, 2] == 12
