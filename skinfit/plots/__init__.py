"""Figures for papers, drawn from saved results only (a :class:`~skinfit.Fit` or its DataTree).

One figure per module. Posterior-predictive plots in each model's natural axes
(:func:`plot_ppc`; its numbers from :func:`ppc_bands`, its layout from the card's ``[plot]``
table, :func:`plot_spec`). Inference plots: :func:`plot_pair` (corner), :func:`plot_trace`
(walker traces with rank histograms), :func:`plot_rank` (ArviZ), :func:`plot_prior_posterior`
(what the data determined). Across fits: :func:`plot_forest` (a parameter across subjects and
conditions, with the population distribution when given), :func:`plot_comparison`
(evidence / LOO chart) and :func:`plot_contrast_matrix` (pairwise contrasts of many subjects).

Every plot function returns a :class:`matplotlib.figure.Figure` and writes it to ``path`` when
one is given. Figures are made without pyplot (nothing is ever shown); where ArviZ is used, the
Agg backend is selected unless the user already chose one (``MPLBACKEND`` or an explicit
``matplotlib.use``). :mod:`skinfit.plots.style` holds what every figure shares (palette,
sizes, saving).
"""

from skinfit.plots.comparison import plot_comparison
from skinfit.plots.contrast_matrix import plot_contrast_matrix
from skinfit.plots.forest import plot_forest
from skinfit.plots.pair import plot_pair
from skinfit.plots.ppc import plot_ppc
from skinfit.plots.predictive import plot_spec, ppc_bands
from skinfit.plots.prior_posterior import plot_prior_posterior
from skinfit.plots.rank import plot_rank
from skinfit.plots.reading import axis_label, parameter_units
from skinfit.plots.style import DPI, MAX_WIDTH, MIN_FONT, save_figure, write_figure_files
from skinfit.plots.trace import plot_trace

__all__ = ["plot_ppc", "ppc_bands", "plot_spec", "plot_pair", "plot_trace", "plot_rank",
           "plot_prior_posterior", "plot_forest", "plot_comparison", "plot_contrast_matrix", "parameter_units",
           "axis_label",
           "DPI", "MAX_WIDTH", "MIN_FONT", "save_figure", "write_figure_files"]
