"""Every kernel entry point's declared argument types (clfx/device/kernel_args.py) against its
source: the compiler's own view (each program built with ``-cl-kernel-arg-info``, read back
with ``Kernel.get_arg_info``: after macros and ``#if``) and a plain-text reading of kernels/
(the fallback where the driver gives no argument info; it must agree with the compiler).

Every ``kernel`` in kernels/ has exactly one declaration, in its file's entry, with its
parameters' names and types; REAL parameters are float in a float32 build and double in a
``CLFX_FP64`` one.  The tests below them show the checks fail on a wrong declaration."""
from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from clfx.device.kernel_args import ENTRY_POINTS, KernelArgs, KernelArgumentError
from clfx.device.runtime import BUILD_OPTIONS, is_pocl, kernel_dir

PROBE_DEFINES = {
    "bleed.cl": [{}, {"RANK": 1}],                        # bleed_direct_mix / _separable_mix
    "chromatic_aberration.cl": [{"NWAVE": 3, "LUTN": 64},        # + the bicubic-only pair
                                {"NWAVE": 3, "LUTN": 64, "RS_FILTER": 1}],
    "lens.cl": [{}, {"LENS_MAPS": 1}],                    # lens_apply / lens_packed(_fix)
    "lib/analysis.cl": [{"TILE": 16}],
    "lib/image.cl": [{"CH": 4, "BORDER": 0}],
    "lib/motion.cl": [{}, {"CURVED": 1}],                 # motion_dilate's backward pair
}
"""Defines under which each file builds, together reaching every entry point (others build
with none).  Each is also built with CLFX_FP64=1 where the device has float64 (the f64 entry
points of breathing, distortion and lens exist only there)."""


def kernel_files() -> list[str]:
    root = kernel_dir()
    return sorted(p.relative_to(root).as_posix()
                  for p in [*root.glob("*.cl"), *root.glob("lib/*.cl")])


# -- the compiler's view ----------------------------------------------------------------------
def compiled_signatures(rt) -> dict[str, list[tuple[dict, int, list[tuple[str, str, str]]]]]:
    """{kernel: [(defines, fp64 (0/1), [(address qualifier, type name, name), ...]), ...]}: every
    build of every kernels/ file that has the kernel."""
    cl = rt.cl
    root = kernel_dir()
    qualifier = {cl.kernel_arg_address_qualifier.GLOBAL: "global",
                 cl.kernel_arg_address_qualifier.CONSTANT: "constant",
                 cl.kernel_arg_address_qualifier.LOCAL: "local",
                 cl.kernel_arg_address_qualifier.PRIVATE: "private"}
    out: dict = {}
    for file in kernel_files():
        src = (root / file).read_text()
        for defines in PROBE_DEFINES.get(file, [{}]):
            for fp64 in (0, 1) if rt.has_fp64 else (0,):
                opts = [*BUILD_OPTIONS, f"-I{root}", "-cl-kernel-arg-info",
                        *(["-DCLFX_HAS_FP64=1"] if rt.has_fp64 else []),
                        *(f"-D{k}={v}" for k, v in {**defines, "CLFX_FP64": fp64}.items())]
                prg = cl.Program(rt.ctx, src).build(options=opts)
                for knl in prg.all_kernels():
                    info = [(qualifier[knl.get_arg_info(i, cl.kernel_arg_info.ADDRESS_QUALIFIER)],
                             knl.get_arg_info(i, cl.kernel_arg_info.TYPE_NAME),
                             # PoCL spells a parameter named like a builtin (step) _cl_step
                             knl.get_arg_info(i, cl.kernel_arg_info.NAME).removeprefix("_cl_"))
                            for i in range(knl.num_args)]
                    out.setdefault(knl.function_name, []).append((defines, fp64, info))
    return out


def _unmatched(declared, found) -> list[str]:
    return ([f"{k}: a kernel without a declaration" for k in sorted(set(found) - set(declared))]
            + [f"{k}: declared, but no such kernel" for k in sorted(set(declared) - set(found))])


