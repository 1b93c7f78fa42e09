"""Depth "no hit" conventions on read (issue 11 item 4): 0 and huge sentinel values become +inf
(infinitely far), said once per sequence; ``--depth-zero`` / ``PassSpec.depth_zero`` override;
the real Beachball frame (Z = 0 background) through ``dof`` gets a wider, not harder, edge."""
import warnings

import numpy as np
import OpenImageIO as oiio
import pytest
from click.testing import CliRunner

from clfx.cli import cli
from clfx.io import channels as ch
from clfx.io.probe import format_probe, probe
from clfx.io.read import DepthConventionWarning, PassSpec, read_frame
from tests.conftest import EXR_IMAGES as DATA, needs_exr_images

BEACHBALL = DATA / "Beachball"
needs_data = needs_exr_images
NO_HIT = "read as no hit"
# cinema's camera: 35 mm f/2 on Super 35 focused at 3 m; the ball (Z 9..11) is out of focus
# (CoC ~11 px), the background (+inf) more so (~17 px)
CAMERA = ("camera.focal_length=35", "camera.f_number=2", "camera.sensor_width=24.89",
          "camera.focus_distance=3")


def write_exr(path, channels: dict, formats: dict | None = None):
    names = list(channels)
    h, w = np.shape(channels[names[0]])
    spec = oiio.ImageSpec(w, h, len(names), "float")
    spec.channelnames = tuple(names)
    if formats:
        spec.channelformats = tuple(oiio.TypeDesc(formats.get(n, "float")) for n in names)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec), out.geterror()
    assert out.write_image(np.stack([np.asarray(channels[n], np.float32) for n in names], -1))
    assert out.close()
    return path


def ball(h=24, w=32, radius=8.0):
    """A disk at depth 5 with alpha 1 on a background of alpha 0; returns (rgba dict, mask)."""
    yy, xx = np.mgrid[0:h, 0:w]
    inside = (yy - h / 2) ** 2 + (xx - w / 2) ** 2 < radius ** 2
    a = inside.astype(np.float32)
    return {"R": a * 0.5, "G": a * 0.25, "B": a, "A": a}, inside


def read_warned(path, **kw):
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        fr = read_frame(path, **kw)
    return fr, [w for w in got if issubclass(w.category, DepthConventionWarning)]


# --------------------------------------------------------------------------------------------
# Synthetic files

def test_zero_background_with_alpha_0_is_far(tmp_path):
    rgba, inside = ball()
    path = write_exr(tmp_path / "zbg.exr", {**rgba, "Z": np.where(inside, 5.0, 0.0)})
    fr, warned = read_warned(path)
    assert np.all(np.isposinf(fr.depth[~inside])) and np.all(fr.depth[inside] == 5.0)
    assert len(warned) == 1
    msg = str(warned[0].message)
    assert str(path) in msg and "depth Z" in msg and NO_HIT in msg and "alpha 0" in msg
    info = probe(path)
    assert info["depth"]["no_hit"]["zero"] == "far"
    assert "infinitely far" in format_probe(info)
    kept, warned = read_warned(path, passes=PassSpec(depth_zero="invalid"))
    assert np.all(kept.depth[~inside] == 0.0) and not warned
    assert probe(path, passes=PassSpec(depth_zero="invalid"))["depth"]["no_hit"]["zero"] == "invalid"


def test_zero_sky_without_alpha_is_far_by_its_share(tmp_path):
    rgba, inside = ball()
    del rgba["A"]
    z = np.where(inside, 5.0, 0.0)              # ~74 % zeros, opaque (no alpha channel)
    fr, warned = read_warned(write_exr(tmp_path / "sky.exr", {**rgba, "Z": z}))
    assert np.all(np.isposinf(fr.depth[~inside])) and len(warned) == 1
    assert "at least 5%" in str(warned[0].message)


def test_few_opaque_zeros_stay_invalid_unless_forced(tmp_path):
    z = np.full((20, 30), 4.0, np.float32)
    z[3, 4] = 0.0                               # one hole, 0.17 %, alpha 1: a bad sample
    ones = np.ones_like(z)
    path = write_exr(tmp_path / "hole.exr", {"R": ones, "G": ones, "B": ones, "A": ones, "Z": z})
    fr, warned = read_warned(path)
    assert fr.depth[3, 4] == 0.0 and not warned
    assert probe(path)["depth"]["no_hit"]["zero"] == "invalid"
    far, warned = read_warned(path, passes=PassSpec(depth_zero="far"))
    assert far.depth[3, 4] == np.inf and len(warned) == 1


