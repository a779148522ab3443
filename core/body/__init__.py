"""The articulated body: joints and their naming (joints), the kinematic model and its templates
(body), segment shapes and collision proxies (shapes, collision), and fitting the model to known
3D joints (fit3d). May import core.geometry.
"""
