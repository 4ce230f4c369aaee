"""Spike-stream (viform) data: container, .dat files, zarr stores, events view."""
