"""Read-only inputs (a `Features` array, a 2 x 2 R broadcast to one measurement) reach the
association's kernels as writable arrays: one numba signature per kernel, where a read-only
array was another (about 6 s of CPU to compile in each process that met one), and the same
results."""

from __future__ import annotations

import dataclasses

import numpy as np
from numba import types

from association import inputs
from association.inputs import prepare


def _scene(rng, m, n):
    z = np.column_stack([rng.uniform(1, 20, m), rng.uniform(-1.5, 1.5, m)])
    z_hat = z[rng.integers(0, m, n)] + rng.normal(0, 0.2, (n, 2))
    R = np.tile(np.diag([0.04, 1e-3]), (m, 1, 1))
    d = 3 + 2 * n
    B = rng.normal(size=(d, d)) * 0.05
    P = B @ B.T + 1e-3 * np.eye(d)
    H = np.zeros((n, 2, d))
    H[:, :, :3] = rng.normal(size=(n, 2, 3))
    for j in range(n):
        H[j, :, 3 + 2 * j : 5 + 2 * j] = rng.normal(size=(2, 2))
    return z, R, z_hat, H, P


def _read_only(a: np.ndarray) -> np.ndarray:
    a = a.copy()
    a.setflags(write=False)
    return a


def _arrays(kernel):
    return [t for sig in kernel.signatures for t in sig if isinstance(t, types.Array)]


def test_read_only_inputs_give_the_same_results_through_the_writable_signature():
    rng = np.random.default_rng(4)
    for m, n, validate in ((5, 7, True), (1, 3, False), (4, 70, True)):
        z, R, z_hat, H, P = _scene(rng, m, n)
        want = prepare(z, R, z_hat, H, P, 0.99, validate=validate)
        for R_in in (_read_only(R), np.broadcast_to(R[0], (m, 2, 2)) if m == 1 else None):
            if R_in is None:
                continue
            got = prepare(_read_only(z), R_in, _read_only(z_hat), H, P, 0.99, validate=validate)
            for f in dataclasses.fields(want):
                a, b = getattr(want, f.name), getattr(got, f.name)
                assert np.array_equal(a, b), f.name
    for kernel in (inputs._trusted_kernel, inputs._gated_pairs, inputs._rank_kernel):
        assert _arrays(kernel) and all(t.mutable for t in _arrays(kernel)), kernel
