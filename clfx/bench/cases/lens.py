"""Bench case of lens (moving here from the plugin module)."""
from clfx.bench.cases import Case
from clfx.plugins.lens import bench_case

CASE = Case(make=bench_case)
