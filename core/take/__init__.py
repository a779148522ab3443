"""The take driver: passes between anchors, running a tracker forward and backward, blending,
status, workers, progress and cancel (track), and fine-tuning of a tracked take (finetune). May
import every stage above; not commands.
"""
