#!/usr/bin/env python3
"""Sum a ``CLFX_TEST_CPU_LOG`` file (see tests/conftest.py) per test module, most CPU first.

    CLFX_TEST_CPU_LOG=cpu.jsonl make test;  python3 scripts/test_cpu_table.py cpu.jsonl [--tests N]
"""
import argparse
import collections
import json

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("log")
ap.add_argument("--tests", type=int, default=0, help="also list the N costliest tests")
args = ap.parse_args()
rows = [json.loads(line) for line in open(args.log) if line.strip()]
modules = collections.defaultdict(lambda: [0, 0.0, 0.0])
for r in rows:
    m = modules[r["id"].split("::")[0]]
    m[0] += 1
    m[1] += r["cpu_s"] + r["children_cpu_s"]
    m[2] += r["children_cpu_s"]
print(f"| module | tests | CPU s | of which children |\n|---|---:|---:|---:|")
for name, (n, cpu, kids) in sorted(modules.items(), key=lambda kv: -kv[1][1]):
    print(f"| {name} | {n} | {cpu:.1f} | {kids:.1f} |")
print(f"| total | {len(rows)} | {sum(m[1] for m in modules.values()):.1f} | |")
for r in sorted(rows, key=lambda r: -(r["cpu_s"] + r["children_cpu_s"]))[:args.tests]:
    print(f"{r['cpu_s'] + r['children_cpu_s']:8.1f}  {r['id']}")