@pytest.mark.parametrize("value, fmt", [(1e10, "float"), (1e30, "float"), (-1e30, "float"),
                                        (-np.inf, "float"), (65504.0, "half")])
def test_huge_sentinels_are_far(tmp_path, value, fmt):
    z = np.full((8, 10), 3.0, np.float32)
    z[0, :] = value
    ones = np.ones_like(z)
    path = write_exr(tmp_path / "huge.exr", {"R": ones, "G": ones, "B": ones, "Z": z},
                     formats={"Z": fmt})
    fr, warned = read_warned(path)
    assert np.all(np.isposinf(fr.depth[0])) and np.all(fr.depth[1:] == 3.0)
    assert len(warned) == 1 and "10 pixel(s)" in str(warned[0].message)
    if np.isfinite(value) and value > 0 and fmt == "float":   # the threshold overrides
        kept, warned = read_warned(path, passes=PassSpec(depth_far_threshold=np.inf))
        assert np.all(kept.depth[0] == np.float32(value)) and not warned


def test_inf_background_and_scale(tmp_path):
    z = np.full((6, 6), 200.0, np.float32)
    z[0] = np.inf                               # clfx's own convention: nothing to say
    ones = np.ones_like(z)
    path = write_exr(tmp_path / "inf.exr", {"R": ones, "G": ones, "B": ones, "Z": z})
    fr, warned = read_warned(path, passes=PassSpec(depth_scale=0.01))
    assert np.all(np.isposinf(fr.depth[0])) and np.allclose(fr.depth[1:], 2.0) and not warned


def test_no_hit_decision_function():
    z = np.array([[0, 0, 5], [5, 5, 5]], np.float32)
    assert ch.no_hit(z, np.array([[0, 0, 1], [1, 1, 1]], np.float32)).zero == "far"
    assert ch.no_hit(z).zero == "far"                                # 33 % share
    one = np.full((10, 10), 5.0, np.float32)
    one[0, 0] = 0
    assert ch.no_hit(one, np.ones_like(one)).zero == "invalid"
    assert ch.no_hit(one, np.ones_like(one), zero="far").zero == "far"
    assert ch.no_hit(np.ones((2, 2), np.float32)).zero is None
    with pytest.raises(ValueError):
        ch.no_hit(z, zero="sometimes")


def test_pass_spec_checks_depth_zero():
    from clfx.core.errors import ClipError
    with pytest.raises(ClipError, match="depth_zero"):
        PassSpec(depth_zero="near")
    with pytest.raises(ClipError, match="depth_far_threshold"):
        PassSpec(depth_far_threshold=0.0)


def test_once_per_sequence_and_override_on_the_command_line(tmp_path, rt):
    rgba, inside = ball()
    for f in (1, 2, 3):
        write_exr(tmp_path / f"zb.{f:04d}.exr", {**rgba, "Z": np.where(inside, 5.0, 0.0)})
    args = ["apply", "dof", str(tmp_path / "zb.#.exr"), str(tmp_path / "o.#.exr"), *CAMERA]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 0, r.output
    lines = [ln for ln in r.stderr.splitlines() if NO_HIT in ln]
    assert len(lines) == 1 and "zb.0001.exr" in lines[0], r.stderr
    r = CliRunner().invoke(cli, args + ["--depth-zero", "invalid", "--overwrite"])
    assert r.exit_code == 0 and NO_HIT not in r.stderr, r.stderr
    r = CliRunner().invoke(cli, ["probe", str(tmp_path / "zb.0001.exr"), "--depth-zero", "invalid"])
    assert "kept as invalid" in r.output


# --------------------------------------------------------------------------------------------
# The real Beachball frame

@needs_data
def test_beachball_zero_background_reads_as_infinitely_far():
    path = BEACHBALL / "multipart.0001.exr"
    raw = read_frame(path, passes=PassSpec(depth_zero="invalid"))
    fr, warned = read_warned(path)
    zero = raw.depth == 0
    assert 0.2 < zero.mean() < 0.25                     # 22 % of Z is 0, all transparent
    assert np.all(np.isposinf(fr.depth[zero])) and np.array_equal(fr.depth[~zero], raw.depth[~zero])
    assert len(warned) == 1 and "multipart.0001.exr" in str(warned[0].message)
    assert probe(path)["depth"]["no_hit"]["zero"] == "far"


