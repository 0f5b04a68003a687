"""A linear-Gaussian model for tests that need a posterior known in closed form: the forward
function of a card the tests write (``forward = "linear_gaussian:plane"``, registered by them)
and the conjugate posterior of its three coefficients."""

import numpy as np

FORWARD = "linear_gaussian:plane"
PRIOR_SD = 1.0  # normal(0, PRIOR_SD) priors on a, b, c

CARD = f'''schema_version = 1
id = "plane_test"
title = "A plane, y = a + b x1 + c x2 (test model with a Gaussian posterior)"
source = "electroadhesion_friction"
forward = "{FORWARD}"
[[observables]]
name = "y"
unit = "1"
noise = "normal"
[[covariates]]
name = "x1"
unit = "V"
[[covariates]]
name = "x2"
unit = "1"
[[parameters]]
name = "a"
unit = "1"
[[parameters]]
name = "b"
unit = "1/V"
[[parameters]]
name = "c"
unit = "1"
'''

PRIORS = f'''schema_version = 1
model = "plane_test"
[a]
dist = "normal"
loc = 0.0
scale = {PRIOR_SD}
bounds = [-inf, inf]
source = "electroadhesion_friction"
[b]
dist = "normal"
loc = 0.0
scale = {PRIOR_SD}
bounds = [-inf, inf]
source = "electroadhesion_friction"
[c]
dist = "normal"
loc = 0.0
scale = {PRIOR_SD}
bounds = [-inf, inf]
source = "electroadhesion_friction"
[sigma]
dist = "lognormal"
median = 0.2
sigma = 0.01
bounds = [0.1, 0.4]
source = "electroadhesion_friction"
'''


def plane(p, x, c):
    """y = a + b x1 + c x2: ``p`` a, b, c (k, 1); ``x`` x1, x2 (n,); returns ({"y": (k, n)}, ok)."""
    y = p["a"] + p["b"] * x["x1"] + p["c"] * x["x2"]
    y = np.broadcast_to(y, np.broadcast_shapes(np.shape(y), (1, len(x["x1"]))))
    return {"y": y}, np.ones(y.shape, dtype=bool)


def rows(x1, x2):
    """Design matrix (n, 3) of the plane."""
    return np.column_stack([np.ones(len(x1)), x1, x2])


def posterior_cov(x1, x2, sigma):
    """Posterior covariance of (a, b, c) after data at (x1, x2) with noise sd ``sigma``."""
    X = rows(np.asarray(x1, float), np.asarray(x2, float))
    return np.linalg.inv(np.eye(3) / PRIOR_SD**2 + X.T @ X / sigma**2)


def subset_gain(S, X, sigma, focus):
    """Closed-form expected information gain (nats) about the coefficients ``focus`` of the
    measurements at design rows ``X`` (k, 3), noise sd ``sigma``, from the posterior covariance
    ``S`` (3, 3): 0.5 log det S_ff / det S'_ff with S' = (S^-1 + X^T X / sigma^2)^-1."""
    f = np.ix_(focus, focus)
    after = np.linalg.inv(np.linalg.inv(S) + X.T @ X / sigma**2)
    return 0.5 * (np.linalg.slogdet(S[f])[1] - np.linalg.slogdet(after[f])[1])
