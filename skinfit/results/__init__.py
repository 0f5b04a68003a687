"""The one results container: :class:`~skinfit.results.fit.Fit` (an ArviZ DataTree
with provenance attributes), its summary, saving and loading."""
