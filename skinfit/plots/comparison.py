"""The model comparison chart: log-evidence and LOO ELPD relative to the best (:func:`plot_comparison`)."""

import numpy as np
import pandas as pd

from skinfit.errors import InputError
from skinfit.plots.style import COLOURS, finish_figure, new_figure, suptitle

__all__ = ["plot_comparison"]


_EVIDENCE = ("log_Z", "logZ", "log_z", "log_evidence", "lnZ", "ln_Z")
_EVIDENCE_ERR = ("log_Z_err", "log_Z_se", "logZ_err", "log_Z_error", "se_log_Z", "log_Z_sd", "log_evidence_err",
                 "lnZ_err")
_LOO = ("elpd_loo", "elpd")
_LOO_ERR = ("elpd_loo_se", "elpd_se", "se")


def _pick(table, names):
    lower = {str(c).lower(): c for c in table.columns}
    return next((lower[n.lower()] for n in names if n.lower() in lower), None)


def plot_comparison(table, path=None, *, title=None):
    """Model comparison chart: log-evidence and/or LOO ELPD of each model relative to the best.

    ``table`` is any DataFrame with one row per model (index or a ``model`` column) and
    columns such as ``log_Z`` (+ ``log_Z_err``) and ``elpd_loo`` (+ ``se``); without them,
    its first numeric column is drawn as is.
    """
    table = table.copy()
    if "model" in table.columns:
        table = table.set_index("model")
    metrics = []
    for names, errs, text in ((_EVIDENCE, _EVIDENCE_ERR, "log evidence, log Z − best"),
                              (_LOO, _LOO_ERR, "ELPD (LOO) − best")):
        col = _pick(table, names)
        if col is not None:
            metrics.append((col, _pick(table, errs), f"{text} [nats]", True))
    if not metrics:
        numeric = [c for c in table.columns if pd.api.types.is_numeric_dtype(table[c])]
        if not numeric:
            raise InputError("plot_comparison", "the comparison table has no numeric column to draw")
        metrics.append((numeric[0], None, str(numeric[0]), False))
    fig = new_figure(4.2 * len(metrics) + 1.5, 0.38 * len(table) + 1.6)
    axes = fig.subplots(1, len(metrics), squeeze=False, sharey=True)[0]
    y = np.arange(len(table))[::-1]
    for ax, (col, err, label, relative) in zip(axes, metrics):
        v = table[col].to_numpy(dtype=float)
        shown = v - np.nanmax(v) if relative else v
        e = table[err].to_numpy(dtype=float) if err is not None else None
        ax.errorbar(shown, y, xerr=e, fmt="o", color=COLOURS[0], ecolor=COLOURS[0], capsize=3, ms=5)
        if relative:
            ax.axvline(0, color="black", lw=0.7)
        ax.set_xlabel(label)
        ax.grid(axis="x", alpha=0.3, lw=0.5)
    axes[0].set_yticks(y, [str(i) for i in table.index], fontsize=9)
    suptitle(fig, title or "model comparison (higher is better; bars: ± 1 standard error)")
    return finish_figure(fig, path)
