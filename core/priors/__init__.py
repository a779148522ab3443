"""Learned priors and their data files (data/): the smooth-motion prior and the pose parameters'
names (motion_prior), the walking model and prior (walking), the pose prior of one-view
initialization (pose) and body proportions (proportions). May import core.geometry, core.body,
core.files.
"""
