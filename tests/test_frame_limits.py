"""Issue 10 item 3 (pipeline half): a frame's windows, and every window an effect grows it
to, are checked against the pixel limit before anything that size is allocated."""
import numpy as np
import pytest
from click.testing import CliRunner

from clfx.core import limits
from clfx.cli import cli
from clfx.core.errors import ClfxError
from clfx.core.frame import Frame
from clfx.core.rect import Rect
from clfx.pipeline.look import FrameTooLarge, Look, Step, render_frame
from clfx.plugins import get_plugin


def hot_frame(size=40):
    rgba = np.zeros((size, size, 4), np.float32)
    rgba[..., 3] = 1.0
    rgba[size // 2, size // 2, :3] = 1e4
    return Frame.from_array(rgba)


def glare_look():
    return Look("g", steps=[Step("glare", get_plugin("glare").params())])


def test_a_huge_display_window_is_refused_before_upload(rt, monkeypatch):
    frame = Frame(np.ones((1, 1, 4), np.float32), Rect(0, 0, 1, 1), Rect(0, 0, 60000, 60000),
                  source="tiny.exr")
    monkeypatch.setattr(rt, "upload", lambda *a, **k: pytest.fail("uploaded before the check"))
    with pytest.raises(FrameTooLarge) as err:
        render_frame(rt, glare_look(), frame)
    msg = str(err.value)
    assert isinstance(err.value, ClfxError) and "\n" not in msg
    assert msg.startswith("tiny.exr: display window is 60000x60000; the limit is")
    assert "(CLFX_MAX_PIXELS)" in msg


def test_a_window_grown_past_the_limit_is_refused_before_rendering(rt, monkeypatch):
    frame = hot_frame(40)
    _, report = render_frame(rt, glare_look(), frame, keep_overscan=True)
    assert report.steps[0].ran  # glare runs and spreads light past the frame
    monkeypatch.setattr(limits, "MAX_PIXELS", 40 * 40 + 1)  # the frame fits, growth does not
    glare = get_plugin("glare")
    render = glare.render
    monkeypatch.setattr(glare, "render", lambda *a, **k: pytest.fail("rendered past the limit"))
    with pytest.raises(FrameTooLarge, match=r"^frame grown by glare is \d+x\d+; the limit is 1601 "
                                            r"pixels and 65536 a side \(CLFX_MAX_PIXELS\)$"):
        render_frame(rt, glare_look(), frame, keep_overscan=True)
    monkeypatch.setattr(glare, "render", render)
    _, report = render_frame(rt, glare_look(), frame)  # cropped to the frame: within the limit
    assert report.steps[0].ran


def test_tiny_data_window_in_a_huge_display_window_from_the_cli(rt, tmp_path):
    """A few hundred bytes claiming a 60000x60000 frame: one line, exit 1, nothing written."""
    from clfx.io.write import write_frame

    src = tmp_path / "tiny.exr"
    write_frame(Frame(np.ones((1, 1, 4), np.float32), Rect(0, 0, 1, 1), Rect(0, 0, 60000, 60000)),
                src, bit_depth="float")
    assert src.stat().st_size < 2000
    r = CliRunner().invoke(cli, ["render", str(src), str(tmp_path / "o.exr"), "--look", "wide-angle"])
    err = r.stderr.strip()
    assert r.exit_code == 1, (r.exit_code, r.output)
    assert err.startswith("clfx: error:") and "\n" not in err and "60000" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tiny.exr"]
