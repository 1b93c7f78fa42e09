"""Bench case of soft_focus (moving here from the plugin module)."""
from clfx.bench.cases import Case
from clfx.plugins.soft_focus import bench_case

CASE = Case(make=bench_case)
