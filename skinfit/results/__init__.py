"""The one results container: :class:`~skinfit.results.fit.Fit` (an ArviZ DataTree with
provenance attributes) made by :func:`~skinfit.results.fitting.fit`, its tree
(:mod:`~skinfit.results.tree`), summary (:mod:`~skinfit.results.summary`), saving and loading
(:mod:`~skinfit.results.store`)."""
