"""Model kinds (baked MLP, per-mesh AO field, DeepAO U-Net), their training and checkpoints."""
