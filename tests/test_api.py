"""The Python API (issue 13): `import clfx` loads looks and renders arrays, files and
sequences; the examples of the README and docs/api.md run as written; the CLI goes through
the same functions."""
import os
import re
from pathlib import Path

import numpy as np
import pytest

import clfx

ROOT = Path(__file__).resolve().parents[1]


def python_example(page: str) -> str:
    """The first Python block of ``page`` (a path from the repository root)."""
    text = (ROOT / page).read_text()
    return re.search(r"```python\n(.*?)```", text, re.S).group(1)


def test_readme_example_runs(rt, capsys):
    code = python_example("README.md")
    exec(compile(code, "README.md", "exec"), {})
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("(90, 160, 4) [") and "'dof'" in out[0], out


def test_examples_give_opaque_frames():
    """An example's frame is opaque: alpha is coverage, never the grey of the pixels."""
    for page in ("README.md", "docs/api.md"):
        code = python_example(page)
        assert re.search(r"rgba\[\.\.\., 3\] = 1\.0", code), page


def test_api_page_example_runs(rt, tmp_path, monkeypatch, capsys):
    from clfx.core.frame import Frame
    from clfx.io.write import write_frame

    img = np.random.default_rng(2).uniform(0.05, 0.5, (36, 48, 4)).astype(np.float32)
    img[..., 3] = 1.0
    write_frame(Frame.from_array(img), tmp_path / "shot.exr")
    monkeypatch.chdir(tmp_path)
    exec(compile(python_example("docs/api.md"), "docs/api.md", "exec"), {})
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("(90, 160, 4) {'camera.focus_distance': ")
    assert "dof" in out[1] and out[2].startswith("1 ")
    assert (tmp_path / "out" / "shot.exr").is_file()


