"""The OpenCL device: runtime, program cache, pooled buffers and the one cache the runtime owns."""
