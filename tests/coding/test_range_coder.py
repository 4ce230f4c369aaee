"""The binary range coder every range-coded ``.vfc`` model shares: the bytes of a plain Python coder
written from the format's rules (LZMA-style carry, byte output), exact round trips, and a size within
a few bytes of the information coded."""

import numpy as np
import pytest

from viform.coding import _range_coder as rc

TOP, MASK32 = 1 << 24, (1 << 32) - 1


class PlainEncoder:
    """The coder's rules written out in Python: low (33 bits), range, a cached byte held for a carry."""

    def __init__(self):
        self.low, self.range, self.cache, self.csize, self.out = 0, MASK32, 0, 1, bytearray()

    def _shift(self):
        if self.low < 0xFF000000 or self.low > MASK32:
            carry, temp = self.low >> 32, self.cache
            while True:
                self.out.append((temp + carry) & 0xFF)
                temp = 0xFF
                self.csize -= 1
                if self.csize == 0:
                    break
            self.cache = (self.low >> 24) & 0xFF
        self.csize += 1
        self.low = (self.low & 0x00FFFFFF) << 8

    def _norm(self):
        while self.range < TOP:
            self.range <<= 8
            self._shift()

    def bit(self, p, shift, bit):
        bound = (self.range >> shift) * p
        if bit:
            self.low += bound
            self.range -= bound
        else:
            self.range = bound
        self._norm()

    def plain(self, bit):
        self.range >>= 1
        if bit:
            self.low += self.range
        self._norm()

    def uniform(self, v, n):
        """v in [0, n): the top 12-bit digit first (recursively), each digit range-coded uniformly."""
        if n <= 4096:
            if n > 1:
                r = self.range // n
                self.low += v * r
                self.range = r
                self._norm()
            return
        hi_n = ((n - 1) >> 12) + 1
        self.uniform(v >> 12, hi_n)
        lo_n = ((n - 1) & 4095) + 1 if (v >> 12) == hi_n - 1 else 4096
        self.uniform(v & 4095, lo_n)

    def flush(self):
        for _ in range(5):
            self._shift()
        return bytes(self.out)


def _script(seed, n=3000):
    """A random mix of modelled bits (skewed probabilities, shifts 11, 12, 16), plain bits and uniform values."""
    rng = np.random.default_rng(seed)
    ops = []
    for _ in range(n):
        kind = rng.integers(0, 3)
        if kind == 0:
            shift = int(rng.choice([11, 12, 16]))
            p = int(rng.integers(1, 1 << shift))
            bit = int(rng.random() >= p / (1 << shift))  # drawn from the stated probability
            ops.append(("bit", p, shift, bit))
        elif kind == 1:
            ops.append(("plain", int(rng.integers(0, 2))))
        else:
            n_values = int(rng.choice([1, 2, 7, 4096, 4097, 5000, 1 << 24, (1 << 24) + 3, (1 << 40) + 12345, 1 << 47]))
            n_values = int(rng.integers(1, n_values + 1))
            ops.append(("uniform", int(rng.integers(0, n_values)), n_values))
    return ops


def _encode(ops, size):
    out = np.zeros(size, np.uint8)
    st = rc.encoder_start()
    for op in ops:
        if op[0] == "bit":
            st = rc.encode_bit(st, out, op[1], op[2], op[3])
        elif op[0] == "plain":
            st = rc.encode_plain(st, out, op[1])
        else:
            st = rc.encode_uniform(st, out, op[1], op[2])
    return out, rc.encoder_flush(st, out)


@pytest.mark.parametrize("seed", [0, 1])
def test_bytes_are_the_plain_coders_and_decode_back(seed):
    ops = _script(seed)
    ref = PlainEncoder()
    for op in ops:
        getattr(ref, op[0])(*op[1:])
    want = ref.flush()
    out, n = _encode(ops, len(want) + 64)
    assert n == len(want) and out[:n].tobytes() == want
    # a too-small buffer: the count says how much is needed, nothing is written past the end
    small, n_small = _encode(ops, 10)
    assert n_small == n and small.tobytes() == want[:10]
    data = np.frombuffer(want, np.uint8)
    st = rc.decoder_start(data)
    for op in ops:
        if op[0] == "bit":
            got, st = rc.decode_bit(st, data, op[1], op[2])
            assert got == op[3]
        elif op[0] == "plain":
            got, st = rc.decode_plain(st, data)
            assert got == op[1]
        else:
            got, st = rc.decode_uniform(st, data, op[2])
            assert got == op[1]
    assert st[3] == 0 and st[2] <= len(want) + 5


def test_size_is_the_information_coded():
    """Bits drawn with P(0) = p cost −log2 of their probability; uniform values log2 n; the coder adds
    only its flush (5 bytes) and the rounding of each step."""
    ops = _script(3, 6000)
    info = 0.0
    for op in ops:
        if op[0] == "bit":
            p0 = op[1] / (1 << op[2])
            info -= np.log2(p0 if op[3] == 0 else 1 - p0)
        elif op[0] == "plain":
            info += 1
        else:
            info += np.log2(op[2])
    _, n = _encode(ops, 1 << 16)
    assert info / 8 <= n <= info / 8 * 1.002 + 6


def test_a_value_outside_the_range_sets_the_error_flag():
    """Bytes that no encoder writes for n = 3 (the code word past the range) decode to the flag, not a crash."""
    data = np.frombuffer(b"\xff" * 8, np.uint8)  # read-only, as the readers pass bytes (one compiled form)
    v, st = rc.decode_uniform(rc.decoder_start(data), data, 3)
    assert st[3] == 1 and 0 <= v < 3
