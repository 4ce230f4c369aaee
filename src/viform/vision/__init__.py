"""Machine vision on sensor outputs, scored against the scene's exact truth (seed 000 §7).

* Detection and tracking (:mod:`viform.vision.tracking`): :func:`track_spikes` and :func:`track_frames`
  (spike and frame front ends :class:`SpikeChangeDetector`, :class:`FrameChangeDetector`, one
  association back end :class:`Tracker` with :class:`TrackerParameters`) → :class:`TrackingResult`;
  scored by :func:`score_tracking` (HOTA, MOTA, IDF1 from TrackEval, :func:`trackeval_scores`;
  latency and position error). MOTChallenge files (``gt.txt``, results, ``seqinfo.ini``) are
  :mod:`viform.vision.motchallenge`.
* Optical flow (:mod:`viform.vision.flow`): :func:`estimate_flow` and :func:`flow_sequence` from spikes
  (:class:`FlowEstimate`), scored by :func:`motion_scores` and :func:`flow_scores`; Middlebury ``.flo``
  files by :func:`read_flo` / :func:`write_flo`.

The names are imported on first use (:mod:`viform._lazy`): ``import viform.vision`` costs nothing.
"""

from viform import _lazy

__all__ = [
    "track_spikes", "track_frames", "Tracker", "TrackerParameters", "TrackingResult", "SpikeChangeDetector",
    "FrameChangeDetector", "score_tracking", "trackeval_scores",
    "estimate_flow", "flow_sequence", "FlowEstimate", "motion_scores", "flow_scores", "read_flo", "write_flo",
]

__getattr__, __dir__ = _lazy.attach(__name__, __all__, {
    "tracking": ["track_spikes", "track_frames", "Tracker", "TrackerParameters", "TrackingResult",
                 "SpikeChangeDetector", "FrameChangeDetector"],
    "metrics": ["score_tracking", "trackeval_scores"],
    "flow": ["estimate_flow", "flow_sequence", "FlowEstimate", "motion_scores", "flow_scores", "read_flo",
             "write_flo"],
})
