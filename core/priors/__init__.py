"""Learned priors and their data files (data/): the smooth-motion prior and the pose parameters'
names (motion_prior), the walking model and prior (walking), and body proportions
(proportions). May import core.geometry, core.body, core.files.
"""