def compiled_mismatches(declared: dict[str, KernelArgs], compiled) -> list[str]:
    """Where ``declared`` disagrees with the compiler: kernels without a declaration,
    declarations without a kernel, and per parameter of each build its name, buffer-ness and
    type (REAL: float in a float32 build, double in a float64 one)."""
    problems = _unmatched(declared, compiled)
    for name in sorted(set(compiled) & set(declared)):
        for defines, fp64, args in compiled[name]:
            decl = declared[name].built_with(defines)
            if len(args) != len(decl.types):
                problems.append(f"{name}: {len(args)} parameters, declared {len(decl.types)}")
                continue
            for i, ((qual, tname, pname), want, dname) in enumerate(zip(args, decl.types,
                                                                        decl.names)):
                where = f"{name} parameter {i + 1} ({pname})"
                if pname != dname:
                    problems.append(f"{where}: declared as {dname}")
                if (qual in ("global", "constant")) != (want == "buf"):
                    problems.append(f"{where}: a {qual} {tname}, declared {want}")
                elif want != "buf":
                    expect = {"REAL": "double" if fp64 else "float"}.get(want, want)
                    if tname != expect:
                        problems.append(f"{where}: {tname} in a {'float64' if fp64 else 'float32'}"
                                        f" build, declared {want}")
    return list(dict.fromkeys(problems))       # once, not once per build


# -- the plain-text view --------------------------------------------------------------------------
_QUALIFIERS = {"const", "global", "__global", "constant", "__constant", "restrict",
               "__restrict", "volatile", "unsigned"}


def _clean(text: str) -> str:
    text = re.sub(r"/\*.*?\*/", " ", text, flags=re.S)
    text = re.sub(r"//[^\n]*", " ", text)
    return text.replace("\\\n", " ")


def text_signatures() -> dict[str, tuple[str, list[tuple[str, str]]]]:
    """{kernel: (file, [(type, name), ...])} read from kernels/ as text: ``kernel void`` of
    every .cl file (every ``#if`` branch), object-like macros in parameter lists and the
    function-like macros that define kernels (lib/scatter.h's SCATTER_KERNELS) expanded;
    a pointer parameter's type is ``buf``."""
    root = kernel_dir()
    sources = {p.relative_to(root).as_posix(): _clean(p.read_text())
               for p in [*root.glob("*.cl"), *root.glob("lib/*.cl"), *root.glob("lib/*.h")]}
    objects, functions = {}, {}
    for text in sources.values():
        for m in re.finditer(r"^\s*#define\s+(\w+)(\(([\w\s,]*)\))?[ \t]*([^\n]*)", text, re.M):
            if m.group(2):
                functions[m.group(1)] = ([p.strip() for p in m.group(3).split(",")], m.group(4))
            else:
                objects[m.group(1)] = m.group(4)
    out: dict = {}
    for file, text in sources.items():
        if not file.endswith(".cl"):
            continue
        for macro, (params, body) in functions.items():
            if "kernel" not in body:
                continue
            for m in re.finditer(rf"^\s*{macro}\(([^)]*)\)", text, re.M):
                expanded = body
                for p, a in zip(params, (a.strip() for a in m.group(1).split(","))):
                    expanded = re.sub(rf"\b{p}\b", a, expanded)
                text += "\n" + re.sub(r"\s*##\s*", "", expanded)
        for m in re.finditer(r"\bkernel\s+void\s+(\w+)\s*\(([^)]*)\)", text):
            params = re.sub(r"\b(\w+)\b", lambda w: objects.get(w.group(1), w.group(1))
                            if "," in objects.get(w.group(1), "") else w.group(1), m.group(2))
            params = re.sub(r"#if\s+(\w+)(.*?)#endif",    # conditional: "... if DEFINE"
                            lambda c: re.sub(r"([^,\s][^,]*)", rf"\1 @if {c.group(1)}",
                                             c.group(2)), params, flags=re.S)
            args = []
            for p in (p.strip() for p in params.split(",") if p.strip()):
                p, _, cond = p.partition("@if")
                words = [w for w in re.findall(r"\w+|\*", p) if w not in _QUALIFIERS]
                args.append(("buf" if "*" in words else words[0], words[-1], cond.strip() or None))
            assert m.group(1) not in out or out[m.group(1)] == (file, args), m.group(1)
            out[m.group(1)] = (file, args)
    return out


def text_mismatches(declared: dict[str, KernelArgs], parsed) -> list[str]:
    problems = _unmatched(declared, parsed)
    for name in sorted(set(parsed) & set(declared)):
        file, args = parsed[name]
        decl = declared[name]
        if decl.file != file:
            problems.append(f"{name}: defined in kernels/{file}, declared under {decl.file}")
        said = ", ".join(f"{t} {n}" + (f" if {c}" if c else "") for t, n, c in args)
        if said != decl.signature():
            problems.append(f"{name}: the source says {said}; declared {decl.signature()}")
    return problems


