"""Bench case of vignette (moving here from the plugin module)."""
from clfx.bench.cases import Case
from clfx.plugins.vignette import bench_case

CASE = Case(make=bench_case)
