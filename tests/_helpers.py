"""Helpers that several test modules share (the fixtures are in conftest.py)."""

import threading

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
from scipy.optimize import approx_fprime


def share_between_threads(make_map, room, read, n_readers=3):
    """Insert 20 noisy copies of the scan `room` (points, origin) into one map from a
    thread while `n_readers` others call ``read(map, points)`` 50 times each; return
    that map, one built from the same scans in a single thread, and the exceptions
    the readers raised."""
    points, origin = room
    rng = np.random.default_rng(4)
    scans = [(points + rng.normal(0, 0.02, points.shape), origin) for _ in range(20)]
    shared, errors = make_map(), []

    def write():
        for p, o in scans:
            shared.insert_scan(p, o)

    def reader():
        try:
            for _ in range(50):
                read(shared, points)
        except Exception as exc:   # pragma: no cover - reported by the caller
            errors.append(exc)

    threads = [threading.Thread(target=write)]
    threads += [threading.Thread(target=reader) for _ in range(n_readers)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    sequential = make_map()
    for p, o in scans:
        sequential.insert_scan(p, o)
    return shared, sequential, errors


def random_scans(rng, n_scans=3, n_points=60, spread=2.0, *, origins=0.5, near=0.2):
    """`n_scans` scans of `n_points` random rays each, from origins drawn uniformly in
    ``[-origins, origins]^3``, of lengths uniform in ``[near, spread]``."""
    scans = []
    for _ in range(n_scans):
        origin = rng.uniform(-origins, origins, 3)
        direction = rng.normal(size=(n_points, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        points = origin + direction * rng.uniform(near, spread, (n_points, 1))
        scans.append((points, origin))
    return scans


def assert_prediction_shapes(model, X):
    """A fitted occgp.gp model's ``predict`` (with and without `return_var`) and
    ``predict_proba`` at `X`: one value per row, the same mean both ways,
    probabilities in [0, 1], and an empty answer to an empty query. Returns the
    variance."""
    mean = model.predict(X)
    mean2, var = model.predict(X, return_var=True)
    proba = model.predict_proba(X)
    assert mean.shape == var.shape == proba.shape == (len(X),)
    assert_array_equal(mean, mean2)
    assert ((proba >= 0) & (proba <= 1)).all()
    assert model.predict(np.empty((0, X.shape[1]))).shape == (0,)
    return var


def assert_gradient_matches(objective, theta, *args):
    """`objective(theta, *args)` returns (value, gradient): the gradient has theta's
    shape and matches finite differences of the value. Returns the value."""
    value, grad = objective(theta, *args)
    assert grad.shape == theta.shape
    assert_allclose(grad, approx_fprime(theta, lambda t: objective(t, *args)[0], 1e-7),
                    rtol=1e-4, atol=1e-5)
    return value
