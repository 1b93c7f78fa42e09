#!/usr/bin/env python3
"""Which kernels each group of tests/test_oclgrind.py launches, run on the default device
(PoCL: seconds, not Oclgrind's minutes), and which kernels of kernels/ no group launches:
exit status 1 if there is any (every kernel runs under Oclgrind; cover a new kernel in
``tests/oclgrind_child.py``'s ``PARAMS``, ``EXTRA`` or ``FX``, or delete a dead one).

    PYTHONPATH=. .venv/bin/python scripts/oclgrind_coverage.py [--size WxH] [--json F]

``--size`` replaces the effects' main frame (``tests/oclgrind_child.W, H``): a smaller frame
keeps Oclgrind's coverage where every group launches the same kernels (compare two --json).
"""
import argparse
import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from clfx.core.plugin import QUALITY_LEVELS  # noqa: E402
from clfx.device.runtime import Runtime  # noqa: E402
from tests import oclgrind_child as child  # noqa: E402
from tests.test_oclgrind import _builtin  # noqa: E402

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("--size", help="the effects' main frame, WxH (default: the child's)")
ap.add_argument("--json", help="write {group: kernels} here")
args = ap.parse_args()
if args.size:
    child.W, child.H = map(int, args.size.lower().split("x"))

rt = Runtime.get()
launched: set[str] = set()
launch = type(rt).launch


def recording(self, knl, *a, **kw):
    launched.add(knl.function_name)
    return launch(self, knl, *a, **kw)


type(rt).launch = recording
groups = {}
for kind in ("effect", "look", "fx"):
    for name in _builtin(kind):
        launched.clear()
        for level in QUALITY_LEVELS if kind == "effect" else ["draft"]:
            child.main([kind, name, level])   # the child's renders, one JSON line each
        groups[f"{kind}:{name}"] = sorted(launched)
source = "".join(p.read_text() for p in sorted((ROOT / "kernels").rglob("*"))
                 if p.suffix in (".cl", ".h"))
declared = set(re.findall(r"kernel void (\w+)\b(?!##)", source))
for macro, arg, body in re.findall(r"#define (\w+)\((\w+)\)((?:.*\\\n)*.*)", source):
    suffixes = re.findall(rf"kernel void {arg}##(\w+)", body)   # SCATTER_KERNELS(glare)
    for name in re.findall(rf"^{macro}\((\w+)\)", source, re.M) if suffixes else ():
        declared |= {name + s for s in suffixes}
used = set().union(*groups.values())
never = sorted(declared - used)
print(f"{len(used & declared)} of {len(declared)} kernels launched; never: "
      f"{', '.join(never) or '-'}", file=sys.stderr)
if args.json:
    Path(args.json).write_text(json.dumps(groups, indent=1))
sys.exit(1 if never else 0)
