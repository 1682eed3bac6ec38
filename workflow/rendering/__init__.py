"""Rendering textures on the plate: from a texture and a finger's motion to the drive envelope (docs/rendering.md).

:mod:`.textures` holds what is rendered (gratings, profiles, friction curves) and how the finger
moves; :mod:`.synthesis` computes the pre-compensated drive with the envelope model of
:mod:`workflow.damping.envelope`; :mod:`.metrics` measures how well an envelope follows the wanted one.
"""
