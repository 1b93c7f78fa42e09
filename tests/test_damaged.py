"""Fuzzed OpenEXR files (openexr-images/Damaged): each is rejected with ImageIOError, fast."""
import threading

import pytest

from clfx.core.errors import ImageIOError
from clfx.io.probe import probe
from clfx.io.read import read_frame
from tests.conftest import EXR_IMAGES, NO_EXR_IMAGES

DAMAGED = EXR_IMAGES / "Damaged"
FILES = sorted(p for p in DAMAGED.iterdir() if p.is_file() and not p.name.endswith(".rst")) \
    if DAMAGED.is_dir() else []
TIMEOUT_S = 30.0   # each file takes < 0.2 s; a hang fails the test instead of the run


def run_with_timeout(fn, *args, timeout=TIMEOUT_S):
    """Run ``fn(*args)`` in a thread; return the exception it raised (or None); fail the test
    if it has not finished after ``timeout`` seconds (a hang, a blocked open)."""
    result = {}

    def target():
        try:
            fn(*args)
        except BaseException as e:   # noqa: BLE001 - the test inspects it
            result["error"] = e

    t = threading.Thread(target=target, daemon=True)
    t.start()
    t.join(timeout)
    assert not t.is_alive(), f"{getattr(fn, '__name__', fn)}{args} did not finish within {timeout} s"
    return result.get("error")


@pytest.mark.skipif(not FILES, reason=f"{NO_EXR_IMAGES} (Damaged/)")
@pytest.mark.parametrize("path", FILES, ids=[p.name[:60] for p in FILES])
def test_damaged_file_raises_image_io_error(path):
    err = run_with_timeout(read_frame, path)
    assert isinstance(err, ImageIOError), f"{path.name}: expected ImageIOError, got {err!r}"
    msg = str(err)
    assert path.name in msg
    assert "\n" not in msg


@pytest.mark.skipif(not FILES, reason=f"{NO_EXR_IMAGES} (Damaged/)")
def test_damaged_files_probe_never_crashes():
    # probe reads headers only, so a file with a valid header may probe fine;
    # anything else must be an ImageIOError.
    for path in FILES:
        err = run_with_timeout(probe, path)
        assert err is None or isinstance(err, ImageIOError), f"{path.name}: {err!r}"


def test_missing_file_names_it(tmp_path):
    missing = tmp_path / "nope.0001.exr"
    with pytest.raises(ImageIOError, match="nope.0001.exr"):
        read_frame(missing)


def test_not_an_image_names_it(tmp_path):
    junk = tmp_path / "junk.exr"
    junk.write_text("this is not an image\n" * 10)
    with pytest.raises(ImageIOError, match="junk.exr") as info:
        read_frame(junk)
    assert "\n" not in str(info.value)


def test_empty_file_and_folder(tmp_path):
    empty = tmp_path / "empty.exr"
    empty.write_bytes(b"")
    with pytest.raises(ImageIOError, match="empty.exr"):
        read_frame(empty)
    with pytest.raises(ImageIOError, match="folder"):
        read_frame(tmp_path)
