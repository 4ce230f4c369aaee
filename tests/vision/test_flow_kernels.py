"""The layered refinement's compiled kernels against plain references (same sums, same choices)."""

import numpy as np
import pytest
from scipy import ndimage as ndi

from viform.vision._flow_kernels import (
    best_shift,
    grid_gains,
    inner_depth,
    rim_mean_exceeds,
    shift_gain,
    shift_gains,
    warp_costs,
    warp_costs_at,
)

CAP, UNKNOWN, EXCEPTION = 9.0, 3.0, 2.0


def _images(seed, h=24, w=30):
    """Two noisy log images with a bright square moved by (2, 3) px, their variances, still costs, labels."""
    rng = np.random.default_rng(seed)
    log0 = rng.normal(0.0, 0.05, (h, w))
    log1 = rng.normal(0.0, 0.05, (h, w))
    log0[6:14, 8:17] += 1.0
    log1[8:16, 11:20] += 1.0
    var0 = np.full((h, w), 0.01) * rng.uniform(0.5, 2.0, (h, w))
    var1 = np.full((h, w), 0.01) * rng.uniform(0.5, 2.0, (h, w))
    still = np.minimum((log1 - log0) ** 2 / (var0 + var1), CAP)
    labels = np.zeros((h, w), np.int32)
    labels[6:14, 8:17] = 1
    rows, cols = np.nonzero(labels == 1)
    return log0, log1, var0, var1, still, labels, rows.astype(np.int64), cols.astype(np.int64)


def _best_shift_reference(log0, log1, var0, var1, still, labels, region, rows, cols, sub_r, sub_c, radius):
    """The search written shift by shift with :func:`shift_gain` (grid of 2, then steps 1 and 0.5)."""
    def gain(pr, pc, dy, dx):
        return shift_gain(log0, log1, var0, var1, still, labels, region, pr, pc, float(dy), float(dx), CAP, UNKNOWN,
                          EXCEPTION)

    best, by, bx = 0.0, 0.0, 0.0
    for i in range(-radius, radius + 1, 2):
        for j in range(-radius, radius + 1, 2):
            g = gain(sub_r, sub_c, i, j)
            if g < best:
                best, by, bx = g, float(i), float(j)
    best = gain(rows, cols, by, bx)
    if by != 0.0 or bx != 0.0:
        zero = gain(rows, cols, 0.0, 0.0)
        if zero <= best:
            best, by, bx = zero, 0.0, 0.0
    for step, reach in ((1.0, 2), (0.5, 1)):
        cy, cx = by, bx
        for i in range(-reach, reach + 1):
            for j in range(-reach, reach + 1):
                if i == 0 and j == 0:
                    continue
                g = gain(rows, cols, cy + i * step, cx + j * step)
                if g < best:
                    best, by, bx = g, cy + i * step, cx + j * step
    return by, bx, best


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_grid_gains_are_shift_gain_to_the_last_bit(seed):
    log0, log1, var0, var1, still, labels, rows, cols = _images(seed)
    shifts = np.arange(-20, 21, 3)  # many landings outside the field
    grid = grid_gains(log0, log1, var0, var1, still, labels, 1, rows, cols, shifts, shifts, CAP, UNKNOWN, EXCEPTION)
    for i, dy in enumerate(shifts):
        for j, dx in enumerate(shifts):
            assert grid[i, j] == shift_gain(log0, log1, var0, var1, still, labels, 1, rows, cols, float(dy),
                                            float(dx), CAP, UNKNOWN, EXCEPTION)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_shift_gains_are_shift_gain_to_the_last_bit(seed):
    log0, log1, var0, var1, still, labels, rows, cols = _images(seed)
    # half-pixel shifts, some landing outside the field, some one axis whole
    dys = np.array([2.5, -0.5, 3.0, 12.5, -7.5, 0.5, 1.0, -20.5])
    dxs = np.array([3.5, 0.0, -1.5, 14.5, 2.0, -0.5, 29.5, 1.5])
    got = shift_gains(log0, log1, var0, var1, still, labels, 1, rows, cols, dys, dxs, CAP, UNKNOWN, EXCEPTION)
    for i, (dy, dx) in enumerate(zip(dys, dxs, strict=True)):
        assert got[i] == shift_gain(log0, log1, var0, var1, still, labels, 1, rows, cols, dy, dx, CAP, UNKNOWN,
                                    EXCEPTION)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_best_shift_finds_what_the_shift_by_shift_search_finds(seed):
    log0, log1, var0, var1, still, labels, rows, cols = _images(seed)
    sub_r, sub_c = rows[::3].copy(), cols[::3].copy()
    got = best_shift(log0, log1, var0, var1, still, labels, 1, rows, cols, sub_r, sub_c, 6, CAP, UNKNOWN, EXCEPTION)
    want = _best_shift_reference(log0, log1, var0, var1, still, labels, 1, rows, cols, sub_r, sub_c, 6)
    assert got == want
    assert abs(got[0] - 2.0) <= 0.5 and abs(got[1] - 3.0) <= 0.5  # the square's motion


