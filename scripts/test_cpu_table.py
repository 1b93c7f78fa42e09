#!/usr/bin/env python3
"""Sum a ``CLFX_TEST_CPU_LOG`` file (see tests/conftest.py) per test module, most CPU first.

    CLFX_TEST_CPU_LOG=cpu.jsonl make test;  python3 scripts/test_cpu_table.py cpu.jsonl [--tests N]

With ``CLFX_BUILD_LOG=builds.jsonl`` as well (clfx/device/runtime.py), ``--builds builds.jsonl``
adds per module: program builds, programs first built there, and builds slower than
``--cold`` seconds (compiles, not PoCL cache hits) of a program another process had already
compiled cold (two workers compiling the same program at once).
"""
import argparse
import collections
import json

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("log")
ap.add_argument("--tests", type=int, default=0, help="also list the N costliest tests")
ap.add_argument("--builds", help="a CLFX_BUILD_LOG file of the same run")
ap.add_argument("--cold", type=float, default=0.25,
                help="seconds above which a build was a compile (default 0.25)")
args = ap.parse_args()
rows = [json.loads(line) for line in open(args.log) if line.strip()]
modules = collections.defaultdict(lambda: [0, 0.0, 0.0, ""])
cache = [0, 0]
for r in rows:
    m = modules[r["id"].split("::")[0]]
    m[0] += 1
    m[1] += r["cpu_s"] + r["children_cpu_s"]
    m[2] += r["children_cpu_s"]
    if r.get("kernel_cache"):   # PoCL cache entries at the module's end: what it compiled
        m[3] = "{} / {}".format(*(now - was for now, was in zip(r["kernel_cache"], cache)))
        cache = r["kernel_cache"]
print("| module | tests | CPU s | of which children | programs / kernels compiled |\n"
      "|---|---:|---:|---:|---:|")
for name, (n, cpu, kids, built) in sorted(modules.items(), key=lambda kv: -kv[1][1]):
    print(f"| {name} | {n} | {cpu:.1f} | {kids:.1f} | {built} |")
print(f"| total | {len(rows)} | {sum(m[1] for m in modules.values()):.1f} | |")
for r in sorted(rows, key=lambda r: -(r["cpu_s"] + r["children_cpu_s"]))[:args.tests]:
    print(f"{r['cpu_s'] + r['children_cpu_s']:8.1f}  {r['id']}")
if args.builds:
    seen, cold_in = set(), collections.defaultdict(set)
    per = collections.defaultdict(lambda: [0, 0, 0, 0.0])
    for b in (json.loads(line) for line in open(args.builds) if line.strip()):
        key = (b["file"], tuple(map(tuple, b["defines"])))
        m = per[b["test"].split("::")[0] or "(outside a test)"]
        m[0] += 1
        if key not in seen:
            seen.add(key)
            m[1] += 1
        if b["s"] > args.cold:
            m[3] += b["s"]
            if cold_in[key] - {b["pid"]}:
                m[2] += 1
            cold_in[key].add(b["pid"])
    print("\n| module | builds | new programs | compiled again elsewhere | build s |\n"
          "|---|---:|---:|---:|---:|")
    for name, (n, new, again, secs) in sorted(per.items(), key=lambda kv: -kv[1][3]):
        print(f"| {name} | {n} | {new} | {again} | {secs:.1f} |")
    print(f"| total | {sum(m[0] for m in per.values())} | {len(seen)} | "
          f"{sum(m[2] for m in per.values())} | {sum(m[3] for m in per.values()):.1f} |")
