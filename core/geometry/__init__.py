"""Rigid-body and camera geometry: twists and SE(3) (se3), pinhole, distortion and scaled
orthographic cameras (camera), triangulation and the similarity of point sets (triangulate).
Imports numpy, scipy, OpenCV and core.errors only.
"""