@pytest.fixture(scope="module")
def compiled(rt):
    if not is_pocl(rt.device.platform.name):
        pytest.skip("argument info is read from PoCL's builds (-cl-kernel-arg-info)")
    return compiled_signatures(rt)


def test_every_kernel_has_one_declaration_that_matches_what_the_compiler_built(compiled):
    assert compiled_mismatches(ENTRY_POINTS, compiled) == []
    assert len(compiled) == len(ENTRY_POINTS) >= 85


def test_every_kernel_has_one_declaration_that_matches_its_source_text():
    parsed = text_signatures()
    assert text_mismatches(ENTRY_POINTS, parsed) == []


def test_the_text_reading_agrees_with_the_compiler(compiled):
    """The fallback reads what the compiler builds (the same kernels, names, buffers)."""
    parsed = text_signatures()
    assert set(parsed) == set(compiled)
    for name, (_, args) in parsed.items():
        for defines, _, info in compiled[name]:
            built = [(t, n) for t, n, c in args if c is None or defines.get(c)]
            assert [n for _, n in built] == [n for _, _, n in info], name
            assert [t == "buf" for t, _ in built] == [q != "private" for q, _, _ in info], name


def _wrong(name: str, **change) -> dict[str, KernelArgs]:
    return {**ENTRY_POINTS, name: dataclasses.replace(ENTRY_POINTS[name], **change)}


def _retyped(name: str, index: int, new: str) -> dict[str, KernelArgs]:
    types = list(ENTRY_POINTS[name].types)
    types[index] = new
    return _wrong(name, types=tuple(types))


@pytest.mark.parametrize("declared, said", [
    (_retyped("dof_gather", 15, "int"), "dof_gather parameter 16 (cap_factor): float"),
    (_retyped("vignette_apply", 0, "int"), "vignette_apply parameter 1 (src): a global"),
    (_retyped("motion_gather", 6, "buf"), "motion_gather parameter 7 (ntiles): a private"),
    (_retyped("motion_dilate", 7, "int"), "motion_dilate parameter 8 (auxb): a global"),
    (_retyped("grain_noise", 5, "int"), "grain_noise parameter 6 (seed): uint"),
    (_retyped("chromatic_aberration_apply", 9, "float"), None),   # REAL cx: a float64 build
    (_wrong("mask_mix", types=ENTRY_POINTS["mask_mix"].types[:-1],
            names=ENTRY_POINTS["mask_mix"].names[:-1]), "mask_mix: 6 parameters, declared 5"),
    ({k: v for k, v in ENTRY_POINTS.items() if k != "corona_down"},
     "corona_down: a kernel without a declaration"),
    ({**ENTRY_POINTS, "corona_up": ENTRY_POINTS["corona_down"]},
     "corona_up: declared, but no such kernel"),
])
def test_a_wrong_declaration_fails_both_checks(compiled, rt, declared, said):
    found = compiled_mismatches(declared, compiled)
    if said is None:          # float vs REAL shows only where the device builds float64
        assert bool(found) == rt.has_fp64
    else:
        assert any(p.startswith(said) for p in found), found
    assert text_mismatches(declared, text_signatures())


def test_a_renamed_parameter_fails_both_checks(compiled):
    names = list(ENTRY_POINTS["corona_bright"].names)
    names[4] = "thresh"
    declared = _wrong("corona_bright", names=tuple(names))
    assert compiled_mismatches(declared, compiled) == [
        "corona_bright parameter 5 (threshold): declared as thresh"]
    assert len(text_mismatches(declared, text_signatures())) == 1


