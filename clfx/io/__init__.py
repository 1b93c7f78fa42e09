"""Files: reading (OpenImageIO), probing, writing, channels and renderer conventions, sequences."""
