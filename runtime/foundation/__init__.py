"""Foundation: errors, atomic file io, settings dataclasses with --set, the tolerance table, limits, metrics,
spherical harmonics. Imports nothing above it."""
