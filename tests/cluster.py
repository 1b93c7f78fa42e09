"""Helpers for the scaling tests: real `dask scheduler` / `dask worker` processes on 127.0.0.1,
`clfx render` in a subprocess, and pixel comparison of two output folders."""
from __future__ import annotations

import os
import socket
import subprocess
import sys
from contextlib import ExitStack, contextmanager
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
VENV_BIN = Path(sys.executable).parent
RENDER_TIMEOUT_S = 150  # a bound, not a speed target: 2 cores shared with Dask workers


def env(**extra) -> dict:
    """This checkout first on the path; one PoCL thread per process (2 shared cores)."""
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)
    return {**os.environ, "PYTHONPATH": path, "POCL_MAX_PTHREAD_COUNT": "1", **extra}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _stop(procs) -> None:
    for p in procs:
        if p.poll() is None:
            p.terminate()
    for p in procs:
        try:
            p.wait(timeout=5)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(timeout=5)


@contextmanager
def dask_cluster(logs: Path, workers: int = 2):
    """A scheduler and ``workers`` single-threaded workers (no nanny: a worker's pid is its
    process) from this venv's ``dask``; yields (address, worker Popen objects); every process
    is ended on exit."""
    from distributed import Client

    dask = VENV_BIN / "dask"
    address = f"tcp://127.0.0.1:{free_port()}"
    logs.mkdir(parents=True, exist_ok=True)
    procs = []
    files = ExitStack()

    def start(name, *args):
        log = files.enter_context(open(logs / f"{name}.log", "w"))
        procs.append(subprocess.Popen([str(dask), *args], env=env(), stdout=log,
                                      stderr=subprocess.STDOUT))
    try:
        start("scheduler", "scheduler", "--host", "127.0.0.1", "--port",
              address.rsplit(":", 1)[1], "--no-dashboard")
        for i in range(workers):
            start(f"worker{i}", "worker", address, "--nworkers", "1", "--nthreads", "2",
                  "--host", "127.0.0.1", "--no-dashboard", "--no-nanny")
        with Client(address, timeout=30, set_as_default=False) as client:
            client.wait_for_workers(workers, timeout=40)
        yield address, procs[1:]
    finally:
        _stop(procs)
        files.close()


def clfx(*args, timeout=RENDER_TIMEOUT_S, check=True, **extra_env) -> subprocess.CompletedProcess:
    """Run ``python -m clfx.cli ARGS`` from this checkout."""
    proc = subprocess.run([sys.executable, "-m", "clfx.cli", *map(str, args)], check=False,
                          env=env(**extra_env), capture_output=True, text=True, timeout=timeout)
    if check and proc.returncode != 0:
        raise AssertionError(f"clfx {' '.join(map(str, args))} exited {proc.returncode}:\n"
                             f"{proc.stderr[-3000:]}")
    return proc


def clfx_popen(*args) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "clfx.cli", *map(str, args)], env=env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def pixels(path: Path):
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(str(path))
    spec = buf.spec()
    return (spec.x, spec.y, spec.width, spec.height, tuple(spec.channelnames)), \
        buf.get_pixels(oiio.FLOAT)


def stamps(path: Path) -> dict:
    """The ``clfx:*`` header attributes a render stamps (look, its JSON, quality, values,
    hash, version, ...), but the command line, which names how the render was run."""
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    inp.close()
    return {a.name: spec.getattribute(a.name) for a in spec.extra_attribs
            if a.name.startswith("clfx:") and a.name != "clfx:commandLine"}


def assert_same_outputs(got: Path, want: Path) -> None:
    """Same file names (no temp files), bit-identical pixels, windows and channels, and the
    same stamps (a worker that rendered at another quality or with other values says so)."""
    names = sorted(os.listdir(want))
    assert sorted(os.listdir(got)) == names, f"{got}: {sorted(os.listdir(got))} != {names}"
    for name in names:
        (w_layout, w_px), (g_layout, g_px) = pixels(want / name), pixels(got / name)
        assert g_layout == w_layout, name
        np.testing.assert_array_equal(g_px, w_px, err_msg=name)
        w_stamps = stamps(want / name)
        assert "clfx:quality" in w_stamps and stamps(got / name) == w_stamps, name

