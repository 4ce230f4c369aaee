"""The default ``.vfc`` encoder's bytes on the shared recordings stay those of the reference encoder.

The SHA-256 of each file was recorded with the reference encoder (``main`` at commit b971c1f): a
faster coder must write the very same bytes, and read them back to the very same spikes.
"""

from __future__ import annotations

import hashlib
import warnings

import numpy as np
import pytest

from viform._validate import UnverifiedDataWarning
from viform.coding.aer_file import CodedFile, encode_source
from viform.stream.io import open_spikes

#: (file, (height, width) for a .dat, format version, bytes, SHA-256 of the .vfc file)
GOLDEN = [
    ("reds_sim_400x250.dat", (250, 400), 6, 959021,
     "ce50b10a78f74bd02ad752ecc28d28ade98c9534db1387776991a248e0e383b4"),
    ("reds_sim2_400x250.dat", (250, 400), 6, 1176872,
     "b4aa18b2158c514b2e885fc295d68c239e08101426bd20ac22c9291588c0c436"),
    ("real_uhsr_250x250.npz", (None, None), 6, 160646,
     "9aeae220b9ab13e61b67d6ab63deb878e5eb8ca1936c85f3947999d365fd3416"),
    ("real_uhsr_250x250.npz", (None, None), 5, 162650,
     "e7f05a75b8eb3300695047160cab070595dd233b48ba8db33256be4b762fed64"),
]


@pytest.mark.parametrize("name, hw, version, nbytes, sha", GOLDEN, ids=[f"{g[0]}-v{g[2]}" for g in GOLDEN])
def test_shared_files_code_to_the_reference_bytes(spike_data_dir, tmp_path, name, hw, version, nbytes, sha):
    path = spike_data_dir / name
    if not path.exists():
        pytest.skip(f"{name} absent")
    with warnings.catch_warnings():  # the shared files carry no viform checksums
        warnings.simplefilter("ignore", UnverifiedDataWarning)
        stream = open_spikes(path, *hw).to_memory()
    out = tmp_path / "s.vfc"
    encode_source(stream, out, version=version)
    data = out.read_bytes()
    assert (len(data), hashlib.sha256(data).hexdigest()) == (nbytes, sha)
    back = np.concatenate([b for _, b in CodedFile(out).iter_blocks(1024)])
    assert np.array_equal(back, stream.spikes)
