"""Metadata travels with the data: the .dat JSON sidecar and the same header in .npz and zarr."""

import json

import numpy as np
import pytest

from viform._validate import ViformError
from viform.imaging import accumulation_image
from viform.sensors.spike import SpikeSensor
from viform.stream.container import SpikeStream
from viform.stream.dat import write_dat
from viform.stream.io import open_spikes, save_spikes
from viform.stream.sidecar import provenance, read_sidecar, sidecar_path, write_sidecar

FIELDS = ("height", "width", "clock_hz", "threshold_electrons", "optics", "dark_current_e_per_s", "rows",
          "scene", "seed", "viform_version", "command_line", "utc_date")


def simulated_stream():
    """A stream with a full sensor description, as `viform simulate` gives."""
    sensor = SpikeSensor(threshold_electrons=80.0, dark_current_e_per_s=5.0)
    spikes = np.random.default_rng(0).random((40, 4, 8)) < 0.2
    meta = {"sensor": sensor.describe(), "scene": {"name": "moving-edge"}, "seed": 7}
    return SpikeStream(spikes, 40_000.0, 80.0, 0.0, meta)


def test_sidecar_path_and_provenance():
    assert sidecar_path("/a/clip.dat").name == "clip.dat.json"
    p = provenance()
    assert set(p) == {"viform_version", "command_line", "utc_date"}
    assert p["utc_date"].endswith("Z") and p["utc_date"][:2] == "20"


@pytest.mark.parametrize("name", ["s.dat", "s.npz", "s.zarr"])
def test_every_format_records_the_same_fields_and_gives_lux(tmp_path, name):
    stream = simulated_stream()
    path = save_spikes(tmp_path / name, stream, block_ticks=16)
    if name.endswith(".dat"):
        header = read_sidecar(path)
    elif name.endswith(".npz"):
        header = json.loads(str(np.load(path)["viform_header"]))
    else:
        import zarr

        header = zarr.open_array(str(path), mode="r").attrs["viform"]
    for field in FIELDS:
        assert field in header, field
    assert header["optics"]["quantum_efficiency"] == 0.7 and header["dark_current_e_per_s"] == 5.0
    assert header["seed"] == 7 and header["scene"]["name"] == "moving-edge"
    back = open_spikes(path)  # no height/width: the .dat sidecar gives them
    assert back.shape == stream.shape and back.threshold_electrons == 80.0
    assert np.array_equal(back.read_ticks(0, 40), stream.spikes)
    image = accumulation_image(back, 0.0009, 0.0005)
    assert image.lux is not None and np.all(np.isfinite(image.lux))


def test_dat_sidecar_contradiction_and_forgery_are_refused(tmp_path):
    path = write_dat(tmp_path / "s.dat", simulated_stream())
    with pytest.raises(ViformError, match="height = 5 contradicts"):
        open_spikes(path, 5, 8)
    side = read_sidecar(path)
    for field, value in [("clock_hz", -1), ("height", 0), ("threshold_electrons", "nan"), ("rows", "sideways"),
                         ("n_ticks", 41)]:
        write_sidecar(path, {**side, field: value})
        with pytest.raises(ViformError, match=field):
            open_spikes(path)
    sidecar_path(path).write_text("{not json")
    with pytest.raises(ViformError, match="not a readable JSON sidecar"):
        open_spikes(path)


def test_dat_sidecar_row_order_is_honoured(tmp_path):
    stream = simulated_stream()
    path = write_dat(tmp_path / "up.dat", stream, flip=False)
    assert read_sidecar(path)["rows"] == "upright"
    assert np.array_equal(open_spikes(path).read_ticks(0, 40), stream.spikes)


def test_dat_verify_catches_a_flipped_bit(tmp_path):
    path = write_dat(tmp_path / "s.dat", simulated_stream())
    assert open_spikes(path).verify()["verified"]
    raw = bytearray(path.read_bytes())
    raw[10] ^= 4
    path.write_bytes(bytes(raw))
    with pytest.raises(ViformError, match="damaged"):
        open_spikes(path).verify()


