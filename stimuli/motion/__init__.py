"""Motions: the Motion object, BVH/AMASS import, the walking/jogging generator, DTW averaging,
the thesis modifier, retargeting onto the Anny rig and motion-quality metrics."""

from stimuli.motion.motion import Motion

__all__ = ["Motion"]
