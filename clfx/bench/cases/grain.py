"""Bench case of grain (moving here from the plugin module)."""
from clfx.bench.cases import Case
from clfx.plugins.grain import bench_case, bench_peers

CASE = Case(make=bench_case, peers=bench_peers)