def test_import_is_cheap_and_documented():
    import subprocess
    import sys

    code = ("import sys, clfx; assert 'pyopencl' not in sys.modules and "
            "'OpenImageIO' not in sys.modules, sorted(sys.modules); print(clfx.__version__)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode == 0, r.stderr
    for name in ("load_look", "render_array", "render_file", "render_sequence", "runtime"):
        doc = getattr(clfx, name).__doc__
        assert doc and len(doc) > 40, name
    assert "metres" in clfx.render_array.__doc__ and "pixels per frame" in clfx.render_array.__doc__
    with pytest.raises(AttributeError):
        clfx.no_such_name


def test_load_look_by_name_dict_and_look():
    by_name = clfx.load_look("cinema", set=["glare.strength=0.1"])
    assert next(s for s in by_name.steps if s.effect == "glare").params.strength == 0.1
    doc = by_name.document()
    from_dict = clfx.load_look(doc)
    assert from_dict.params_hash() == by_name.params_hash()
    inherited = clfx.load_look({"base": "cinema", "effects": [{"effect": "grain",
                                                               "enabled": False}]})
    assert "grain" not in [s.effect for s in inherited.steps]
    copy = clfx.load_look(by_name, set=["seed=5"])
    assert copy.seed == 5 and by_name.seed != 5
    from clfx.core.errors import PresetError
    with pytest.raises(PresetError, match=r"look: effects\[0\].effect: unknown effect"):
        clfx.load_look({"effects": [{"effect": "glair"}]})


def test_render_array_with_passes_and_report(rt):
    h, w = 40, 64
    rgba = np.random.default_rng(4).uniform(0.1, 0.4, (h, w, 4)).astype(np.float32)
    rgba[..., 3] = 1.0
    rgba[10:20, 10:30, :3] = 1.0
    depth = np.where(np.arange(w)[None, :] < 32, 1.0, 50.0).astype(np.float32).repeat(h, 0)
    velocity = np.zeros((h, w, 2), np.float32)
    velocity[10:20, 10:30, 0] = 5.0
    look = {"camera": {"focus_distance": 1.0, "f_number": 1.4},
            "effects": [{"effect": "dof"}, {"effect": "motion_blur"}]}
    res = clfx.render_array(rgba, look, depth=depth, velocity=velocity, quality="draft")
    assert res.rgba.shape == (h, w, 4) and res.window.width == w
    assert [s.effect for s in res.report.steps if s.ran] == ["dof", "motion_blur"]
    assert np.abs(res.rgba - rgba)[:, 40:].max() > 1e-3     # the far half is out of focus
    from clfx.core.errors import ClipError, ParamError
    with pytest.raises(ClipError, match="needs a depth pass"):
        clfx.render_array(rgba, look)
    with pytest.raises(ParamError, match="depth: shape"):
        clfx.render_array(rgba, look, depth=depth[:5])


def test_render_sequence_returns_reports_and_checks_first(rt, tmp_path):
    from clfx.core.errors import ImageIOError
    from clfx.core.frame import Frame
    from clfx.io.write import write_frame

    img = np.full((16, 24, 4), 0.3, np.float32)
    for f in (1, 2, 3):
        write_frame(Frame.from_array(img), tmp_path / f"in.{f:04d}.exr")
    seen = []
    res = clfx.render_sequence(tmp_path / "in.#.exr", tmp_path / "out.#.exr",
                               "film-35mm", frames="1-2",
                               on_frame=lambda done, total, rep: seen.append((done, total)))
    assert res.summary["frames"] == 2 and seen == [(1, 2), (2, 2)]
    assert [r.frame for r in res.reports] == [1, 2] and len(res.outputs) == 2
    with pytest.raises(ImageIOError, match="exists"):
        clfx.render_sequence(tmp_path / "in.#.exr", tmp_path / "out.#.exr", "film-35mm")
    with pytest.raises(TypeError, match="RenderOptions"):
        clfx.render_file(tmp_path / "in.0001.exr", tmp_path / "x.exr", no_such_option=1)


def test_cli_is_a_thin_layer_over_the_api():
    """The CLI renders and loads looks through clfx.api (no second implementation)."""
    import inspect

    from clfx import cli

    src = inspect.getsource(cli)
    assert "from clfx.api import render as render_api" in src
    assert "Batch(" not in src and "render_frame" not in src


def test_the_api_keeps_compiler_warnings_quiet_on_a_cold_cache(tmp_path):
    """A cold PoCL cache makes the compiler warn (hundreds of lines for a look on some
    machines, none on others); the API says nothing, as the command line without -v, unless the
    caller's own filter asks.  The child builds one program that always warns
    (`tests.compiler_warns`) through the runtime, so the test does not depend on whether this
    machine's compiler has anything to say about clfx's own kernels, then renders through
    the API on a cold cache."""
    import subprocess
    import sys
    from pathlib import Path

    from tests import compiler_warns

    root = Path(__file__).resolve().parents[1]
    code = ("import sys, numpy as np, clfx\n"
            "from clfx.device.runtime import Runtime\n"
            "from tests import compiler_warns\n"
            "compiler_warns.build(Runtime.get(), sys.argv[1])\n"
            "clfx.render_array(np.ones((8, 8, 4), np.float32), {'effects': [{'effect': 'vignette'}]})\n")

    def run(*flags, cache):
        env = {**os.environ, "PYTHONPATH": str(root), "POCL_CACHE_DIR": str(tmp_path / cache)}
        env.pop("PYTHONWARNINGS", None)
        return subprocess.run([sys.executable, *flags, "-c", code, str(tmp_path / f"k{cache}")],
                              capture_output=True, text=True, env=env, timeout=300)

    quiet = run(cache="a")
    assert quiet.returncode == 0 and quiet.stderr == "", quiet.stderr
    shown = run("-W", "always::UserWarning", cache="b")     # the warnings are there to hide
    assert shown.returncode == 0, shown.stderr
    if compiler_warns.spoke(shown.stderr):
        assert "KernelBuildWarning" in shown.stderr
    else:        # a compiler that ignores #warning (none seen yet): nothing leaked either way
        assert shown.stderr == "", shown.stderr
