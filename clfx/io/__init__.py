"""Files: `read` (OpenImageIO reading and pass planning), `probe` (what a file holds and how it
is read), `write` (checked, atomic, exclusive writes), `raw` (ffmpeg gbrpf32le pipes),
`channels` (renderer conventions), `colour` (OCIO spaces: working space, conversions,
chromaticities, RGB -> XYZ), `sequence` (frame patterns, ranges, input files)."""
