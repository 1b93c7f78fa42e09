"""The core: rectangles, errors, frames, the camera model and the plugin base. Imports nothing else of clfx."""
