"""The result of :func:`skinfit.analysis.population.population.population`: the hyper-posterior
and the shrunk subject posteriors, their summaries and questions, saved and read back."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import arviz_base
import arviz_stats
import numpy as np
import pandas as pd
import xarray as xr

from skinfit.analysis.population.checks import check_prob
from skinfit.analysis.population.hierarchical import NU_T
from skinfit.errors import InputError
from skinfit.inference.checkpoint import replace_atomic
from skinfit.io import integrity
from skinfit.io.arguments import as_generator
from skinfit.results.intervals import CI_PROB, hdi

__all__ = ["PopulationWarning", "DERIVED", "WEAK_DATA", "PopulationResult", "load_population"]


class PopulationWarning(UserWarning):
    """A population result that cannot be trusted as it stands (not converged, subjects whose
    data barely move their prior, a proposal that rarely moves)."""


#: The population quantities :meth:`PopulationResult.summary` computes from mu and tau (natural
#: units): the R-hat and ESS that describe them are those of mu and tau, on their own rows.
DERIVED = ("mean", "sd", "median")


#: the words of the note that a subject's data barely move a parameter's prior (information,
#: not a problem of the result: :attr:`PopulationResult.problems`)
WEAK_DATA = "barely move the prior"


@dataclass
class PopulationResult:
    """Hyper-posterior and shrunk subject posteriors.

    Draw arrays are (chain, draw, ...): ``mu``, ``sd`` (p,) in each parameter's population
    coordinate (``coordinates``: ``log`` or ``natural``); ``corr`` (p, p) or None; ``shrunk``
    (S, p) natural units.  ``separate``: {subject: (n, p) natural-unit draws of its own fit}.
    """

    model_id: str
    parameters: list
    families: list
    subjects: list
    mu: np.ndarray
    sd: np.ndarray
    corr: np.ndarray | None
    shrunk: np.ndarray
    separate: dict
    hyperpriors: dict
    sampler: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    contraction: dict = field(default_factory=dict)
    #: {subject label: :func:`subject_digest` of its fit}: which fits the result was made from
    #: (empty for subjects given as draws), so that a saved result is matched to fits by content.
    inputs: dict = field(default_factory=dict)
    #: The file the result was read from (:func:`load_population`); empty when computed here.
    origin: str = ""
    #: :meth:`diagnostics`' rows, computed once (kept in the population cache beside the draws)
    _diagnostics: list | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def log(self):
        return [f == "lognormal" for f in self.families]

    @property
    def coordinates(self):
        return ["log" if g else "natural" for g in self.log]

    @property
    def converged(self):
        return bool(self.sampler.get("converged"))

    def _flat(self, x):
        return x.reshape((-1,) + x.shape[2:])

    def population_draws(self):
        """Population mean, sd and median in natural units: dict -> (chain, draw, p)."""
        lg = np.array(self.log)
        st = np.array([f == "student_t" for f in self.families])
        with np.errstate(over="ignore"):
            mean = np.where(lg, np.exp(self.mu + 0.5 * self.sd**2), self.mu)
            sd = np.where(lg, mean * np.sqrt(np.expm1(self.sd**2)),
                          np.where(st, self.sd * math.sqrt(NU_T / (NU_T - 2)), self.sd))
        return {"mean": mean, "sd": sd, "median": np.where(lg, np.exp(self.mu), self.mu)}

    def predictive(self, rng=0):
        """Draws (chain*draw, p) of a new subject's parameters in natural units."""
        rng = as_generator(rng)
        mu, sd = self._flat(self.mu), self._flat(self.sd)
        n, p = mu.shape
        if self.corr is not None:
            cov = self._flat(self.corr) * sd[:, :, None] * sd[:, None, :]
            e = np.einsum("kij,kj->ki", np.linalg.cholesky(cov), rng.standard_normal((n, p)))
        else:
            e = sd * rng.standard_normal((n, p))
            st = np.array([f == "student_t" for f in self.families])
            e = np.where(st, e / np.sqrt(rng.chisquare(NU_T, (n, p)) / NU_T), e)
        u = mu + e
        return np.where(self.log, np.exp(u), u)

    def diagnostics(self):
        """R-hat and bulk / tail ESS of every hyper-parameter (ArviZ): a table indexed like
        summary(). Computed once; a result read from the population cache has them already."""
        if self._diagnostics is None:
            self._diagnostics = self._diagnostic_rows()
        return pd.DataFrame(self._diagnostics)

    def _diagnostic_rows(self):
        rows = []
        items = [("mu", self.mu), ("sd", self.sd)]
        for q, x in items:
            for j, name in enumerate(self.parameters):
                rows.append(_diag(name, q, x[:, :, j]))
        if self.corr is not None:
            for j, k in self._pairs():
                rows.append(_diag(f"{self.parameters[j]},{self.parameters[k]}", "corr", self.corr[:, :, j, k]))
        return rows

    def _pairs(self):
        p = len(self.parameters)
        return [(j, k) for j in range(p) for k in range(j + 1, p)]

    def summary(self, prob=CI_PROB):
        """Per parameter: population mean, sd and median (natural units), ``mu`` and ``sd`` in
        the population coordinate, correlations: posterior median, sd and highest-density
        interval at ``prob`` (:mod:`skinfit.results.intervals`), with the family, R-hat and ESS
        of ``mu`` / ``sd``."""
        check_prob(prob, "summary")
        rows = []
        draws = self.population_draws()
        diag = self.diagnostics().set_index(["parameter", "quantity"])
        for j, name in enumerate(self.parameters):
            coord = self.coordinates[j]
            items = [*((q, draws[q], "natural") for q in DERIVED), ("mu", self.mu, coord), ("tau", self.sd, coord)]
            for qty, x, c in items:
                lo, med, hi = _interval(x[:, :, j], prob)
                d = diag.loc[(name, "sd" if qty == "tau" else "mu")] if qty in ("mu", "tau") else None
                rows.append({"parameter": name, "family": self.families[j], "quantity": qty, "estimate": med,
                             "sd": float(np.std(x[:, :, j])), "lower": lo, "upper": hi, "coordinate": c,
                             "r_hat": np.nan if d is None else d["r_hat"],
                             "ess_bulk": np.nan if d is None else d["ess_bulk"],
                             "ess_tail": np.nan if d is None else d["ess_tail"]})
        if self.corr is not None:
            for j, k in self._pairs():
                lo, med, hi = _interval(self.corr[:, :, j, k], prob)
                key = f"{self.parameters[j]},{self.parameters[k]}"
                d = diag.loc[(key, "corr")]
                rows.append({"parameter": key, "family": "", "quantity": "corr", "estimate": med,
                             "sd": float(np.std(self.corr[:, :, j, k])), "lower": lo,
                             "upper": hi, "coordinate": "population", "r_hat": d["r_hat"],
                             "ess_bulk": d["ess_bulk"], "ess_tail": d["ess_tail"]})
        return pd.DataFrame(rows)

    def subject_summary(self, prob=CI_PROB):
        """Per subject and parameter: separate-fit and shrunk posterior median, sd and
        highest-density interval at ``prob``, and the contraction of the subject's own fit
        (1 - var posterior / var prior, sampling coordinate: near 0 the subject's data barely
        moved its prior)."""
        check_prob(prob, "subject_summary")
        rows = []
        for i, s in enumerate(self.subjects):
            for j, name in enumerate(self.parameters):
                sep = _interval(self.separate[s][:, j], prob)
                shr = _interval(self.shrunk[:, :, i, j], prob)
                rows.append({"subject": s, "parameter": name, "sd": float(np.std(self.separate[s][:, j])),
                             "separate": sep[1], "separate_lower": sep[0],
                             "separate_upper": sep[2], "shrunk": shr[1], "shrunk_lower": shr[0],
                             "shrunk_upper": shr[2], "contraction": self.contraction.get(s, {}).get(name, np.nan)})
        return pd.DataFrame(rows)

    def effect(self, parameter, prob=CI_PROB, reference=0.0):
        """Is a population parameter (a slope with a condition, e.g. contact_area's ``m1``)
        below or above ``reference``?  Posterior probabilities and highest-density ``prob`` interval of
        the population mean (of ``mu`` in the population coordinate, i.e. of the median for a
        log-normal family), and of a new subject's value."""
        j = self._index(parameter)
        check_prob(prob, "effect")
        if isinstance(reference, bool) or not isinstance(reference, (int, float, np.number)) or not np.isfinite(
                reference):
            raise InputError("effect", f"expected a finite number (got {reference!r})", field="reference")
        if self.log[j] and reference <= 0:
            raise InputError("effect", f"{parameter} has a log-normal population (every value > 0): expected a "
                             f"reference > 0 (got {reference:g})", field="reference")
        ref = math.log(reference) if self.log[j] else reference
        m = self.mu[:, :, j].ravel()
        new = self.predictive()[:, j]
        new_u = np.log(new) if self.log[j] else new
        lo, med, hi = _interval(m, prob)
        nlo, nhi = hdi(new, prob)
        centre = "median" if self.log[j] else "mean"
        tr = (lambda x: math.exp(x)) if self.log[j] else (lambda x: x)
        return {"parameter": parameter, "question": f"population {centre} of {parameter} vs {reference:g}",
                "estimate": tr(med), "sd": float(np.std(np.exp(m) if self.log[j] else m)), "lower": tr(lo),
                "upper": tr(hi),
                "p_below": float(np.mean(m < ref)), "p_above": float(np.mean(m > ref)),
                "new_subject_lower": float(nlo), "new_subject_upper": float(nhi),
                "p_new_subject_below": float(np.mean(new_u < ref))}

    def contrast(self, a, b, prob=CI_PROB):
        """Population-level contrast of two parameters (e.g. two levels of a split parameter):
        posterior of the difference of their population means (natural, or for log-normal
        families the ratio of medians), interval and P(A > B)."""
        ja, jb = self._index(a), self._index(b)
        check_prob(prob, "contrast")
        if self.log[ja] != self.log[jb]:
            raise InputError("contrast", f"{a} and {b} have different population coordinates")
        d = (self.mu[:, :, ja] - self.mu[:, :, jb]).ravel()
        lo, med, hi = _interval(d, prob)
        kind = "ratio of medians" if self.log[ja] else "difference of means"
        tr = np.exp if self.log[ja] else (lambda x: x)
        return {"A": a, "B": b, "quantity": kind, "estimate": float(tr(med)), "sd": float(np.std(tr(d))),
                "lower": float(tr(lo)),
                "upper": float(tr(hi)), "p_greater": float(np.mean(d > 0))}

    def effects(self, prob=CI_PROB):
        """The default questions: every population parameter whose prior allows both signs
        (a slope with a condition) against 0, and each level of a split parameter against its
        first level.  A table."""
        check_prob(prob, "effects")
        rows = []
        bounds = self.hyperpriors.get("_bounds", {})
        for name in self.parameters:
            lo, hi = bounds.get(name, (0.0, 0.0))
            if lo < 0 < hi and not self.log[self._index(name)]:
                rows.append(self.effect(name, prob))
        levels = {}
        for name in self.parameters:
            if "[" in name:
                levels.setdefault(name.split("[", 1)[0], []).append(name)
        for names in levels.values():
            for other in names[1:]:
                c = self.contrast(other, names[0], prob)
                rows.append({"parameter": f"{other} vs {names[0]}", "question": c["quantity"],
                             "estimate": c["estimate"], "sd": c["sd"], "lower": c["lower"], "upper": c["upper"],
                             "p_above": c["p_greater"], "p_below": 1 - c["p_greater"]})
        return pd.DataFrame(rows)

    def _index(self, name):
        if not isinstance(name, str) or name not in self.parameters:
            raise InputError("population", f"no population parameter {name!r} (parameters: "
                             f"{', '.join(self.parameters)})", field="parameter")
        return self.parameters.index(name)

    # mapping interface for skinfit.report.html.write_report(population=...): a parameter's
    # population distribution as draws of a new subject's value
    def __contains__(self, name):
        return name in self.parameters

    def get(self, name, default=None):
        return self.predictive()[:, self.parameters.index(name)] if name in self.parameters else default

    def to_datatree(self):
        """An ArviZ DataTree: ``posterior`` (hyper-parameters, dims chain, draw, parameter),
        ``subjects`` (shrunk subject posteriors, dims chain, draw, subject, parameter),
        ``separate`` (the separate fits' draws, thinned to 1000 a subject) and the
        families, hyper-priors, sampler record and warnings as root attributes."""
        draws = self.population_draws()
        post = {"mu": self.mu, "sd": self.sd, "pop_mean": draws["mean"], "pop_sd": draws["sd"],
                "pop_median": draws["median"]}
        dims = {k: ["parameter"] for k in post}
        if self.corr is not None:
            post["corr"] = self.corr
            dims["corr"] = ["parameter", "parameter_b"]
        coords = {"parameter": self.parameters, "parameter_b": self.parameters, "subject": self.subjects}
        attrs = {"kind": "skinfit.population", integrity.SCHEMA_ATTR: integrity.CHECKED_SCHEMA,
                 "model_id": self.model_id,
                 "families": json.dumps(dict(zip(self.parameters, self.families))),
                 # not "coordinates": netCDF readers take that for CF's list of coordinate variables and drop it
                 "population_coordinates": json.dumps(dict(zip(self.parameters, self.coordinates))),
                 "hyperpriors": json.dumps(self.hyperpriors), "sampler": json.dumps(self.sampler, default=float),
                 "warnings": json.dumps(self.warnings), "contraction": json.dumps(self.contraction),
                 "inputs": json.dumps(self.inputs)}
        tree = arviz_base.from_dict({"posterior": post}, dims=dims, coords=coords, attrs={"/": attrs})
        ds = xr.Dataset({"theta": (("chain", "draw", "subject", "parameter"), self.shrunk)},
                        coords={"chain": np.arange(self.shrunk.shape[0]), "draw": np.arange(self.shrunk.shape[1]),
                                "subject": self.subjects, "parameter": self.parameters})
        tree["subjects"] = xr.DataTree(ds)
        n = min(len(v) for v in self.separate.values())
        pick = {s: np.linspace(0, len(v) - 1, min(n, 1000)).astype(int) for s, v in self.separate.items()}
        sep = np.stack([self.separate[s][pick[s]] for s in self.subjects])
        tree["separate"] = xr.DataTree(xr.Dataset({"theta": (("subject", "sample", "parameter"), sep)},
                                                  coords={"subject": self.subjects, "parameter": self.parameters}))
        return tree

    def save(self, path):
        """Write :meth:`to_datatree` as NetCDF (h5netcdf), with the sha256 of each group and of
        the root attributes (:mod:`skinfit.io.integrity`), which :func:`load_population` checks."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tree = self.to_datatree()
        integrity.stamp(tree)
        replace_atomic(path, integrity.seal(tree.to_netcdf(engine="h5netcdf")))
        return path

    @property
    def problems(self):
        """The warnings that mean the result cannot be reported as it stands (not converged, a
        sampler that rarely moved, incomplete inputs): all but the notes that a subject's data
        barely move a parameter's prior, which is information about the data."""
        return [w for w in self.warnings if WEAK_DATA not in w]


