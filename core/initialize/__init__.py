"""The fit of pose, joint angles and body dimensions to the joints clicked on anchor frames.
May import every stage above it: geometry, body, imaging, files, priors.
"""