@pytest.mark.parametrize("seed", [0, 1])
def test_inner_depth_is_repeated_cross_erosion(seed):
    rng = np.random.default_rng(seed)
    mask = ndi.binary_opening(rng.random((17, 23)) < 0.7)
    depth = inner_depth(mask)
    assert np.array_equal(depth > 0, mask)
    for n in range(1, 5):
        eroded = ndi.binary_erosion(np.pad(mask, 1), iterations=n)[1:-1, 1:-1]
        assert np.array_equal(depth > n, eroded), n


def test_warp_costs_at_listed_flows_equal_warp_costs_of_the_field():
    log0, log1, var0, var1, _, _, rows, cols = _images(3)
    rng = np.random.default_rng(3)
    u = rng.normal(0, 3, log0.shape).astype(np.float32)
    v = rng.normal(0, 3, log0.shape).astype(np.float32)
    weight = 1.0 / (var0 + var1)
    assert np.array_equal(warp_costs_at(log0, log1, weight, rows, cols, u[rows, cols], v[rows, cols], CAP),
                          warp_costs(log0, log1, weight, rows, cols, u, v, CAP))


def test_rim_mean_is_the_5x5_mean_over_the_rim():
    rng = np.random.default_rng(4)
    mask = np.zeros((20, 26), bool)
    mask[3:15, 4:22] = True
    core = ndi.binary_erosion(mask, iterations=3)
    rim_r, rim_c = np.nonzero(mask & ~core)
    values = rng.normal(2.0, 3.0, rim_r.size)
    better = np.zeros(mask.shape)
    on_rim = np.zeros(mask.shape)
    better[rim_r, rim_c] = values
    on_rim[rim_r, rim_c] = 1.0
    mean = ndi.uniform_filter(better, 5, mode="constant") / np.maximum(
        ndi.uniform_filter(on_rim, 5, mode="constant"), 1e-9)
    for threshold in (0.0, 2.0, 4.0):
        got = rim_mean_exceeds(rim_r.astype(np.int64), rim_c.astype(np.int64), values, 20, 26, 2, threshold)
        near = np.abs(mean[rim_r, rim_c] - threshold) < 1e-9  # ties only up to rounding
        assert np.array_equal(got[~near], mean[rim_r, rim_c][~near] > threshold)


@pytest.mark.parametrize("noise_q, tolerance", [(1.0, 3.0), (100.0, 3.0), (16250.0, 2.0), (1e4, 0.5)])
def test_tabled_verdicts_are_the_tests_verdicts(noise_q, tolerance):
    """consistent_limits gives, for every (intervals, span) it tables, exactly the whole intervals
    interval_consistent accepts (checked interval by interval, up to well past the range)."""
    from viform.imaging.multi_interval import interval_consistent
    from viform.vision._flow_kernels import consistent_limits

    limits = consistent_limits(8, 160, noise_q, tolerance)
    accepted = 0
    for n in range(1, 8):
        for span in range(n, 160):
            first, last = limits[n, span]
            for interval in range(1, 4 * span // n + 8):
                verdict = interval_consistent(interval, span / n, n, noise_q, tolerance)
                assert verdict == (first <= interval <= last), (n, span, interval)
                accepted += verdict
    assert accepted > 0
