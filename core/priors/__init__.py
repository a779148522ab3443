"""Learned priors and their data files (data/): motion priors of the particle tracker
(motion_prior), the pose prior of one-view initialization (pose) and body proportions
(proportions). May import core.geometry, core.body, core.files.
"""
