"""Which measurement next: Bayesian experimental design over a model's covariates.

Ranks candidate measurement conditions (loads, voltages, ...) by the expected information gain
(EIG) about chosen parameters, proposes a batch of ``n`` measurements, compares it with a
baseline design, and (``discriminate``) finds the batch that best separates competing models.

Estimators (every random draw from the one ``rng``):

* One candidate at a time: nested Monte Carlo (Ryan 2003, "Estimating expected information
  gains for experimental designs with application to the random fatigue-limit model";
  Rainforth et al. 2018, "On nesting Monte Carlo estimators"), vectorised over candidates and
  inner draws (:func:`eig_nmc`).  The outer draws, their simulated observations and the ``M``
  inner draws are shared by every candidate (common random numbers: differences between
  candidates are estimated much better than the values).  ``eig`` is the value to read: the
  outer draw counted among the inner ones (Foster et al. 2019), biased low by O(1/M), most
  where the EIG nears log M; ``eig_bias`` estimates that bias (M/2 inner draws against M) and
  ``eig_se`` includes the shared inner draws' variance (a jackknife over blocks of them).
  For a subset of parameters the nuisance parameters are drawn *given* the outer draw's
  targets: for the priors (independent) a swap, for a Gaussian the regression on the targets,
  for a fit's posterior that regression as a proposal weighted by the fit's own density.
* Batches: greedy selection on the Laplace / Fisher-information approximation
  EIG ~ E_theta[0.5 log det Sigma0_psi - 0.5 log det Sigma_post_psi(theta)], Sigma_post^-1 =
  Sigma0^-1 + sum of the points' Fisher information (a Bayesian D_s-optimal criterion, Chaloner
  & Verdinelli 1995, "Bayesian experimental design: a review"), with the current distribution
  approximated by a Gaussian in the coordinate u (log of parameters with a positive lower
  bound, else natural).  It is approximate for non-linear models and exact for a linear-Gaussian
  one.  The EIG of the whole batch is then estimated jointly by nested Monte Carlo with
  Laplace-based importance sampling of the inner draws (Beck et al. 2018, "Fast Bayesian
  experimental design: Laplace-based importance sampling for the expected information gain"),
  which stays accurate where plain inner sampling from the prior saturates; from a fit, whose
  density is known only up to a constant and whose posterior may be far from its Gaussian
  approximation, by :func:`eig_nmc` over the fit's own draws instead.
* Discrimination: greedy on the expected log Bayes factor of the generating model against its
  best competitor (capped at +-6 nats), each model's marginal likelihood of the simulated batch
  by nested Monte Carlo over its own prior (or fit) draws at the fixed noise sd; these are
  biased low once a batch determines the parameters, so they only rank candidates.  The
  plan's and the baseline's median ln BF and P(ln BF > 3) come from Laplace evidences of every
  model for each simulated batch, the noise sd integrated over its prior (a misfitting model
  inflates its noise, as a fit does).  bench/bench_design.py checks them against full fits.

The noise model of each observable is the model card's (or the fit's); its scale is fixed at
the fit's posterior median, else the prior's median, unless ``noise_scale`` is given.
Parameters whose prediction leaves the model's physical support at a candidate are dropped from
the draws (the support is part of the model; how many is reported).

Modules: ``problem`` (the draws, mean function and noise every estimator shares), ``nested``
(one candidate at a time), ``laplace`` (the greedy plan and the batch EIG), ``discrimination``,
``candidates`` (the candidates file), ``model_problem`` (a model's priors or a fit's posterior
as a problem), ``checks`` (arguments and cost, before any work), ``result`` and ``plan``
(:func:`design`).
"""

from skinfit.analysis.design.candidates import read_candidates
from skinfit.analysis.design.discrimination import discrimination_plan
from skinfit.analysis.design.laplace import batch_eig, greedy_plan, laplace_design, laplace_gains
from skinfit.analysis.design.nested import eig_nmc
from skinfit.analysis.design.plan import design
from skinfit.analysis.design.problem import DesignProblem, gaussian_problem
from skinfit.analysis.design.result import FILES, DesignResult, load_design

__all__ = ["DesignProblem", "DesignResult", "design", "gaussian_problem", "read_candidates", "eig_nmc", "laplace_gains",
           "laplace_design", "greedy_plan", "batch_eig", "discrimination_plan", "load_design", "FILES"]
