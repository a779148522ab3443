"""Learned priors and their data files (data/): motion priors of the particle tracker
(motion_prior) and body proportions (proportions). May import core.geometry, core.body, core.files.
"""
