"""`clfx bench`: the runner, one case module per effect, layered scenes, ground truth, metrics."""
