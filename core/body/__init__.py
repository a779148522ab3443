"""The articulated body: joints and their naming (joints), the kinematic model and its templates
(body), the standard joints' kinematics linear in the lengths (kinematics), the shape
primitives the renderer casts rays against (primitives), segment shapes and collision proxies
(shapes, collision), and fitting the model to known 3D joints (fit3d). May import core.geometry.
"""
