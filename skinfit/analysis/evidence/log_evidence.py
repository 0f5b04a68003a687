"""A log evidence estimate (:class:`LogEvidence`) and the words for a Bayes factor."""

import math
from dataclasses import dataclass, field

__all__ = ["LogEvidence", "bayes_factor_strength"]


@dataclass(frozen=True)
class LogEvidence:
    """A log marginal likelihood estimate.

    Attributes
    ----------
    log_z : float
        Natural log of the evidence.
    se : float
        Its standard error (NaN for Laplace, whose error is not estimable from one expansion).
    method : str
        ``"bridge"``, ``"laplace"`` or ``"nested"``.
    n_evals : int
        Log-target (or log-likelihood) evaluations spent on the estimate.
    seconds : float
        Wall time.
    approximate : bool
        True when the estimate carries an unquantified approximation error (Laplace).
    repeats : tuple of float
        Individual estimates when the estimate was repeated.
    caveat : str
        What limits an approximate estimate, in words (Laplace: bounds that cut its Gaussian,
        and the bracket on log Z from the posterior draws); empty when there is none.
    details : dict
        Method-specific figures (iterations, proposal, relative MSE, ...).
    """

    log_z: float
    se: float
    method: str
    n_evals: int
    seconds: float
    approximate: bool = False
    repeats: tuple = ()
    caveat: str = ""
    details: dict = field(default_factory=dict, compare=False)

    def __str__(self):
        se = "n/a" if math.isnan(self.se) else f"{self.se:.3f}"
        tag = ", approximate" if self.approximate else ""
        text = f"log Z = {self.log_z:.3f} +- {se} ({self.method}{tag}, {self.n_evals} evaluations)"
        return f"{text}; {self.caveat}" if self.caveat else text


def bayes_factor_strength(log_bf):
    """Kass & Raftery (1995) words for a Bayes factor given as ``ln BF`` (>= 0 favours the first).

    On 2 ln BF: 0-2 "not worth more than a bare mention", 2-6 "positive", 6-10 "strong",
    > 10 "very strong".
    """
    two = 2.0 * abs(float(log_bf))
    if two < 2:
        return "not worth more than a bare mention"
    if two < 6:
        return "positive"
    if two < 10:
        return "strong"
    return "very strong"
