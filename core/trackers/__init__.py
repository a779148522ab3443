"""Per-frame steppers: the differential tracker (differential, its image motion and limb
search: image_motion, recover), the particle filter and its likelihood (particle, likelihood) and
the hybrid of both (hybrid). May import geometry, body, imaging, files, priors, initialize.
"""
