"""Pure, vectorised forward functions of the published skin-friction models.

Nothing here imports from the rest of skinfit, reads files or knows about pandas.

The contract every forward function follows (the model registry checks it)::

    y, ok = f(p, x, c)

``p``
    mapping parameter name -> float or ndarray broadcastable to ``(k, n)``; the engine passes
    arrays of shape ``(k, 1)`` (one row per parameter vector of an ensemble) or ``(k, n)``
    (a parameter split by a grouping column, already expanded to the data rows).
``x``
    mapping covariate name -> ndarray of shape ``(n,)``, SI units.  Covariates that are
    missing by design (e.g. the texture geometry of a flat reference) are NaN.
``c``
    mapping constant name -> float (fixed constants of the model card), SI units.
``y``
    dict observable name -> ndarray of shape ``(k, n)`` (always broadcast to full shape).
    ``y`` is finite everywhere, also where ``ok`` is False (filled with a harmless value).
``ok``
    bool ndarray broadcastable to ``(k, n)``: False where the parameter point lies outside
    the model's physical support at that data row.  The engine turns any False into a
    log-likelihood of ``-inf`` for that parameter vector and counts it in the diagnostics.
"""
