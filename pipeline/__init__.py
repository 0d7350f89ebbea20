"""neuralao pipeline: scenes, cameras, G-buffers, AO labels, datasets, training, evaluation."""
