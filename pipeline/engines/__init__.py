"""Execution engines (local threads, Ray) that run tasks; no domain code."""
