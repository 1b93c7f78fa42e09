"""Bench case of dof (moving here from the plugin module)."""
from clfx.bench.cases import Case
from clfx.plugins.dof import bench_case

CASE = Case(make=bench_case)
