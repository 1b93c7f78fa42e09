"""Reusable algorithms below the effects: blur, FFT convolution, resampling, PSFs, spectra, scene analysis."""
