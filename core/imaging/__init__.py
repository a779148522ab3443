"""Images: plates read frame by frame (plates), background and foreground (background), the
model renderer (render) and contact sheets. May import core.geometry and core.body.
"""
