"""The argument types of every kernel entry point, declared once (pyopencl's scalar argument
dtypes, ``Kernel.set_scalar_arg_dtypes``).

One table, file by file as in ``kernels/``: each entry point's parameters as its source
declares them, ``"<type> <name>, ..."``, where the type is

  ``buf``                   a ``global`` or ``constant`` pointer (a DeviceImage, a pooled or raw
                            buffer, or None for NULL)
  ``int`` ``uint`` ``float``  np.int32, np.uint32, np.float32
  ``REAL``                  kernels/lib/precision.h's REAL: np.float32, or np.float64 in a
                            ``CLFX_FP64`` build (``Runtime.kernel(..., fp64=True)`` where the
                            device has it)
  ``float4`` ``float8`` ``int4``  the OpenCL vector (pyopencl.cltypes); a launch may pass any
                            sequence of as many numbers

and ``<type> <name> if DEFINE`` is a parameter the source has only under ``#if DEFINE`` (a
build with that define non-zero).

`Runtime.kernel` applies the entry's dtypes to the kernel it returns and refuses a kernel the
table does not name; `Runtime.launch` checks a call against it (the count, buffers where
buffers go, and values that fit) and names the kernel and argument when one does not, so call
sites pass plain Python ints and floats.  tests/test_kernel_args.py checks every entry against
the compiler's own view of the source (PoCL's ``-cl-kernel-arg-info``): every ``kernel`` in
kernels/ has exactly one entry, with its parameters' names and types.

Why one table here and not a declaration beside each caller: the runtime applies it, and the
device layer imports nothing above it, so declarations in the effect modules would reach it
only as a side effect of importing them; several modules launch one file's kernels
(lib/motion.cl from fx/motion.py and plugins/rolling_shutter.py); and a kernel's signature is
edited in its ``.cl`` file, which this table mirrors file by file.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_SCALARS = {"int": np.dtype(np.int32), "uint": np.dtype(np.uint32),
            "float": np.dtype(np.float32)}
_VECTORS = {"float4", "float8", "int4"}


def _scatter_family(effect: str) -> dict[str, str]:
    """The three kernels lib/scatter.h's ``SCATTER_KERNELS(effect)`` defines."""
    return {
        f"{effect}_highlights": (
            "buf src, buf dst, int pitch, int height, float threshold, float knee, float boost"
        ),
        f"{effect}_highlights_at": (
            "buf src, int spitch, int swidth, int sheight, int dx, int dy, buf dst, int pitch, "
            "int width, int height, float threshold, float knee, float boost"
        ),
        f"{effect}_mix": (
            "buf src, int spitch, int swidth, int sheight, buf g, buf dst, int pitch, "
            "int height, int dx, int dy, float strength, float4 tint, float threshold, "
            "float knee, float boost, int additive"
        ),
    }


def _footprint_warp_family(effect: str) -> dict[str, str]:
    """The two kernels lib/footprint_warp.h's ``FOOTPRINT_WARP_KERNELS(effect)`` and
    ``EWA_WARP_KERNELS(effect)`` define (clfx.kit.warp.FootprintWarp)."""
    return {
        f"{effect}_footprint": (
            "buf src, buf dst, buf map, buf records, int src_pitch, int src_w, int src_h, "
            "int dst_pitch, int dst_h, int row0, int shift"
        ),
        f"{effect}_ewa_f64": (
            "buf src, buf dst, buf map, int src_pitch, int src_w, int src_h, int dst_pitch, "
            "int dst_h, int row0, int shift"
        ),
    }


