"""Images: plates read frame by frame (plates), background and foreground (background), the
model renderer (render) and its ray casting against the body's primitives (raycast), and contact
sheets. May import core.geometry and core.body.
"""