# -- the runtime applies and checks them -------------------------------------------------------
def test_the_runtime_refuses_an_undeclared_kernel_and_a_call_that_does_not_match(rt):
    with pytest.raises(KernelArgumentError, match="corona_nothing has no argument declaration"):
        rt.kernel("corona.cl", "corona_nothing")
    knl = rt.kernel("corona.cl", "corona_bright")
    src, dst = rt.image((4, 4), 4), rt.image((4, 4), 4)
    with pytest.raises(KernelArgumentError, match=r"corona.cl corona_bright takes 5 arguments, "
                                                  r"got 4 \(buf src, buf dst, int pitch"):
        rt.launch(knl, (4, 4), src, dst, 4, 4)
    with pytest.raises(KernelArgumentError, match=r"argument 2 \(buf dst\) wants a buffer, "
                                                  r"got int"):
        rt.launch(knl, (4, 4), src, 4, 4, 4, 0.5)
    with pytest.raises(KernelArgumentError, match=r"argument 3 \(int pitch\) wants int32, "
                                                  r"got DeviceImage"):
        rt.launch(knl, (4, 4), src, dst, dst, 4, 0.5)
    with pytest.raises(KernelArgumentError, match=r"argument 4 \(int height\) wants an "
                                                  r"integer, got 4.0"):
        rt.launch(knl, (4, 4), src, dst, 4, 4.0, 0.5)
    with pytest.raises(KernelArgumentError, match="out of range"):
        rt.launch(knl, (4, 4), src, dst, 4, 1 << 31, 0.5)
    rt.launch(knl, (4, 4), src, dst, 4, 4, 0.5)       # plain Python ints and floats
    rt.finish()


def test_plain_arguments_are_checked_without_the_general_path(rt, monkeypatch):
    """Issue 37: a launch's images, buffers, plain ints within the type and plain floats are
    checked by their exact types (the general `_scalar` path took ~4 ms of host time per
    1080p cinema frame); anything else still goes through it, refusals and all."""
    from clfx.device import runtime as runtime_module

    knl = rt.kernel("corona.cl", "corona_bright")
    src, dst = rt.image((4, 4), 4), rt.image((4, 4), 4)
    general = []
    scalar = runtime_module._scalar
    monkeypatch.setattr(runtime_module, "_scalar",
                        lambda v, *a: general.append(v) or scalar(v, *a))
    rt.launch(knl, (4, 4), src, dst.buffer, 4, 4, 0.5)
    assert general == []
    rt.launch(knl, (4, 4), src, dst, np.int32(4), True, np.float32(0.5))
    assert general == [4, True, 0.5]
    with pytest.raises(KernelArgumentError, match="out of range"):
        rt.launch(knl, (4, 4), src, dst, 4, 1 << 31, 0.5)
    rt.finish()


@pytest.fixture
def probe_dir(rt, tmp_path, monkeypatch):
    (tmp_path / "probe_args.cl").write_text(
        "kernel void probe(global float *o, const float f, const int i, const uint u,\n"
        "                  const float4 v)\n"
        "{ o[0] = f; o[1] = (float)i; o[2] = (float)u; vstore4(v, 1, o); }\n")
    monkeypatch.setattr(rt, "kernel_dir", tmp_path)
    return tmp_path


@pytest.mark.filterwarnings("ignore:overflow encountered in cast:RuntimeWarning")  # 1e39 -> inf
def test_plain_python_values_match_the_hand_casts(rt, probe_dir):
    """A plain float becomes the float32 the hand cast made (round to nearest, overflow to
    inf), an int or bool the int32 / uint32; a vector may be any sequence of numbers."""
    knl = rt.kernel("probe_args.cl", "probe", arg_types="buf o, float f, int i, uint u, "
                                                        "float4 v")
    out = rt.buffer(32)
    got = np.empty(8, np.float32)
    for f, i, u, v in ((0.1, -7, 2 ** 32 - 1, (1.0, 2.5, -3.0, 1e39)),
                       (1e39, True, np.uint32(5), np.arange(4.0) / 3),
                       (np.float64(1 / 3), np.int64(3), 0, [0, 1, 2, 3])):
        rt.launch(knl, (1,), out, f, i, u, v)
        rt.cl.enqueue_copy(rt.queue, got, out.buffer)
        want = np.array([np.float32(f), np.int32(i), np.float32(np.uint32(u)), 0, *np.float32(v)],
                        np.float32)
        np.testing.assert_array_equal(got[[0, 1, 2, 4, 5, 6, 7]], want[[0, 1, 2, 4, 5, 6, 7]])
    with pytest.raises(KernelArgumentError, match=r"argument 5 \(float4 v\) wants 4 numbers"):
        rt.launch(knl, (1,), out, 0.0, 0, 0, (1.0, 2.0))
    with pytest.raises(KernelArgumentError, match=r"argument 4 \(uint u\) wants a uint32"):
        rt.launch(knl, (1,), out, 0.0, 0, -1, (1.0, 2.0, 3.0, 4.0))
