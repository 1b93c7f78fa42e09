"""Bench case of motion_blur (moving here from the plugin module)."""
from clfx.bench.cases import Case
from clfx.plugins.motion_blur import bench_case

CASE = Case(make=bench_case)