def test_other_tools_flat_sidecar_gives_lux(tmp_path):
    """A sidecar with flat optics and dark current (no sensor object) still gives lux."""
    path = write_dat(tmp_path / "s.dat", SpikeStream(np.ones((4, 4, 8), bool), 20_000.0), sidecar=False)
    write_sidecar(path, {"height": 4, "width": 8, "clock_hz": 20_000.0, "threshold_electrons": 50.0,
                         "optics": {"pixel_pitch_m": 1e-5, "fill_factor": 1.0, "quantum_efficiency": 0.5,
                                    "wavelength_m": 5.55e-7},
                         "dark_current_e_per_s": 0.0, "rows": "bottom-up", "source_clip": "clip7"})
    source = open_spikes(path)
    assert source.clock_hz == 20_000.0 and source.metadata["source_clip"] == "clip7"
    assert accumulation_image(source, 0.0001, 0.0001).lux is not None


def _two_pairs(tmp_path):
    """s.dat with its sidecar (stream a), and the sidecar stream b would have, as bytes."""
    a, b = (SpikeStream(np.random.default_rng(s).random((16, 4, 8)) < 0.3, 40_000.0) for s in (0, 1))
    other = write_dat(tmp_path / "other.dat", b)
    path = write_dat(tmp_path / "s.dat", a)
    return path, other, sidecar_path(other).read_bytes()


def test_pending_sidecar_matching_the_data_is_renamed_in(tmp_path):
    """A writer killed between its renames: new data, old sidecar, new one pending beside it."""
    from viform.stream.sidecar import pending_sidecar_path

    path, other, new_side = _two_pairs(tmp_path)
    path.write_bytes(other.read_bytes())  # the new data is in
    pending_sidecar_path(path).write_bytes(new_side)
    assert open_spikes(path).verify()["verified"]
    assert sidecar_path(path).read_bytes() == new_side and not pending_sidecar_path(path).exists()


def test_pending_sidecar_of_data_that_never_arrived(tmp_path):
    """Killed before its data rename: the old pair holds; the pending sidecar goes once stale."""
    import os

    from viform.stream.sidecar import PENDING_STALE_S, pending_sidecar_path

    path, _, new_side = _two_pairs(tmp_path)
    old_side = sidecar_path(path).read_bytes()
    pending = pending_sidecar_path(path)
    pending.write_bytes(new_side)
    assert open_spikes(path).verify()["verified"]
    assert pending.exists()  # young: it may be a live writer's, about to rename its data in
    old = pending.stat().st_mtime - 2 * PENDING_STALE_S
    os.utime(pending, (old, old))
    assert open_spikes(path).verify()["verified"]
    assert not pending.exists() and sidecar_path(path).read_bytes() == old_side


def test_neither_sidecar_matches_damaged_data(tmp_path):
    from viform.stream.sidecar import pending_sidecar_path

    path, _, new_side = _two_pairs(tmp_path)
    pending_sidecar_path(path).write_bytes(new_side)
    data = bytearray(path.read_bytes())
    data[3] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(ViformError, match="damaged"):
        open_spikes(path).read_ticks(0, 1)  # the block holding tick 0 is checked before use
    assert pending_sidecar_path(path).exists()  # both kept for whoever looks into it


def test_writer_whose_pending_sidecar_vanished_writes_it_again(tmp_path):
    """The second rename finds no pending sidecar (a reader renamed it in, or it was removed):
    the sidecar in place ends up the writer's either way."""
    from viform.stream.dat import _finish_pair
    from viform.stream.sidecar import DIGEST_KEY, pending_sidecar_path

    path, other, new_side = _two_pairs(tmp_path)
    body = json.loads(new_side)
    path.write_bytes(other.read_bytes())  # the new data is in, its sidecar gone missing
    _finish_pair(pending_sidecar_path(path), sidecar_path(path), body)
    assert read_sidecar(path)[DIGEST_KEY] == body[DIGEST_KEY]
    assert open_spikes(path).verify()["verified"]
