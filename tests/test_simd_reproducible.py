"""A seed's trajectory must not depend on the SIMD code numpy runs (AVX-512 on one machine, not on another).

numpy's ``argpartition`` picks among equal values differently with and without AVX-512, and a global search's
candidates often tie; ``mcl.filter.top_k`` takes the first of them, so the pick is the same everywhere.
"""

from __future__ import annotations

import hashlib

import numpy as np

from mcl.filter import top_k
from tests.blas import outputs_by_numpy_simd


def test_top_k_takes_the_largest_and_the_first_of_equal_values_at_the_cut():
    assert top_k(np.array([5.0, 1.0, 3.0, 3.0, 3.0, 0.0]), 3).tolist() == [0, 2, 3]
    assert top_k(np.array([-np.inf, 2.0, -np.inf, -np.inf]), 2).tolist() == [0, 1]
    rng = np.random.default_rng(3)
    for _ in range(50):
        v = rng.integers(0, 6, rng.integers(2, 400)).astype(np.float64)  # many ties at every cut
        k = int(rng.integers(1, v.size))
        want = np.sort(np.argsort(-v, kind="stable")[:k])  # the k largest, the first of equal values
        np.testing.assert_array_equal(top_k(v, k), want)


def test_top_k_picks_the_same_on_every_level_of_numpys_simd_code():
    # 200,000 candidates' log-likelihoods in 1,000 distinct values, the best 20,000 kept: on every SIMD level numpy
    # has on this CPU (AVX-512, AVX2, SSE on an AVX-512 machine; np.argpartition's picks differ on all three) the
    # indices a stable sort gives
    code = ("import hashlib, numpy as np; from mcl.filter import top_k; "
            "v = np.random.default_rng(0).integers(0, 1000, 200_000).astype(np.float64); "
            "print(hashlib.md5(top_k(v, 20_000).tobytes()).hexdigest())")
    v = np.random.default_rng(0).integers(0, 1000, 200_000).astype(np.float64)
    want = hashlib.md5(np.sort(np.argsort(-v, kind="stable")[:20_000]).tobytes()).hexdigest()
    assert outputs_by_numpy_simd(code) == {want + "\n"}
