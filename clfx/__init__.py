"""clfx: OpenCL-accelerated camera-defect effects for image sequences.

Real cameras are not perfect pinholes.  clfx adds their defects back to rendered frames, from
scene-linear radiance, as post effects: depth of field, defocus, noise and grain, motion blur,
glare, streaks, flares, coronas, vignetting, distortion and chromatic aberration.
"""
__version__ = "0.1.0"