KERNEL_ARGS: dict[str, dict[str, str]] = {
    # kernels/defocus.cl and motion_blur.cl build lib/blur.cl's and lib/motion.cl's kernels
    "lib/image.cl": {
        "image_reframe": (
            "buf src, int src_pitch, int src_w, int src_h, buf dst, int dst_pitch, int dst_w, "
            "int dst_h, int dx, int dy"
        ),
        "image_sanitize": "buf img, int pitch, int height, buf count",
        "image_rgb_matrix": (
            "buf src, buf dst, int pitch, int height, float4 r0, float4 r1, float4 r2"
        ),
    },
    "lib/mask.cl": {
        "mask_mix": "buf src, buf eff, buf mask, buf dst, int pitch, int height",
        "mask_multiply": "buf src, buf mask, buf dst, int pitch, int height",
        "mask_spread": "buf src, buf masked, buf eff, buf dst, int pitch, int height",
    },
    "lib/analysis.cl": {
        "analysis_rows": (
            "buf src, int pitch, int width, int height, buf depth, buf velocity, int has_depth, "
            "int has_velocity, buf rows, int tiles_x"
        ),
        "analysis_tiles": "buf rows, int width, int height, buf stats, int tiles_x, int tiles_y",
    },
    "lib/blur.cl": {
        "blur_direct_h": (
            "buf src, int src_pitch, int src_width, buf dst, int dst_pitch, int rows, "
            "int offset, buf weights, int taps, int border"
        ),
        "blur_direct_v": (
            "buf src, int src_rows, buf dst, int dst_rows, int pitch, int offset, buf weights, "
            "int taps, int border"
        ),
        "blur_gather_h": (
            "buf src, int src_pitch, buf dst, int dst_pitch, int rows, buf idx, buf wtab, "
            "int taps"
        ),
        "blur_gather_v": "buf src, buf dst, int pitch, int dst_rows, buf idx, buf wtab, int taps",
        "blur_sanitize": "buf src, buf dst, int pitch, int width, int rows, buf counts",
    },
    "lib/fftconv.cl": {
        "fftconv_pack": (
            "buf src, int pitch, int channels, int sx, int sy, int sw, int sh, buf work, int n1, "
            "int n2p, int c0, int nb, float split"
        ),
        "fftconv_multiply": "buf work, buf spec, int count, int nb, int spec_planes, int spec_c0",
        "fftconv_unpack": (
            "buf work, int n1, int n2p, int n2, buf dst, int pitch, int channels, int width, "
            "int height, int dx, int dy, int ex0, int ey0, int ex1, int ey1, int c0, int nb"
        ),
        "fftconv_count_bright": (
            "buf src, int pitch, int channels, int sx, int sy, int sw, int sh, float split, "
            "buf counts"
        ),
        "fftconv_compact_bright": (
            "buf src, int pitch, int channels, int sx, int sy, int sw, int sh, float split, "
            "buf offsets, buf pos, buf val"
        ),
        "fftconv_gather": (
            "buf dst, int pitch, int channels, int height, int dx, int dy, buf pos, buf val, "
            "int count, buf psf, int kw, int kh, int kcx, int kcy, int planes"
        ),
        "fftconv_pad": (
            "buf src, int pitch, int channels, int sx, int sy, int sw, int sh, buf dst, "
            "int dpitch, int dheight, int px, int py"
        ),
        "fftconv_direct": (
            "buf pad, int ppitch, buf dst, int pitch, int channels, int width, int height, "
            "int ex0, int ey0, int ex1, int ey1, buf psf, int kw, int kh, int planes"
        ),
        "fftconv_down2": (
            "buf src, int pitch, int channels, int sx, int sy, int sw, int sh, buf dst, "
            "int dpitch, int dwidth, int dheight"
        ),
        "fftconv_up2": (
            "buf lo, int hpitch, int hwidth, int hheight, int hx, int hy, buf dst, int pitch, "
            "int channels, int width, int height, int dx, int dy, int ex0, int ey0, int ex1, "
            "int ey1"
        ),
    },
    "lib/motion.cl": {
        "motion_prepare": "buf vel, buf depth, buf aux, int pitch, int height, float vmax",
        "motion_dilate": (
            "buf aux, buf col, buf out, int pitch, int width, int height, float duration, "
            "buf auxb if CURVED, buf outb if CURVED"
        ),
        "motion_sanitize": "buf src, buf dst, int pitch, int height",
        "motion_tilemax": (
            "buf aux, buf auxb, buf tiles, buf tiles_b, buf zrange, int pitch, int width, "
            "int height, int row0, int tiles_x, int tiles_y, int ty0, int k"
        ),
        "motion_neighbormax": (
            "buf tiles, buf tiles_b, buf nmax, buf nmax_b, int tiles_x, int tiles_y"
        ),
        "motion_gather": (
            "buf col, buf aux, buf auxb, buf nmax, buf nmax_b, buf tiles, int ntiles, buf dst, "
            "int pitch, int width, int row0, int row1, int band0, int band1, int tiles_x, int k, "
            "float t0, float t1, int frame"
        ),
    },
    "bleed.cl": {
        **_scatter_family("bleed"),
        "bleed_pad_highlights": (
            "buf src, int spitch, int swidth, int sheight, int ox, int oy, buf hp, int hpitch, "
            "int hheight, buf flags, float threshold, float knee"
        ),
        "bleed_active": "buf flags, int fpitch, int fheight, buf active, int pitch, int blocks_y",
        "bleed_direct_mix": (
            "buf hp, int hpitch, buf active, buf src, int spitch, int swidth, int sheight, "
            "buf dst, int pitch, int height, int dx, int dy, float strength, float4 tint, "
            "buf psf"
        ),
        "bleed_separable_mix": (
            "buf hp, int hpitch, buf active, buf src, int spitch, int swidth, int sheight, "
            "buf dst, int pitch, int height, int dx, int dy, float strength, float4 tint, "
            "buf hvec, buf vvec"
        ),
    },
    "breathing.cl": {
        "breathing_footprint": (
            "buf src, buf dst, int src_pitch, int src_w, int src_h, int dst_pitch, int dst_h, "
            "float ax, float ay, float inv_m, float hx, float hy, int n, int row0, int shift"
        ),
        "breathing_ewa_f64": (
            "buf src, buf dst, int src_pitch, int src_w, int src_h, int dst_pitch, int dst_h, "
            "REAL ax, REAL ay, REAL inv_m, REAL e, int n, int row0, int shift"
        ),
    },
    "camera_blur.cl": {
        "camera_blur_similarity": (
            "buf col, buf dst, int pitch, int width, int row0, int row1, int band0, int band1, "
            "int x0, int y0, float cx, float cy, float sx, float sy, float roll, float zoom, "
            "float t0, float t1, int n, int frame"
        ),
        "camera_blur_velocity": (
            "buf depth, buf vel, int pitch, int width, int height, int row0, int x0, int y0, "
            "float cx, float cy, float sx, float sy, float roll, float zoom, float truck_px_x, "
            "float truck_px_y, float dolly, float chord"
        ),
    },
    "chromatic_aberration.cl": {
        "chromatic_aberration_apply": (
            "buf src, buf dst, buf luts, buf weights, int pitch, int w, int h, int x0, int y0, "
            "REAL cx, REAL cy, REAL ax, REAL ay, int qx0, int row0, int nqx, int nrows, "
            "int shift"
        ),
        "chromatic_aberration_packed": (
            "buf src, buf dst, buf map, buf weights, int pitch, int w, int h, int row0, "
            "int rows, int shift"
        ),
        "chromatic_aberration_packed_rb": (
            "buf src, buf dst, buf map, buf flags, buf weights, int pitch, int w, int h, "
            "int row0, int rows, int shift"
        ),
        "chromatic_aberration_packed_exact": (
            "buf src, buf dst, buf map, buf flags, buf weights, int pitch, int w, int h, "
            "int row0, int rows, int shift"
        ),
        "chromatic_aberration_packed_fix": (
            "buf src, buf dst, buf records, int count, buf weights, int pitch, int w, int h, "
            "int row0, int rows, int shift"
        ),
    },
    "corona.cl": {
        "corona_bright": "buf src, buf dst, int pitch, int height, float threshold",
        "corona_down": (
            "buf src, int src_pitch, int src_w, int src_h, int ox, int oy, buf dst, int pitch, "
            "int width, int height, float threshold"
        ),
        "corona_compose": (
            "buf src, int src_pitch, int src_w, int src_h, int ox, int oy, buf glow, "
            "int g_pitch, int g_w, int g_h, buf dst, int pitch, int width, int height, "
            "float intensity, float threshold"
        ),
    },
    "distortion.cl": _footprint_warp_family("distortion"),
    "dof.cl": {
        "dof_prepare": (
            "buf src, buf depth, int pitch, int width, int height, buf col, buf coc, int ppitch, "
            "int pheight, int pad, float k_half, float focus, float clamp_r, float offset, "
            "buf log_mean, int tiles_x, int tiles_y, int tile, float cap_factor, int gx0, int gy0"
        ),
        "dof_edges": (
            "buf col, buf coc, buf out, int ppitch, int pheight, int pad, int width, int height"
        ),
        "dof_mixed": (
            "buf col, buf coc, buf mixa, buf mixr, buf mixd, int ppitch, int pheight, int pad, "
            "int width, int height, int y0, int y1, buf count, buf flags, int ftiles_x"
        ),
        "dof_tile_cap": (
            "buf src, int pitch, int ox, int oy, int sw, int sh, int width, int height, "
            "int tile, int tiles_x, int tiles_y, buf out"
        ),
        "dof_prefilter": (
            "buf src, int src_off, buf dst, int dst_off, int ppitch, int pheight, int step, "
            "int vertical"
        ),
        "dof_down2": (
            "buf col, buf coc, int ppitch, int pheight, buf hcol, buf hcoc, int hpitch, "
            "int hheight"
        ),
        "dof_gather": (
            "buf col, buf coc, int ppitch, int pad, buf dst, int pitch, int width, int height, "
            "buf taps, int taps_n4, buf tile_info, buf log_mean, int tiles_x, int tiles_y, "
            "int tile, "
            "float cap_factor, buf hres, int hpitch, int hwidth, int hheight, float4 refine, "
            "float low_r, float sharp_r, float8 cateye, int plane, int4 place, int4 hplace, "
            "buf mixa, buf mixr, "
            "buf mixd, buf mflags, int mtiles_x, int mtiles_y"
        ),
        "dof_merge_channels": "buf r, buf g, buf b, buf dst, int pitch, int width, int height",
    },
    "glare.cl": _scatter_family("glare"),
    "grain.cl": {
        "grain_noise": "buf noise, int npitch, int rows, int fx0, int fy0, uint seed, int frame",
        "grain_blur_h": "buf noise, buf tmp, buf weights, int npitch, int tpitch, int rows",
        "grain_apply": (
            "buf src, buf dst, buf tmp, buf weights, int pitch, int tpitch, int height, "
            "float ar, float ag, float ab, float response, float grey, float inv_grey"
        ),
        "grain_apply_white": (
            "buf src, buf dst, int pitch, int height, int fx0, int fy0, uint seed, int frame, "
            "float ar, float ag, float ab, float response, float grey, float inv_grey"
        ),
    },
    "halation.cl": {
        "halation_highlights": (
            "buf src, buf dst, int pitch, int height, float threshold, float knee"
        ),
        "halation_mix": (
            "buf src, int spitch, int swidth, int sheight, buf g, buf dst, int pitch, "
            "int height, int dx, int dy, float strength, float4 tint, float threshold, "
            "float knee"
        ),
    },
    "lens.cl": {
        "lens_packed": (
            "buf src, buf dst, buf map, int pitch, int w, int h, int row0, int rows, int shift, "
            "float ccx, float ccy, float vig_scale, float vk1, float vk2, float vk3"
        ),
        "lens_apply": (
            "buf src, buf dst, buf map, buf luts, int pitch, int w, int h, int row0, int rows, "
            "int shift, REAL ccx, REAL ccy, REAL lut_scale, REAL vig_scale, REAL vk1, REAL vk2, "
            "REAL vk3"
        ),
        "lens_packed_fix": (
            "buf src, buf dst, buf records, int count, int pitch, int w, int h, int row0, "
            "int rows, int shift, float ccx, float ccy, float vig_scale, float vk1, float vk2, "
            "float vk3"
        ),
    },
    "keystone.cl": _footprint_warp_family("keystone"),
    "lens_flare.cl": {
        "lens_flare_measure": "buf src, int pitch, buf boxes, int count, float threshold, buf out",
        "lens_flare_render": (
            "buf src, int src_pitch, int src_w, int src_h, int ox, int oy, buf dst, int pitch, "
            "int width, int height, int win_x0, int win_y0, int tiles_x, buf tile_start, "
            "buf tile_entries, buf entries, buf normals, float roundness, float rim"
        ),
        "lens_flare_ghosts": (
            "buf layer, int pitch, int width, int height, float fx0, float fy0, float factor, "
            "int tiles_x, buf tile_start, buf tile_items, buf entries, buf constants, "
            "buf normals, buf edge, buf coarse, int c_pitch, int c_w, int c_h, int has_coarse, "
            "buf src, int src_pitch, int src_w, int src_h, int ox, int oy"
        ),
    },
    "rolling_shutter.cl": {
        "rolling_shutter_tiles": (
            "buf aux, buf tiles, int pitch, int width, int height, int row0, int tiles_x, "
            "int tiles_y, int ty0, int k"
        ),
        "rolling_shutter_neighbors": "buf tiles, buf nbr, int tiles_x, int tiles_y",
        "rolling_shutter_gather": (
            "buf col, buf aux, buf auxb, buf nbr, buf dst, int pitch, int width, int row0, "
            "int row1, int band0, int band1, int tiles_x, int k, float tx, float ty, float xr, "
            "float yr"
        ),
    },
    "sensor_noise.cl": {
        "sensor_noise_prnu": (
            "buf pattern, int pitch, int height, int fx0, int fy0, uint prnu_seed, float prnu"
        ),
        "sensor_noise_apply": (
            "buf src, buf dst, buf pattern, int pitch, int height, int fx0, int fy0, uint seed, "
            "int frame, float kr, float kg, float kb, float read_e, float well, float prnu"
        ),
        "sensor_noise_demosaic": (
            "buf src, buf noisy, buf dst, int pitch, int width, int height, int fx0, int fy0, "
            "uint seed, int frame, float kr, float kg, float kb, float read_e, float prnu, "
            "float well, float chroma, float inv_cell"
        ),
    },
    "shake.cl": {
        "shake_velocity": (
            "buf vel, buf m, int pitch, int width, int height, int x0, int y0, float cx, "
            "float cy, float fx, float fy, float inv_dt"
        ),
    },
    "soft_focus.cl": _scatter_family("soft_focus"),
    "streaks.cl": {
        "streaks_seeds": (
            "buf src, int src_pitch, int src_w, int src_h, float threshold, buf peak, "
            "int tiles_x, int tiles_y, float core, float source_color, float core_power, "
            "int radius, float ring_share, buf seeds, buf count, int cap, buf flags, buf spans, "
            "buf lit"
        ),
        "streaks_dilate": "buf in, buf out, int w, int h, int radius, int sx, int sy",
        "streaks_extended": (
            "buf src, int src_pitch, int src_w, int src_h, float threshold, buf peak, "
            "int tiles_x, int tiles_y, float core, float source_color, float core_power, "
            "buf gathered, buf ext"
        ),
        "streaks_bright": (
            "buf src, int src_pitch, int src_w, int src_h, buf dst, int org, int dst_pitch, "
            "int dst_wp, int dst_h, int fx, int fy, float shear, int lead, int ox, int oy, "
            "float threshold, buf peak, int tiles_x, int tiles_y, float core, "
            "float source_color, float core_power, buf gathered, buf points, buf bin_start, "
            "buf bin_seed, int bins_x, int bin, int y0, int rows, buf spans"
        ),
        "streaks_pass": (
            "buf in, buf out, int org, int pitch, int wp, int w, int h, float step_x, "
            "float step_y, float4 w0, float4 w1, float4 w2, float4 w3, int y0, int in_rows, "
            "int out_rows, buf spans"
        ),
        "streaks_expand": (
            "buf lo, int org, int pitch, int lo_w, int lo_h, int f, int ext, float shear, "
            "buf acc, int acc_pitch, int w, int h"
        ),
        "streaks_compose": (
            "buf src, int src_pitch, int src_w, int src_h, int ox, int oy, buf streak, int org, "
            "int s_pitch, int r0, buf dst, int dst_pitch, int dst_w, int dst_h, int dx0, "
            "int dy0, int row0"
        ),
        "streaks_clear": "buf buf, int org, int pitch, int wp, int h, buf spans",
    },
    "vignette.cl": {
        "vignette_apply": (
            "buf src, buf dst, int pitch, int height, int x0, int y0, float cx, float cy, "
            "float sx, float sy, float inv_focal_mm, float natural, float ax, float ay, "
            "float amount, float radius, float inv_softness"
        ),
    },
}


