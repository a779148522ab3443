"""The fit of pose, joint angles and body dimensions to the joints clicked on anchor frames.

``run`` is the entry (``initialize``, and ``initialize_take`` as the trackers, the add-on and the
command line call it) with its options in ``options`` (``InitOptions``); ``problem`` the joint
least-squares problem; ``starts`` the starting points; ``fit`` the per-frame search shared by the
``calibrated`` and ``uncalibrated`` fits; ``flips`` the depth ambiguities of one view; ``refine``
the joint-based fine-tuning. The result and its init.json are ``core.files.initfile``.
May import every stage above it: geometry, body, imaging, files, priors.
"""
