"""A program that always makes the OpenCL compiler warn (``#warning``), built through clfx's
runtime: the cold-cache tests (tests/test_api.py, tests/test_distributed.py) check that what
it says stays off stderr, whether or not this machine's compiler has anything to say about
clfx's own kernels.

Each build is cold: the source names the folder it is written to, so no compiler cache
(PoCL's, clfx's build marker) holds it.  On a Dask worker the build runs through this module
as a worker preload (``DASK_DISTRIBUTED__WORKER__PRELOAD``, :func:`dask_setup`): before the
worker's first task, after clfx's worker plugin has set the worker up, as a render's kernel
builds do.
"""
from __future__ import annotations

import os
from pathlib import Path

SAID = "clfx test: the compiler warns"
"""What the program's ``#warning`` says."""

FOLDER_ENV = "CLFX_TEST_WARNS_DIR"
"""The folder a worker writes and builds the program in (:func:`dask_setup`)."""


def build(rt, folder) -> Path:
    """Write the program into ``folder`` and build it with ``rt`` (its program cache, its
    handling of the compiler's output and its warnings); returns the kernel file."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "warns.cl"
    path.write_text(f'#warning "{SAID}"\n'
                    f"/* {folder.resolve()} */\n"
                    "kernel void k(global float *x) { x[0] = 1.0f; }\n")
    kernels, rt.kernel_dir = rt.kernel_dir, folder
    try:
        rt.program(path.name)
    finally:
        rt.kernel_dir = kernels
    return path


def spoke(stderr: str) -> bool:
    """``stderr`` carries the compiler's warning (or clfx's report of it)."""
    return SAID in stderr or "KernelBuildWarning" in stderr


async def dask_setup(worker):
    """Preload hook: build the program (in ``$CLFX_TEST_WARNS_DIR/<pid>``) when this worker
    starts its first task, through the runtime clfx's worker plugin holds."""
    from distributed import WorkerPlugin

    class BuildBeforeTheFirstTask(WorkerPlugin):
        built = False

        def transition(self, key, start, finish, **kwargs):
            if finish != "executing" or self.built:
                return
            self.built = True
            from clfx.device.runtime import Runtime

            done = build(Runtime.get(), Path(os.environ[FOLDER_ENV]) / str(os.getpid()))
            done.with_suffix(".built").write_text("built\n")

    await worker.plugin_add(BuildBeforeTheFirstTask(), name="clfx-test-compiler-warns")
