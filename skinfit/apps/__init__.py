"""Front ends: the command line, campaigns (processes or Dask) and the demo."""
