"""Raw recordings -> per-stroke datasets (``skinfit ingest``).

A rig file (:mod:`~skinfit.io.recordings.rig`) states how a lab's raw recordings become one row
per stroke: the file format and channels, their units, gains or calibration matrix and bias
windows, the zero-phase filters, the stroke detection and the trial rejection rule.  The
recording is read by chunks (:mod:`~skinfit.io.recordings.read`), calibrated and filtered
(:mod:`~skinfit.io.recordings.signal`), cut into strokes and reduced to means with
autocorrelation-corrected standard errors (:mod:`~skinfit.io.recordings.strokes`); the dataset
folder with its card is written by :mod:`~skinfit.io.recordings.ingest`.
"""
