"""The kit: what every effect of a family shares between the effects and the host.

``clfx.fx`` holds pure algorithms (maps, footprints, look-up tables, PSFs, FFT convolution,
launch helpers taking the device runtime and arrays); ``clfx.host`` holds the plugin host
and the render context.  The kit sits between them and the effects: the band/tile protocol
and the plugin mixins each effect family renders through, so a new effect of a family writes
its maps and kernels and no band code of its own.

- `clfx.kit.warp`: the warp family's canvas and band protocol (distortion, lens,
  chromatic_aberration, breathing, keystone): the frame a border rule applies at, the
  canvas a warp renders over, a tile's rows of the whole render (`CanvasRows`), map cache
  keys, the stand-in source a look's ``prepare`` builds maps on.
- `clfx.kit.scatter`: the glare family's plugin mixins (glare, bleed, soft_focus,
  halation; corona's identity and regions): threshold -> PSF spread -> mix.
- `clfx.kit.motion`: the motion family's base, `VelocityGather` (motion_blur,
  camera_blur's trucking, shake: an effect writes its velocity fields over a band's rows;
  the base plans, tiles and reconstructs them), its passes and band rows (rolling_shutter).
- `clfx.kit.noise`: the noise effects' per-frame exposure and coverage (grain,
  sensor_noise).
- `clfx.kit.spectral`: a spectral effect rendered in the reference basis whatever the
  working space (corona, lens_flare).

Everything here takes a render context or a plugin; nothing in ``clfx.fx`` does (checked by
tests/test_layers.py).
"""
