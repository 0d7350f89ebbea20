"""Ray tracing with Embree: the AO labeller, the level tracer and foliage occlusion."""
