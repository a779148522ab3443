"""Per-frame steppers: the differential tracker (differential, its image motion and limb
search: image_motion, recover), the particle filter and its likelihood (particle, likelihood,
with the capsules of its occlusion and silhouette tests in occlusion) and the hybrid of both
(hybrid). May import geometry, body, imaging, files, priors, initialize.
"""
