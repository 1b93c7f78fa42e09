"""One module per effect; each registers a Plugin subclass (see clfx.plugin)."""
