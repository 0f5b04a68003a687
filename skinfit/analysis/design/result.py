"""What :func:`skinfit.analysis.design.design` found, written to a folder and read back."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from skinfit.errors import InputError
from skinfit.io.outputs import check_outputs
from skinfit.io.units import to_si

__all__ = ["DesignResult", "user_frame", "load_design", "FILES"]


@dataclass
class DesignResult:
    """What :func:`design` found.

    ``table``: one row per candidate (covariates in the user's units); the expected
    information gain of one measurement there, nats, by nested Monte Carlo (:func:`eig_nmc`):
    ``eig`` (the value to read), ``eig_se`` (its Monte Carlo error), ``eig_bias`` (its
    estimated bias), ``eig_upper`` and ``eig_upper_se`` (an upper bound); ``eig_laplace`` (the
    Laplace approximation the plan is chosen on), ``in_plan`` (times the plan uses it).
    ``plan``: the n measurements to run, user units, in the order chosen.  ``comparison``: plan
    vs baseline (EIG of the whole batch by nested Monte Carlo with its error and estimated bias,
    Laplace EIG; with ``discriminate``, expected ln BF and P(ln BF > 3)).  ``sd``: per target
    parameter, the sd now and predicted after the plan and after the baseline, in
    the coordinate u (``log`` = sd of the natural log, i.e. a relative sd).  ``settings``: the
    estimators, draw counts, noise, seed and what was dropped.
    """

    model_id: str
    covariates: tuple
    units: dict
    table: pd.DataFrame
    plan: pd.DataFrame
    baseline: pd.DataFrame
    comparison: pd.DataFrame
    sd: pd.DataFrame
    settings: dict
    discrimination: pd.DataFrame | None = None
    plot: dict = field(default_factory=dict)

    def text(self):
        lines = [f"design for {self.model_id}: {len(self.plan)} measurements chosen from {len(self.table)} "
                 f"candidates ({self.settings['selection']})",
                 f"starting from {self.settings['start']}; targets: {', '.join(self.settings['params'])}; "
                 f"seed {self.settings['seed']}", "", "plan vs baseline:", self.comparison.to_string(), "",
                 "predicted posterior sd (coordinate: log = sd of the natural log):", self.sd.to_string(), "",
                 "plan (user units):", self.plan.to_string(index=False), "", *self._single_lines()]
        if self.discrimination is not None:
            lines += ["", "discrimination (per generating model):", self.discrimination.to_string(index=False)]
        return "\n".join(lines)

    def _single_lines(self):
        """The EIG of one measurement: which column to read, the best candidates, the bias."""
        t = self.table
        covs = [c for c in t.columns if c.endswith("]")]
        shown = [c for c in ("eig", "eig_se", "eig_bias", "eig_upper") if c in t]  # a folder of an older skinfit
        best = t.sort_values("eig", ascending=False).head(5)[covs + shown]
        lines = ["one measurement (candidates.csv): read eig +- eig_se (nats); eig_bias is its estimated Monte "
                 "Carlo bias, eig_upper an upper bound. Best candidates:", best.to_string(index=False)]
        over = self.settings.get("eig_bias_over_se", 0)
        if over:
            lines.append(f"warning: at {over} of {len(t)} candidates the estimated bias of eig exceeds its se "
                         f"(the EIG nears log of the inner draws): rerun with more inner draws (--inner)")
        return lines

    def write(self, out, *, overwrite=False):
        """plan.csv (ready to run), candidates.csv, baseline.csv, comparison.csv, sd.csv and
        design.json (settings and what :func:`load_design` needs); the figure is
        :func:`skinfit.plots.design.plot_eig`'s.  A folder holding an earlier design's files
        (:data:`FILES`) is refused unless ``overwrite``."""
        check_outputs(out, FILES, command="skinfit design", overwrite=overwrite)
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        self.plan.to_csv(out / "plan.csv", index=False)
        self.table.to_csv(out / "candidates.csv", index=False)
        self.baseline.to_csv(out / "baseline.csv", index=False)
        self.comparison.to_csv(out / "comparison.csv")
        self.sd.to_csv(out / "sd.csv")
        if self.discrimination is not None:
            self.discrimination.to_csv(out / "discrimination.csv", index=False)
        doc = {**self.settings, "_result": {"model_id": self.model_id, "covariates": list(self.covariates),
                                            "units": self.units, "plot": self.plot}}
        (out / "design.json").write_text(json.dumps(doc, indent=2, default=str))
        return out


def user_frame(X, units, idx, covariates):
    return pd.DataFrame({f"{c} [{units[c]}]": np.asarray(X[c])[idx] / to_si(units[c])
                         for c in covariates if c in units})


def load_design(out):
    """The :class:`DesignResult` that :meth:`DesignResult.write` wrote into folder ``out``."""
    out = Path(out)
    try:
        doc = json.loads((out / "design.json").read_text())
        meta = doc.pop("_result")
        tables = {name: pd.read_csv(out / f"{name}.csv") for name in ("plan", "candidates", "baseline")}
        comparison = pd.read_csv(out / "comparison.csv", index_col=0)
        sd = pd.read_csv(out / "sd.csv", index_col=0)
    except (OSError, KeyError, ValueError) as exc:
        raise InputError(out, f"not a folder written by `skinfit design --out` ({type(exc).__name__}: {exc})") from None
    disc = pd.read_csv(out / "discrimination.csv") if (out / "discrimination.csv").is_file() else None
    return DesignResult(meta["model_id"], tuple(meta["covariates"]), meta["units"], tables["candidates"],
                        tables["plan"], tables["baseline"], comparison, sd, doc, disc, meta.get("plot") or {})


#: The files ``skinfit design --out`` writes: :meth:`DesignResult.write`'s and the EIG figure
#: (``eig.png``, :func:`skinfit.plots.design.plot_eig`).
FILES = ("plan.csv", "candidates.csv", "baseline.csv", "comparison.csv", "sd.csv", "discrimination.csv",
         "design.json", "eig.png")
