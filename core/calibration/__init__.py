"""Cameras from a calibration board seen in the plates. May import geometry and imaging.
"""
