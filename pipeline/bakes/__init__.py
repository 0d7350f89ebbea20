"""Bakes: per-vertex and texture AO for meshes and glTF scenes, levels, dynamic-object volumes."""
