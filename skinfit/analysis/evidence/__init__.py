"""The log marginal likelihood (log evidence) of a fit, and its estimators.

Every estimator takes a *normalised* log target: log likelihood with all its constants plus a
proper, normalised log prior (and the Jacobian of any change of coordinates), so that the
returned ``log Z`` is comparable between models on the same data.

- :func:`bridge_sampling` (``bridge``) -- Meng & Wong (1996) iterative bridge sampling with a
  multivariate normal proposal fitted on half of the posterior draws; relative mean-squared
  error of Fruehwirth-Schnatter (2004) as used by Gronau et al. (2017), with the posterior
  half's autocorrelation accounted for through its effective sample size.
- :func:`laplace` (``laplace``) -- Laplace's approximation at the mode with a central-difference
  Hessian, its Gaussian integrated over the prior bounds (exact for a Gaussian posterior,
  truncated or not; flagged as approximate, and checked against posterior draws when given).
- :func:`nested` (``nested``) -- dynesty's nested sampling (optional dependency) as an
  independent check.

Never the naive harmonic mean, whose variance can be infinite (Newton & Raftery 1994).

:func:`evidence` (``estimate``) applies them to a fit; each returns a :class:`LogEvidence`.
"""

from skinfit.analysis.evidence.bridge import bridge_sampling
from skinfit.analysis.evidence.estimate import METHODS, evidence, posterior_draws
from skinfit.analysis.evidence.laplace import LaplaceError, laplace
from skinfit.analysis.evidence.log_evidence import LogEvidence, bayes_factor_strength
from skinfit.analysis.evidence.nested import nested

__all__ = ["evidence", "posterior_draws", "METHODS", "LogEvidence", "LaplaceError", "bridge_sampling", "laplace",
           "nested", "bayes_factor_strength"]
