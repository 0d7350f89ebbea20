"""neuralao runtime: what a consumer runs (onnxruntime inference, headless GL shader runner, baselines)."""
