"""neuralao runtime: what a consumer runs. onnxruntime inference on G-buffers, the headless GL and WebGPU
runners of the generated shaders, SSAO/GTAO, the internal-resolution passes, volume probes, the viewer
page and the shipped models. Imports nothing of the training or baking stack (torch, Embree, pyrender,
Ray): only ``neuralao.export.glsl`` and ``neuralao.runtime.foundation`` below it."""
