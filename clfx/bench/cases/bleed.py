"""Bench case of bleed (moving here from the plugin module)."""
from clfx.bench.cases import Case
from clfx.plugins.bleed import bench_case

CASE = Case(make=bench_case)
