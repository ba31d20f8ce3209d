"""Exact truth from a scene: optics (virtual images, alpha, d_total) and ground-truth types."""
