"""Tests of the shared xoshiro128** generator (numpy twin of cdam::Rng)."""
import math

import numpy as np
import pytest
from scipy import stats

from cdam_core.reference import Rng


def test_first_outputs_from_state_1_2_3_4_by_hand():
    # out1 = rotl(2*5, 7)*9 = 1280*9 = 11520; state -> (7, 0, 1026, 12288)
    #   (s2=3^1=2, s3=4^2=6, s1=2^2=0, s0=1^6=7, s2=2^(2<<9)=1026, s3=rotl(6,11)=12288)
    # out2 = rotl(0*5, 7)*9 = 0; state -> (12295, 1029, 1029, 25165824)
    #   (s2=1026^7=1029, s3=12288^0, s1=0^1029=1029, s0=7^12288=12295, s3=12288<<11)
    # out3 = rotl(1029*5, 7)*9 = 5145*128*9 = 5927040
    r = Rng.from_state(1, 2, 3, 4)
    assert r.next_u32() == 11520
    assert r.state == (7, 0, 1026, 12288)
    assert r.next_u32() == 0
    assert r.state == (12295, 1029, 1029, 25165824)
    assert r.next_u32() == 5927040


def numpy_uint32_seed(seed):
    """The DESIGN.md seeding written with numpy's wrapping uint32 arithmetic."""
    with np.errstate(over="ignore"):
        x = np.uint32(seed)
        out = []
        for _ in range(4):
            x = np.uint32(x + np.uint32(0x9E3779B9))
            z = x
            z = np.uint32((z ^ (z >> np.uint32(16))) * np.uint32(0x85EBCA6B))
            z = np.uint32((z ^ (z >> np.uint32(13))) * np.uint32(0xC2B2AE35))
            z = np.uint32(z ^ (z >> np.uint32(16)))
            out.append(int(z))
    return tuple(out)


@pytest.mark.parametrize("seed", [0, 1, 42, 2**31, 2**32 - 1])
def test_seeding_matches_wrapping_uint32_arithmetic(seed):
    assert Rng(seed).state == numpy_uint32_seed(seed)


def test_same_seed_same_stream_and_seeds_differ():
    a, b, c = Rng(7), Rng(7), Rng(8)
    sa = [a.next_u32() for _ in range(50)]
    assert sa == [b.next_u32() for _ in range(50)]
    assert sa != [c.next_u32() for _ in range(50)]
    assert all(0 <= v < 2**32 for v in sa)


def test_uniform_is_24_bit_in_unit_interval_and_uniform():
    r = Rng(1)
    u = r.uniform_array(20000)
    assert u.dtype == np.float64 and u.shape == (20000,)
    assert u.min() >= 0.0 and u.max() < 1.0
    np.testing.assert_array_equal(u * 2**24, np.floor(u * 2**24))
    assert stats.kstest(u, "uniform").pvalue > 1e-3


def test_uniform_draw_order_and_scaling():
    a, b = Rng(3), Rng(3)
    raw = [a.next_u32() for _ in range(5)]
    got = [b.uniform(-2.0, 6.0) for _ in range(5)]
    assert got == [-2.0 + 8.0 * ((x >> 8) * 2.0**-24) for x in raw]
    c, d = Rng(3), Rng(3)
    np.testing.assert_array_equal(c.uniform_array(7, 1.0, 3.0),
                                  [d.uniform(1.0, 3.0) for _ in range(7)])


def test_index_in_range_and_formula():
    a, b = Rng(5), Rng(5)
    for n in (1, 2, 7, 1000, 2**32 - 1):
        raw = a.next_u32()
        k = b.index(n)
        assert 0 <= k < n and k == (raw * n) // 2**32
    r = Rng(9)
    counts = np.bincount([r.index(6) for _ in range(6000)], minlength=6)
    assert counts.size == 6 and stats.chisquare(counts).pvalue > 1e-3


def test_normal_uses_two_draws_and_is_standard_normal():
    a, b = Rng(11), Rng(11)
    u1, u2 = a.uniform(), a.uniform()
    assert b.normal() == math.sqrt(-2 * math.log(1 - u1)) * math.cos(2 * math.pi * u2)
    assert a.next_u32() == b.next_u32()
    r = Rng(12)
    z = np.array([r.normal() for _ in range(20000)])
    assert np.all(np.isfinite(z))
    assert stats.kstest(z, "norm").pvalue > 1e-3


@pytest.mark.parametrize("call, match", [
    (lambda: Rng(-1), "seed: must be >= 0"),
    (lambda: Rng(2**32), "seed: must be <= 4294967295"),
    (lambda: Rng(1.5), "seed: must be an integer"),
    (lambda: Rng.from_state(0, 0, 0, 0), "s0: the state must not be all zero"),
    (lambda: Rng(1).index(0), "n: must be >= 1"),
    (lambda: Rng(1).uniform(float("nan"), 1.0), "a: must be finite"),
    (lambda: Rng(1).uniform_array(-1), "n: must be >= 0"),
])
def test_bad_input(call, match):
    with pytest.raises(ValueError, match=match):
        call()
