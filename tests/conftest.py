"""Shared fixtures: the OpenCL runtime (skipped with a reason if absent), a seeded RNG,
paths to the shared real test data."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("CLFX_SHARED_DATA", ROOT.parent / "shared" / "data"))
EXR_IMAGES = SHARED_DATA / "openexr-images"


@pytest.fixture(scope="session")
def rt():
    from clfx.core.errors import DeviceError
    from clfx.device.runtime import Runtime

    try:
        return Runtime.get()
    except DeviceError as exc:
        if os.environ.get("CI"):
            raise  # CI must have a device: failing beats a green run that tested nothing
        pytest.skip(f"no OpenCL device: {exc}")


@pytest.fixture
def rng():
    return np.random.default_rng(20261121)


@pytest.fixture(scope="session")
def exr_images():
    if not EXR_IMAGES.is_dir():
        pytest.skip(f"shared test data not found at {EXR_IMAGES}")
    return EXR_IMAGES


def hard_shapes():
    """Image shapes every kernel must survive (hard-cases.md case 12)."""
    return [(1, 1), (1, 7), (7, 1), (2, 2), (3, 5), (17, 31), (64, 48)]
