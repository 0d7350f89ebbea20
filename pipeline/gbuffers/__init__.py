"""G-buffers: the float G-buffer rasterizer on the headless GL context."""
