"""neuralao export: ONNX export and validation, GLSL generation from the ONNX graph."""
