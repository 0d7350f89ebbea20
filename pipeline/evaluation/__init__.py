"""Evaluation: scoring on test frames by category and resolution, the report and its parts, selection."""