class KernelArgumentError(TypeError):
    """A kernel without a declaration here, or a launch that does not match its declaration
    (a bug in clfx, not in the user's input: it names the kernel and the argument)."""


@dataclass(frozen=True)
class KernelArgs:
    """One entry point's declared parameters: ``names`` and ``types`` (the table's words), and
    per parameter the define it exists under (None: always)."""

    kernel: str
    file: str
    names: tuple[str, ...]
    types: tuple[str, ...]
    conditions: tuple[str | None, ...] = ()

    @classmethod
    def parse(cls, kernel: str, file: str, spec: str) -> "KernelArgs":
        names, types, conditions = [], [], []
        for part in (p.strip() for p in spec.split(",")) if spec.strip() else ():
            words = part.split()
            if not (len(words) == 2 or len(words) == 4 and words[2] == "if") or not (
                    words[0] in _SCALARS or words[0] in _VECTORS or words[0] in ("buf", "REAL")):
                raise KernelArgumentError(f"{file} {kernel}: cannot read the declaration "
                                          f"{part!r} (want '<type> <name>' or '<type> <name> "
                                          f"if DEFINE', types: buf, int, uint, float, REAL, "
                                          f"float4, float8, int4)")
            types.append(words[0])
            names.append(words[1])
            conditions.append(words[3] if len(words) == 4 else None)
        return cls(kernel, file, tuple(names), tuple(types), tuple(conditions))

    def built_with(self, defines: dict) -> "KernelArgs":
        """The parameters a build with ``defines`` has (``if DEFINE`` ones where it is
        defined non-zero)."""
        if not any(self.conditions):
            return self
        kept = [(n, t) for n, t, c in zip(self.names, self.types, self.conditions)
                if c is None or str(defines.get(c, 0)) not in ("0", "")]
        return KernelArgs(self.kernel, self.file, tuple(n for n, _ in kept),
                          tuple(t for _, t in kept))

    def dtypes(self, fp64: bool) -> list:
        """``Kernel.set_scalar_arg_dtypes``'s list: None for a buffer, else the dtype (REAL:
        float64 in a ``CLFX_FP64`` build)."""
        from pyopencl import cltypes  # lazy: pyopencl is ~0.2 s; `clfx looks` loads this module

        real = np.dtype(np.float64 if fp64 else np.float32)
        return [None if t == "buf" else real if t == "REAL" else _SCALARS.get(t)
                or getattr(cltypes, t) for t in self.types]

    def signature(self) -> str:
        return ", ".join(f"{t} {n}" + (f" if {c}" if c else "")
                         for t, n, c in zip(self.types, self.names,
                                            self.conditions or (None,) * len(self.names)))


def _entry_points() -> dict[str, KernelArgs]:
    out: dict[str, KernelArgs] = {}
    for file, kernels in KERNEL_ARGS.items():
        for name, spec in kernels.items():
            if name in out:
                raise KernelArgumentError(f"kernel {name} is declared twice ({out[name].file}, "
                                          f"{file})")
            out[name] = KernelArgs.parse(name, file, spec)
    return out


ENTRY_POINTS = _entry_points()
"""Every declared entry point by name (a kernel's name is unique across kernels/)."""


def declaration(file: str, name: str) -> KernelArgs:
    """The declaration of kernel ``name`` (built from ``kernels/<file>``); raises
    :class:`KernelArgumentError` when there is none."""
    try:
        return ENTRY_POINTS[name]
    except KeyError:
        raise KernelArgumentError(
            f"kernels/{file}: kernel {name} has no argument declaration; add "
            f"\"{name}\": \"<type> <name>, ...\" to clfx/device/kernel_args.py "
            f"(or pass arg_types= to Runtime.kernel for a kernel outside kernels/)") from None
