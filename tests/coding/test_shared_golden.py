"""The default ``.vfc`` encoder's bytes on the shared recordings stay those of the reference encoder.

The SHA-256 of each file was recorded with the reference encoder (``main`` at commit b971c1f): a
faster coder must write the very same bytes, and read them back to the very same spikes. The header
records where the spikes came from, so the test names each source by its file name alone: the bytes
must not depend on where a machine keeps the shared data.
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
    ("reds_sim_400x250.dat", (250, 400), 6, 959008,
     "cf63f9bb1ec91778fdae9f18d3c8bd0d80d1ef9a03b34a35a43e25bc8e3f9dc7"),
    ("reds_sim2_400x250.dat", (250, 400), 6, 1176858,
     "8bb446104e1023d2a4e4160965feb79e3b584763ba4d7c98cbf12d1ebce912cf"),
    ("real_uhsr_250x250.npz", (None, None), 6, 160630,
     "ef60040cdc63452560980d4f4ed1aae99a6e8bbf2d88c67d6e7623754171db74"),
    ("real_uhsr_250x250.npz", (None, None), 5, 162626,
     "514cd802cea884d90fae2128b72845a2150df8b51d1fe055760b82a2402c7f6b"),
]


@pytest.mark.parametrize("name, hw, version, nbytes, sha", GOLDEN, ids=[f"{g[0]}-v{g[2]}" for g in GOLDEN])
def test_shared_files_code_to_the_reference_bytes(spike_data_dir, tmp_path, name, hw, version, nbytes, sha):
    path = spike_data_dir / name
    if not path.exists():
        pytest.skip(f"{name} absent")
    with warnings.catch_warnings():  # the shared files carry no viform checksums
        warnings.simplefilter("ignore", UnverifiedDataWarning)
        stream = open_spikes(path, *hw).to_memory()
    stream.metadata["source"] = name  # the header records the source: not the machine's folder
    out = tmp_path / "s.vfc"
    encode_source(stream, out, version=version)
    data = out.read_bytes()
    assert (len(data), hashlib.sha256(data).hexdigest()) == (nbytes, sha)
    back = np.concatenate([b for _, b in CodedFile(out).iter_blocks(1024)])
    assert np.array_equal(back, stream.spikes)