def _interval(x, prob):
    """(lower, median, upper) of draws ``x`` (any shape, flattened): the posterior median and
    the highest-density interval at ``prob``."""
    lo, hi = hdi(x, prob)
    return lo, float(np.median(x)), hi


def _diag(name, qty, x):
    """R-hat and bulk / tail ESS of one hyper-parameter's draws x (chain, draw) (ArviZ)."""
    return {"parameter": name, "quantity": qty, "r_hat": float(arviz_stats.rhat(x)) if x.shape[0] > 1 else np.nan,
            "ess_bulk": float(arviz_stats.ess(x)),
            "ess_tail": float(arviz_stats.ess(x, method="tail", prob=(0.05, 0.95)))}


def load_population(path):
    """A :class:`PopulationResult` from the NetCDF written by :meth:`PopulationResult.save`
    (the separate fits' draws thinned to at most 1000 a subject), with ``origin`` the path;
    ``inputs`` is empty for a file written before skinfit recorded them."""
    if not Path(path).is_file():
        raise InputError(path, "no such population file (expected the population.nc of `skinfit population`)")
    try:
        sealed = integrity.check_file(path)  # its bytes, before HDF5 parses any of them
        tree = xr.open_datatree(path).load()
    except InputError:
        raise
    except (OSError, ValueError, KeyError, TypeError, IndexError, RuntimeError, MemoryError) as exc:
        raise InputError(path, f"not a readable skinfit population result ({type(exc).__name__}: "
                               f"{' '.join(str(exc).split())[:200]})") from None
    if tree.attrs.get("kind") != "skinfit.population" and integrity.RECORD not in tree.attrs:
        raise InputError(path, "not a skinfit population result")
    record = integrity.take(path, tree.attrs, list(tree.children), sealed=sealed,
                            unversioned=1)  # a result written before checksums has no schema: 1
    integrity.verify(path, record, groups=integrity.groups_of(tree))
    if tree.attrs.get("kind") != "skinfit.population":
        raise InputError(path, "not a skinfit population result")
    try:  # an old file (no checksums) damaged where an attribute or group was: one line, not a traceback
        post = tree["posterior"].to_dataset()
        attrs = tree.attrs
        fam = json.loads(attrs["families"])
        params = [str(p) for p in post["parameter"].values]
        subjects = [str(s) for s in tree["subjects"].to_dataset()["subject"].values]
        sep_ds = tree["separate"].to_dataset()["theta"].values
        sep = {s: sep_ds[i] for i, s in enumerate(subjects)}
        return PopulationResult(attrs["model_id"], params, [fam[p] for p in params], subjects, post["mu"].values,
                                post["sd"].values, post["corr"].values if "corr" in post else None,
                                tree["subjects"].to_dataset()["theta"].values, sep, json.loads(attrs["hyperpriors"]),
                                json.loads(attrs["sampler"]), json.loads(attrs["warnings"]),
                                json.loads(attrs["contraction"]), json.loads(attrs.get("inputs", "{}")), str(path))
    except (KeyError, ValueError, TypeError, IndexError) as exc:
        raise InputError(path, f"not a complete skinfit population result ({type(exc).__name__}: "
                               f"{' '.join(str(exc).split())[:200]})") from None
