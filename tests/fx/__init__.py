"""Tests of the shared algorithms in clfx/fx/ (blur, fftconv, analysis)."""
