"""Files: `read` (OpenImageIO reading and pass planning), `probe` (what a file holds and how it
is read), `write` (checked, atomic, exclusive writes), `raw` (ffmpeg gbrpf32le pipes),
`channels` (renderer conventions), `sequence` (frame patterns, ranges, input files)."""
