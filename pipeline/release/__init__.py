"""Release: train, export, check and install the shipped models."""
