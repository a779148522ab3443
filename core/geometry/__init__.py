"""Rigid-body and camera geometry: twists and SE(3) (se3), the pinhole camera and what both camera
models share (camera), lens distortion (lens), the scaled orthographic camera (ortho),
triangulation and the similarity of point sets (triangulate). Imports numpy, scipy, OpenCV and
core.errors only.
"""
