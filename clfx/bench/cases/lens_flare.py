"""Bench case of lens_flare (moving here from the plugin module)."""
from clfx.bench.cases import Case
from clfx.plugins.lens_flare import bench_case

CASE = Case(make=bench_case)
