"""The forward contract, checked where a model first meets data.

A card's forward function is called as ``forward(p, x, c)``: ``p`` maps each parameter to a
(k, 1) array (or (k, n) for a parameter split by a column), ``x`` each covariate to an (n,) SI
array, ``c`` the constants.  It returns ``(y, ok)``: ``y`` a mapping observable -> real array
broadcastable to (k, n), ``ok`` a bool array broadcastable to (k, n), False where the model is
undefined (:data:`skinfit.io.registry.ROLES`).  Row ``i`` of every output depends on draw ``i``
alone (vectorised over parameter draws).

:func:`check_forward` calls the function on a few prior draws at the data's covariates before
a MAP search or sampling starts (:class:`skinfit.posterior.Posterior` does), so that a forward
function that raises, returns the wrong type or shape, NaN or inf where it marks the model
valid, or mixes the draws of a batch is a one-line :class:`~skinfit.errors.ForwardError` naming
the card and the function, not a traceback from inside numpy or a silently wrong fit.
"""

from collections.abc import Mapping

import numpy as np

from skinfit.errors import ForwardError
from skinfit.io.arguments import shown

__all__ = ["check_forward", "check_quantiles", "validated", "forward_error", "undefined_hint", "CHECK_DRAWS"]

#: Prior draws the forward function is checked on (then each again alone: CHECK_DRAWS + 1 calls).
CHECK_DRAWS = 3


def check_quantiles(d, k=CHECK_DRAWS):
    """(k, d) prior quantiles in [0.1, 0.9], no random draw (a fit's random stream is untouched):
    draw 0 the medians, draw i > 0 a Kronecker sequence so that every parameter differs between
    draws (a function that mixes up draws then changes its rows)."""
    steps = ((np.arange(d) + 1) * 0.6180339887498949) % 1.0
    return 0.1 + 0.8 * ((0.5 + np.arange(k)[:, None] * steps[None, :]) % 1.0)


def forward_error(model, what):
    """ForwardError naming the card, its ``forward`` (or ``function``) key and the function."""
    field = "function" if getattr(model, "user_function", False) else "forward"
    return ForwardError(model.path or f"model {model.id}", f"{model.forward_ref}: {what}", field=field)


def undefined_hint(model):
    """How to mend a NaN or inf a forward function returns where it says the model is valid."""
    if getattr(model, "user_function", False):  # f(p, x) has no ok: the priors must avoid where it is undefined
        return "narrow the priors to where the model is defined, or fix the function"
    return "return ok False where the model is undefined, or fix the function"


def _call(model, params, x, constants, when):
    forward = model.forward  # not finding the function (InputError) is said as it is, not as the function's error
    try:
        return forward(params, x, constants)
    except ForwardError:  # said by the function's adapter (skinfit.io.user_functions), in one line already
        raise
    except Exception as exc:  # any exception of a plug-in's code is its bug, named here in one line
        raise forward_error(model, f"raised {type(exc).__name__}: {str(exc)[:200]} ({when})") from exc


def validated(model, out, k, n, observables, when="called on a batch of parameter draws"):
    """``(y, ok)`` as returned by the forward function, checked against the contract: (dict
    observable -> new float (k, n) array, bool (k, n) array); ForwardError naming what differs."""
    if not (isinstance(out, tuple) and len(out) == 2):
        raise forward_error(model, f"returned {shown(out)}; expected a tuple (y, ok) ({when})")
    y, ok = out
    if not isinstance(y, Mapping):
        raise forward_error(model, f"returned y = {shown(y)}; expected a dict observable -> (k, n) array ({when})")
    missing = [o for o in observables if o not in y]
    if missing:
        raise forward_error(model, f"returned no {', '.join(map(repr, missing))} (keys: "
                                   f"{', '.join(map(repr, y)) or 'none'}); expected every observable of the card "
                                   f"({when})")
    out_y = {}
    for o in observables:
        arr = y[o]
        if not isinstance(arr, (np.ndarray, np.generic)):
            raise forward_error(model, f"returned {o!r} as {shown(arr, 40)}; expected a numpy array of real numbers "
                                       f"({when})")
        if arr.dtype.kind not in "iuf":
            raise forward_error(model, f"returned {o!r} of dtype {arr.dtype} ({shown(y[o], 40)}); expected real "
                                       f"numbers ({when})")
        out_y[o] = _broadcast(model, arr, k, n, f"{o!r}", when).astype(float)  # a copy: not a cache's buffer
    ok_arr = np.asarray(ok) if ok is not None else np.asarray(None, dtype=object)
    if ok_arr.dtype != bool:
        raise forward_error(model, f"returned ok = {shown(ok, 40)} of dtype {ok_arr.dtype}; expected a bool array, "
                                   f"True where the model is defined ({when})")
    return out_y, _broadcast(model, ok_arr, k, n, "ok", when)


def _broadcast(model, arr, k, n, what, when):
    try:
        return np.broadcast_to(arr, (k, n))
    except ValueError:
        raise forward_error(model, f"returned {what} of shape {arr.shape}; expected ({k}, {n}) = (parameter draws, "
                                   f"data rows), or a shape that broadcasts to it ({when})") from None


def _point(point):
    return "{" + ", ".join(f"{name}={float(v):.6g}" for name, v in point.items()) + "}"


def check_forward(model, params, x, constants, observables, *, rows, points):
    """Call ``model``'s forward function on ``k`` parameter draws at once and on each alone,
    and check the contract (module docstring); ForwardError at the first breach.

    ``params``: mapping parameter -> (k, 1) or (k, n) array; ``x``: mapping covariate -> (n,);
    ``rows``: (n,) 1-based data row of each column (named in messages); ``points``: k dicts
    name -> value describing each draw in messages.
    """
    k, n = len(points), len(rows)
    when = f"called on {k} prior draws at the data's {n} distinct rows"
    y, ok = validated(model, _call(model, params, x, constants, when), k, n, observables, when)
    for o in observables:
        bad = ok & ~np.isfinite(y[o])
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise forward_error(model, f"returned {y[o][i, j]} for {o!r} at data row {rows[j]} with parameters "
                                       f"{_point(points[i])}, a point it marks valid (ok True): "
                                       f"{undefined_hint(model)}")
    for i in range(k):
        alone = {p: v[i:i + 1] for p, v in params.items()}
        when = f"called on prior draw {i + 1} alone"
        y1, ok1 = validated(model, _call(model, alone, x, constants, when), 1, n, observables, when)
        same = np.array_equal(ok1[0], ok[i])
        for o in observables:
            a, b = y1[o][0], y[o][i]
            scale = np.nanmax(np.abs(np.where(np.isfinite(a), a, np.nan)), initial=0.0)
            same = same and np.allclose(a, b, rtol=1e-7, atol=1e-12 * scale, equal_nan=True)
        if not same:
            raise forward_error(model, f"is not vectorised over parameter draws: its row {i + 1} of {k} draws "
                                       f"evaluated together differs from draw {i + 1} evaluated alone "
                                       f"({_point(points[i])}); row i of every output must depend on draw i only "
                                       "(parameters come as (k, 1) arrays)")
