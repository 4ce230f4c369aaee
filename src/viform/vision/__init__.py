"""Machine vision on sensor outputs, scored against the scene's exact truth (seed 000 §7).

Detection and tracking: :mod:`viform.vision.tracking` (spike and frame front ends, one
association back end), :mod:`viform.vision.metrics` (HOTA, MOTA, IDF1 from TrackEval; latency and
position error), :mod:`viform.vision.motchallenge` (MOTChallenge ``gt.txt``, results, ``seqinfo.ini``).
Optical flow: :mod:`viform.vision.flow`.
"""
