"""Bench case of camera_blur (moving here from the plugin module)."""
from clfx.bench.cases import Case
from clfx.plugins.camera_blur import bench_case

CASE = Case(make=bench_case)
