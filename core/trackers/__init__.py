"""Per-frame steppers: the differential tracker (differential, its image motion and limb
search: image_motion, recover) and the stepper that runs it over a take (stepper); the particle
filter and its likelihood (particle, likelihood, with the capsules of its occlusion and
silhouette tests in occlusion and the masks of its silhouette cue in silhouette_cue) and its
stepper (filter_stepper); the hybrid of both (hybrid); one view's frame prepared for them, and
the thread pools that prepare frames (frames). May import geometry, body, imaging, files,
priors, initialize.
"""
