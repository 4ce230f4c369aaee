"""First-spike coding of spike streams (seed 000 §5.2) and the ``.vfc`` file that stores it.

* :func:`encode_array` / :func:`decode_segments` code a spike array in one of three modes
  (:class:`CodingParameters`: ``strict`` lossless, ``statistical``, ``intensity``);
  :func:`first_spikes` gives the (t, τ) first spikes of a pixel train;
  :class:`FirstSpikeEncoder` / :class:`FirstSpikeDecoder` do it segment by segment.
* The ``.vfc`` file: :func:`encode_source` codes any spike source into one (:class:`CodedWriter`),
  :func:`open_coded` reads it back as a spike source (:class:`CodedFile`), :func:`is_coded_file`,
  :func:`describe_coded_file` and :func:`verify_coded_file` inspect and check it.

The names are imported on first use (:mod:`viform._lazy`). Importing the package itself installs
numba's cache locators for the coding kernels (:mod:`viform.coding._compile_cache`), before any kernel
of the package is defined, and so imports numba.
"""

from viform import _lazy
from viform.coding._compile_cache import install_locators as _install_locators

# before any kernel of the package is defined: their numba cache is stamped by every source file here
_install_locators()

__all__ = [
    "CodingParameters", "FirstSpikeEncoder", "FirstSpikeDecoder", "encode_array", "decode_segments", "first_spikes",
    "encode_source", "open_coded", "CodedFile", "CodedWriter", "is_coded_file", "describe_coded_file",
    "verify_coded_file",
]

__getattr__, __dir__ = _lazy.attach(__name__, __all__, {
    "first_spike": ["CodingParameters", "FirstSpikeEncoder", "FirstSpikeDecoder", "encode_array", "decode_segments",
                    "first_spikes"],
    "aer_file": ["encode_source", "open_coded", "CodedFile", "CodedWriter", "is_coded_file", "describe_coded_file",
                 "verify_coded_file"],
})