def _profiles(fr, centre, radius, t):
    """RGBA bilinearly sampled along rays across the silhouette, near the four diagonals
    (where the ball's edge is > 100 px from the data window), in display coordinates."""
    th = np.concatenate([np.deg2rad(d) + np.linspace(-0.35, 0.35, 15) for d in (45, 135, 225, 315)])
    x = centre[0] + (radius + t)[None, :] * np.cos(th)[:, None] - fr.data_window.x0 - 0.5
    y = centre[1] + (radius + t)[None, :] * np.sin(th)[:, None] - fr.data_window.y0 - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    h, w = fr.rgba.shape[:2]

    def at(yy, xx):
        ok = ((yy >= 0) & (yy < h) & (xx >= 0) & (xx < w))[..., None]
        return np.where(ok, fr.rgba[np.clip(yy, 0, h - 1), np.clip(xx, 0, w - 1)], 0.0)

    return (at(y0, x0) * (1 - fx) * (1 - fy) + at(y0, x0 + 1) * fx * (1 - fy)
            + at(y0 + 1, x0) * (1 - fx) * fy + at(y0 + 1, x0 + 1) * fx * fy)


def _edge(fr, centre, radius):
    """(median edge width of alpha, of luminance, largest dark dip) over the profiles.

    Edge width = (inside level - outside level) / steepest slope: a hard cut has a small
    width, a blurred edge a large one.  Dark dip = how far the luminance falls below the
    darker of the two sides' levels anywhere along a profile (a dark outline)."""
    t = np.arange(-40.0, 40.01, 0.5)
    p = _profiles(fr, centre, radius, t)
    lum = p[..., :3] @ np.array([0.2126, 0.7152, 0.0722])

    def width(v):
        inside, outside = v[:, :10].mean(1), v[:, -10:].mean(1)
        slope = (-np.diff(v, axis=1) / 0.5).max(1)
        return float(np.median((inside - outside) / slope))

    sides = np.minimum(lum[:, :10].mean(1), lum[:, -10:].mean(1))
    return width(p[..., 3]), width(lum), float((sides - lum.min(1)).max())


@needs_data
def test_beachball_dof_widens_the_ball_edge_with_one_notice(tmp_path, rt):
    src = read_frame(BEACHBALL / "multipart.0001.exr", passes=PassSpec(depth_zero="invalid"))
    a = src.rgba[..., 3] > 0.5
    ys, xs = np.nonzero(a)
    centre = (xs.mean() + src.data_window.x0, ys.mean() + src.data_window.y0)
    radius = float(np.sqrt(a.sum() / np.pi))
    args = ["apply", "dof", str(BEACHBALL / "multipart.#.exr"), str(tmp_path / "dof.#.exr"),
            *CAMERA, "--frames", "1-2"]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 0, r.output
    lines = [ln for ln in r.stderr.splitlines() if NO_HIT in ln]
    assert len(lines) == 1 and "multipart.0001.exr" in lines[0] and "depth Z" in lines[0], r.stderr
    r = CliRunner().invoke(cli, [*args[:3], str(tmp_path / "hard.#.exr"), *CAMERA,
                                 "--frames", "1", "--depth-zero", "invalid"])
    assert r.exit_code == 0, r.output

    def edge(name):
        return _edge(read_frame(tmp_path / name, passes=PassSpec(depth_zero="invalid")),
                     centre, radius)

    before, soft, hard = _edge(src, centre, radius), edge("dof.0001.exr"), edge("hard.0001.exr")
    # measured: alpha/luminance widths 20.1/13.3 px in the file, 33.7/19.9 px with the
    # background at +inf, 12.2/7.8 px (harder than the input) with Z = 0 kept as in focus
    assert soft[0] > 1.3 * before[0] and soft[1] > 1.3 * before[1], (before, soft)
    assert hard[0] < soft[0] and hard[1] < soft[1], (hard, soft)
    assert soft[2] <= 1e-3, soft                # no dark outline


def test_beachball_cinema_says_it_once(tmp_path, rt, small_beachball):
    # both views of the multipart file (decimated by 4: tests/plates.py; every pixel one of
    # the file's, so the same 22 % of Z is 0 under alpha 0)
    r = CliRunner().invoke(cli, ["render", str(small_beachball.path("multipart", 1)),
                                 str(tmp_path / "c.exr"), "--look", "cinema"])
    assert r.exit_code == 0, r.output
    lines = [ln for ln in r.stderr.splitlines() if NO_HIT in ln]
    assert len(lines) == 1 and "multipart.0001.exr" in lines[0], r.stderr
