"""Issue 23, red team: masks that were reinterpreted silently or cost unbounded memory.

A mask file of another size than the frames was padded with zeros; a NaN mask counted as 0
without a word; a Cryptomatte without manifest matched names by hash without a word; a
feather of 1e7px asked for 88 GiB; a deeply nested manifest was a RecursionError.
"""
import json

import numpy as np
import pytest

import clfx
from clfx.core.errors import ClipError
from clfx.core.frame import Frame
from clfx.io import mattes
from clfx.io.write import write_frame
from clfx.pipeline.masks import MaskWarning
from tests.test_masks import BOX_A, crypto_channels, scene, write_exr


def masked(mask):
    return {"name": "m", "effects": [{"effect": "vignette", "mask": mask}]}


@pytest.fixture
def frame_and_masks(tmp_path):
    rgba = np.random.default_rng(1).uniform(0, 2, (16, 24, 4)).astype(np.float32)
    write_frame(Frame.from_array(rgba), tmp_path / "in.exr")
    write_frame(Frame.from_array(np.ones((8, 8, 4), np.float32)), tmp_path / "small.exr")
    nan = np.full((16, 24, 4), 0.5, np.float32)
    nan[2:5, 3:6, 3] = np.nan
    write_frame(Frame.from_array(nan), tmp_path / "nan.exr")
    write_frame(Frame.from_array(np.full((16, 24, 4), 0.5, np.float32)), tmp_path / "ok.exr")
    return tmp_path


def test_a_mask_file_of_another_size_is_refused(frame_and_masks):
    t = frame_and_masks
    with pytest.raises(ClipError, match=r"small.exr is 8x8 .* the frames 24x16 .* a mask must "
                                        r"match the frames") as info:
        clfx.render_file(t / "in.exr", t / "o.exr", masked({"file": str(t / "small.exr")}))
    assert "\n" not in str(info.value)
    assert not (t / "o.exr").exists()


def test_a_nan_mask_is_said_once(frame_and_masks, rt, capfd):
    t = frame_and_masks
    clfx.render_file(t / "in.exr", t / "o.exr", masked({"file": str(t / "nan.exr")}))
    err = capfd.readouterr().err
    lines = [ln for ln in err.splitlines() if "NaN" in ln]
    assert len(lines) == 1 and lines[0].startswith("clfx: warning: mask") and \
        "9 NaN pixel(s) counted as 0" in lines[0], err
    # the array API: a MaskWarning
    chans = {"m": np.where(np.arange(24)[None, :] < 3, np.nan, 1.0).repeat(16, 0)}
    with pytest.warns(MaskWarning, match="48 NaN pixel"):
        clfx.render_array(np.ones((16, 24, 4), np.float32), masked({"channel": "m"}),
                          channels=chans)


def test_a_huge_feather_is_refused_before_allocating(frame_and_masks):
    t = frame_and_masks
    look = masked({"file": str(t / "ok.exr"), "feather": "1e7px"})
    with pytest.raises(ClipError, match=r"feather 1e\+07px is more than the frame's diagonal"):
        clfx.render_file(t / "in.exr", t / "o.exr", look)
    with pytest.raises(ClipError, match="more than the frame's diagonal"):   # the array API
        clfx.render_array(np.ones((16, 24, 4), np.float32),
                          masked({"channel": "m", "feather": "1e7px"}),
                          channels={"m": np.ones((16, 24), np.float32)})


def _crypto_file(path, manifest):
    chans, alpha_a, alpha_b = scene()
    crypto, attrs = crypto_channels({"boxA": alpha_a, "boxB": alpha_b,
                                     "background": 1.0 - alpha_a - alpha_b})
    key = next(k for k in attrs if k.endswith("/manifest"))
    if manifest is None:
        del attrs[key]
    else:
        attrs[key] = manifest
    write_exr(path, {**chans, **crypto}, attrs)


def test_a_cryptomatte_without_manifest_is_said(tmp_path, rt, capfd):
    _crypto_file(tmp_path / "in.exr", None)
    look = masked({"cryptomatte": "CryptoObject", "names": ["boxA"]})
    clfx.render_file(tmp_path / "in.exr", tmp_path / "o.exr", look)
    err = capfd.readouterr().err
    assert "clfx: warning:" in err and "Cryptomatte 'CryptoObject' has no manifest" in err, err
    matte, _ = mattes.cryptomatte(tmp_path / "in.exr", "CryptoObject", ["boxA"])
    assert matte[BOX_A].min() == 1.0            # still found, by the hash of its name


@pytest.mark.parametrize("manifest", ["[" * 100000 + "]" * 100000,
                                      json.dumps({"boxA": "f" * 5000})])
def test_a_hostile_manifest_is_one_line(tmp_path, manifest):
    _crypto_file(tmp_path / "in.exr", manifest)
    look = masked({"cryptomatte": "CryptoObject", "names": ["boxA"]})
    with pytest.raises(ClipError, match="manifest") as info:
        clfx.render_file(tmp_path / "in.exr", tmp_path / "o.exr", look)
    assert "\n" not in str(info.value)
