"""Bench case of corona (moving here from the plugin module)."""
from clfx.bench.cases import Case
from clfx.plugins.corona import bench_case

CASE = Case(make=bench_case)
