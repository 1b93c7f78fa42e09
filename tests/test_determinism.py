"""Every effect gives identical bytes with 1 PoCL thread (a separate process) and with the
default thread count; twice in a row; and frame N alone equals frame N in a batch (see
test_cli).  No float atomics, hashed noise, fixed summation orders (hard-cases.md case 16)."""
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from clfx.plugins import discover

SIZE = (72, 40)

RENDER_ALL = textwrap.dedent("""
    import sys
    import numpy as np
    from clfx.bench import cases
    from clfx.plugins import discover
    from clfx.device.runtime import Runtime
    from clfx.pipeline.presets import read_lens

    def render_all(width, height):
        rt = Runtime.get()
        out = {}
        for name, cls in discover().items():
            case = cases.for_effect(name).make(width, height, np.random.default_rng(3))
            p = cls.params(**case.get("params", {}))
            out[name] = cls().apply(rt, p, case["source"], depth=case.get("depth"),
                                    velocity=case.get("velocity"), camera=case.get("camera"),
                                    quality="final", frame=7, seed=11, read_lens=read_lens)
        return out

    if __name__ == "__main__":
        np.savez(sys.argv[1], **render_all(int(sys.argv[2]), int(sys.argv[3])))
""")


@pytest.fixture(scope="module")
def renders(rt, tmp_path_factory):
    folder = tmp_path_factory.mktemp("determinism")
    script = folder / "render_all.py"
    script.write_text(RENDER_ALL)
    env = dict(os.environ, POCL_MAX_PTHREAD_COUNT="1", POCL_CPU_MAX_CU_COUNT="1")
    subprocess.run([sys.executable, str(script), str(folder / "one.npz"), *map(str, SIZE)],
                   env=env, check=True, timeout=600)
    namespace = {}
    exec(compile(RENDER_ALL, "render_all", "exec"), namespace)
    first = namespace["render_all"](*SIZE)
    second = namespace["render_all"](*SIZE)
    return first, second, dict(np.load(folder / "one.npz"))


@pytest.mark.parametrize("name", sorted(discover()))
def test_identical_bytes_across_runs_and_thread_counts(renders, name):
    first, second, one_thread = renders
    assert first[name].tobytes() == second[name].tobytes(), f"{name} differs between runs"
    assert first[name].tobytes() == one_thread[name].tobytes(), \
        f"{name} differs between 1 PoCL thread and the default"
