"""Geometry: scenes, cameras, composed rooms, mesh splits, level files and synthetic levels."""
