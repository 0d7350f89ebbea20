"""Datasets: rendered and labelled frames in resumable shards."""
