"""Synthetic plates with ground truth, for tests, the demo and benchmarks. May import geometry,
body, imaging and files.
"""
