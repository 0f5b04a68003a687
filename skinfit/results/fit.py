"""The result of a fit: :class:`Fit`, one ArviZ DataTree with provenance in its root attributes.

Its groups are those of :data:`GROUPS` (posterior, prior, sample_stats, log_likelihood,
posterior_predictive, observed_data, constant_data, derived). Its root attributes record where
every number came from: model card, prior file and dataset (with hashes and full texts),
skinfit and dependency versions, seed, MAP, optimiser status, timings, convergence, guard rails
and the check of the fit to the data. :func:`skinfit.fit` makes one (:mod:`skinfit.results.fitting`),
:func:`load_fit` reads one saved by :meth:`Fit.save`.
"""

from __future__ import annotations

import hashlib
import json
import os
import warnings
from collections.abc import Iterable, Mapping
from html import escape
from pathlib import Path
from types import MappingProxyType

import numpy as np
import pandas as pd
import xarray as xr

from skinfit.errors import InputError, InputTypeError
from skinfit.io import integrity
from skinfit.io.arguments import check_output_file, shown
from skinfit.io.data import Column, Dataset
from skinfit.io.models import parse_model_text
from skinfit.io.priors import PriorSet
from skinfit.io.provenance import input_lines, inputs_of
from skinfit.posterior import Posterior
from skinfit.results.intervals import CI_KIND, CI_PROB, check_ci, interval_name
from skinfit.results.pointwise import RECIPE, Recomputed, recomputable
from skinfit.results.store import fit_file, read_tree, write_tree
from skinfit.results.summary import (
    SUMMARY_ATTR,
    SUMMARY_FORMAT,
    compute_summary,
    format_numbers,
    misfit_line,
    priors_from_attrs,
    summary_from_attr,
    summary_to_attr,
    wall_time_text,
)

__all__ = ["Fit", "load_fit", "as_fit", "as_fits", "rebuild_posterior", "plain_json", "GROUPS", "DEFERRED",
           "CACHED_ATTRS"]

#: The groups of a fit's tree in ArviZ's order; those of :data:`DEFERRED` (pointwise
#: log-likelihood and predictive draws, a value per posterior draw and data row each) are
#: computed by :meth:`Fit.complete` and read from a saved fit's file on first use.
GROUPS = ("posterior", "prior", "sample_stats", "log_likelihood", "posterior_predictive", "observed_data",
          "constant_data", "derived")
DEFERRED = ("log_likelihood", "posterior_predictive")
#: Root attributes a saved fit may gain without its draws or records changing (evidence and LOO
#: by a comparison, the stored summary, the file's checksums): left out of content hashes such as
#: the report's figure cache (:meth:`Fit.content_hash`).
CACHED_ATTRS = ("evidence", "loo", SUMMARY_ATTR, integrity.RECORD)


class Fit:
    """The result of :func:`skinfit.fit`: an ArviZ DataTree plus convenience views.

    ``fit.idata`` is the DataTree; ``fit.summary()`` a table; ``fit.save(path)`` writes NetCDF.

    A fit is complete when made (:func:`skinfit.fit`) or loaded (:func:`load_fit`), or after one
    explicit call, :meth:`complete`, for a fit made with ``skinfit.fit(..., complete=False)``:
    until then it is :attr:`pending`, without the groups of :data:`DEFERRED` (pointwise
    log-likelihood and predictive draws) and the check of the fit to the data, and
    :attr:`idata` and :meth:`group` of those groups raise a RuntimeError naming
    :meth:`complete`. No property computes anything, checks anything or warns; a loaded fit's
    pointwise groups are computed again from its draws (:mod:`skinfit.results.pointwise`), or
    read from a file of an earlier skinfit that holds them, when first used (:attr:`idata`,
    :meth:`group`).
    """

    def __init__(self, idata, posterior=None, *, pointwise=None, stored=None, path=None):
        self._tree = idata
        self._path = None if path is None else Path(path)
        self._posterior = posterior
        self._pointwise = pointwise  # a skinfit.results.tree.Pointwise: the groups of DEFERRED to compute
        self._stored = stored  # a skinfit.results.store.StoredGroups: groups of DEFERRED still in the file
        self._summary = None  # (key, table) of the last summary(): see _summary_key

    @property
    def path(self):
        """The file a loaded fit was read from (:func:`load_fit`); None for a fit made here."""
        return self._path

    @property
    def pending(self):
        """True for a fit made with ``skinfit.fit(..., complete=False)`` until :meth:`complete`:
        the groups of :data:`DEFERRED` and the check of the fit to the data are still to come."""
        return self._pointwise is not None

    @property
    def idata(self):
        """The complete ArviZ DataTree (a loaded fit's pointwise groups computed again or read
        from its file on first use); RuntimeError for a :attr:`pending` fit."""
        self._require_complete("idata")
        return self._read_stored()._tree

    @property
    def partial_tree(self):
        """The tree as held now: every group but, until computed or read, those of
        :data:`DEFERRED`; never computes or reads them (content hashes, summaries)."""
        return self._tree

    def complete(self) -> Fit:
        """Complete a :attr:`pending` fit: compute the groups of :data:`DEFERRED` and put them in
        the tree in ArviZ's order (:data:`GROUPS`), with their time as ``pointwise_s`` in
        ``attr("timings")``, and check the fit to the data on them (:mod:`skinfit.inference.misfit`:
        its record as ``attr("misfit")``, each failed check in :attr:`warnings` and warned as a
        :class:`~skinfit.inference.misfit.MisfitWarning`); for a loaded fit, read them from its
        file; for a complete fit, nothing.  Returns the fit.  The root attributes are kept
        (e.g. an evidence already cached)."""
        self._read_stored()
        if self._pointwise is None:
            return self
        tree, messages = self._pointwise.complete(self._tree, self.posterior)
        self._tree, self._pointwise = tree, None
        for message, category in messages:  # memory thinning, misfit
            warnings.warn(message, category, stacklevel=2)
        return self

    def _read_stored(self):
        """The fit, with the groups of :data:`DEFERRED` of a loaded fit computed again from its
        draws (:class:`~skinfit.results.pointwise.Recomputed`) or read from its file
        (:class:`~skinfit.results.store.StoredGroups`)."""
        if self._stored is not None:
            self._tree, self._stored = self._stored.read(self._tree), None
        return self

    def _require_complete(self, what):
        if self.pending:
            raise RuntimeError(f"{self.model_id} on {self.dataset_id}: {what} needs the pointwise log-likelihood and "
                               "predictive groups of this fit, made with skinfit.fit(..., complete=False): call "
                               "fit.complete() first")

    @property
    def attrs(self):
        """The tree's root attributes (provenance, timings, evidence): a mutable dict; never
        computes the deferred groups."""
        return self._tree.attrs

    def group(self, name):
        """One group of the tree as an ``xarray.Dataset`` (one of :data:`DEFERRED` read from a
        loaded fit's file on first use; RuntimeError for those of a :attr:`pending` fit)."""
        if name in DEFERRED:
            self._require_complete(f"group({name!r})")
            self._read_stored()
        return self._tree[name].to_dataset()

    # ---- provenance ---------------------------------------------------------------------
    def attr(self, key):
        value = self.attrs[key]
        return json.loads(value) if isinstance(value, str) and value[:1] in "{[" else value

    @property
    def inputs(self) -> dict:
        """The model card, prior file and data file this fit read: path, sha256, where on the
        search path each was found and the files of the same id it hid
        (:func:`skinfit.io.provenance.inputs_of`)."""
        return inputs_of(self.attrs)

    @property
    def model_id(self):
        return self.attrs["model_id"]

    @property
    def dataset_id(self):
        return self.attrs["dataset_id"]

    @property
    def map(self):
        return self.attr("map")

    @property
    def warnings(self):
        """Guard-rail problems found when the fit ran (:mod:`skinfit.inference.guardrails`): a list of dicts
        ``check, status (FAIL | WARN), parameter, message``; empty for a clean fit."""
        return json.loads(self.attrs.get("warnings", "[]"))

    @property
    def notes(self):
        """Information the guard rails record that is not a failure (:mod:`skinfit.inference.guardrails`,
        e.g. a posterior that reaches a prior bound where the priors put it): dicts like
        :attr:`warnings`' with status NOTE; ``--strict`` does not act on them.  Empty for a fit
        saved before notes were recorded."""
        return json.loads(self.attrs.get("notes", "[]"))

    @property
    def converged(self):
        return bool(self.attr("sampler")["converged"])

    @property
    def posterior(self):
        """The :class:`~skinfit.posterior.Posterior` behind the fit, rebuilt from the saved tree."""
        if self._posterior is None:
            self._posterior = rebuild_posterior(self._tree)
        return self._posterior

    # ---- tables -------------------------------------------------------------------------
    def summary(self, ci_prob: float | None = None) -> pd.DataFrame:
        """Per parameter: its SI unit, mean, sd, HDI, R-hat, bulk/tail ESS, MAP, tau, contraction.

        The interval is the highest-density interval at ``ci_prob`` (default
        :data:`skinfit.results.intervals.CI_PROB`, 94%: columns ``hdi_3%``, ``hdi_97%``; at 0.9
        ``hdi_5%``, ``hdi_95%``), as ``az.summary(fit.idata, ci_kind="hdi", ci_prob=ci_prob)``
        gives it; the table's ``attrs`` record ``ci_prob`` and ``ci_kind``.

        ``contraction`` is 1 - var_posterior / var_prior, in the sampling coordinate (log for
        positive parameters): near 1 the data determined the parameter; below 0.5 the
        posterior is mostly its prior and ``note`` says so (e.g. ``tau0`` of electroadhesion,
        which the forces determine only through tau0*beta0 and tau0*phi).

        Computed once per content (a copy returned): a report asks for it several times a fit.
        :meth:`save` stores it in the file (root attribute ``summary``, with the sha256 of what
        it was computed from, :meth:`_summary_key`), and a loaded fit whose draws, warnings and
        records still have that hash shows the stored table (the same numbers) without
        computing it again, nor importing arviz_stats and scipy.stats; after any edit of those
        it is computed afresh.
        """
        ci_prob = CI_PROB if ci_prob is None else check_ci(ci_prob, "Fit.summary")
        if ci_prob != CI_PROB:  # another interval: computed each time, never stored
            table = compute_summary(self, ci_prob)
            table.attrs.update(warnings=self.warnings, notes=self.notes)
            return table
        key = self._summary_key()
        if self._summary is not None and self._summary[0] == key:
            return self._summary[1].copy()
        table = summary_from_attr(self._tree.attrs.get(SUMMARY_ATTR), key, self._slot_names())
        if table is None:
            table = self._compute_summary()
        # guard rails and misfit (skinfit.inference.guardrails, skinfit.inference.misfit)
        table.attrs["warnings"] = self.warnings
        table.attrs["notes"] = self.notes  # information, not failures (skinfit.inference.guardrails)
        table.attrs.update(ci_prob=CI_PROB, ci_kind=CI_KIND)
        self._summary = (key, table)
        return table.copy()

    def content_hash(self):
        """sha256 of the fit's content but what is computed from it: the arrays of every group
        but those of :data:`DEFERRED` (pointwise log-likelihood and predictive draws, up to
        200 MB, functions of the posterior and the seeds in the attributes; never computed or
        read for this) with their dimensions and attributes (units), and the root attributes but
        :data:`CACHED_ATTRS` (evidence, LOO and the stored summary, which a comparison or a save
        adds to a file).  Keys the stored summary, the report's figures and the population cache."""
        h = hashlib.sha256()
        tree = self._tree
        for name in sorted(set(tree.children) - set(DEFERRED)):
            ds = tree[name].to_dataset()
            for var in sorted(ds.variables):
                da = ds[var]
                values = da.values
                # text as text: a fit in memory holds str objects where its file gives '<U' arrays
                text = values.dtype.kind in "OUS"
                h.update(f"{name}/{var}{da.dims}{values.shape}{'text' if text else values.dtype.str}".encode())
                h.update(json.dumps(da.attrs, sort_keys=True, default=plain_json).encode())
                h.update(repr([str(v) for v in values.ravel().tolist()]).encode() if text
                         else np.ascontiguousarray(values).tobytes())
        attrs = {k: v for k, v in tree.attrs.items() if k not in CACHED_ATTRS}
        h.update(json.dumps(attrs, sort_keys=True, default=plain_json).encode())
        return h.hexdigest()

    @property
    def summary_stored(self):
        """True when the root attributes hold this fit's summary table for its current content
        (:meth:`summary` then reads it instead of computing it)."""
        return summary_from_attr(self._tree.attrs.get(SUMMARY_ATTR), self._summary_key(),
                                 self._slot_names()) is not None

    def _slot_names(self):
        return [s["name"] for s in self.attr("slots")]

    def _summary_key(self):
        """sha256 of all :meth:`summary` is computed from: the fit's content
        (:meth:`content_hash`: draws with their dimensions, levels and units, warnings, MAP,
        sampler record, slots, priors, derived quantities), with the table's format version
        :data:`~skinfit.results.summary.SUMMARY_FORMAT`."""
        return hashlib.sha256(f"skinfit summary {SUMMARY_FORMAT}\0{self.content_hash()}".encode()).hexdigest()

    def _compute_summary(self):
        return compute_summary(self)

    def diagnostics(self):
        """Sampler, optimiser and support diagnostics as one dict."""
        return {"sampler": self.attr("sampler"), "optimizer": self.attr("optimizer"),
                "timings": self.attr("timings"), "support_counts": self.attr("support_counts"),
                "support_condition": self.attrs.get("support_condition", "")}

    def report_text(self, summary: pd.DataFrame | None = None) -> str:
        """The text printed by ``skinfit fit``: summary table and diagnostics (``summary``:
        the table of :meth:`summary` if the caller has it already)."""
        s = self.attr("sampler")
        t = self.attr("timings")
        c = self.attr("support_counts")
        seed = int(self.attrs.get("seed", -1))
        seed_text = ("a numpy Generator (not recorded)" if seed < 0 else
                     f"{seed}"
                     f"{' (drawn; --seed ' + str(seed) + ' repeats this fit)' if self.attrs.get('seed_drawn') else ''}")
        lines = [f"model {self.model_id}  data {self.dataset_id}  ({self.attrs['dataset_sha256'][:12]})",
                 *input_lines(self.attrs),
                 f"seed: {seed_text}",
                 f"converged: {'yes' if s['converged'] else 'NO: ' + '; '.join(s['reasons'])}",
                 *[f"{w['status']}: {w['message']}" for w in self.warnings if w["check"] != "convergence"],
                 *[f"NOTE: {n['message']}" for n in self.notes],
                 misfit_line(self),
                 *(["note: " + self.attr("pointwise_thinned")["note"]] if "pointwise_thinned" in self.attrs else []),
                 f"walkers {s['nwalkers']}  steps {s['n_steps']}  burn-in {s['burn']}  thin {s['thin']}  "
                 f"acceptance mean {s['acceptance_mean']:.3f} (min {s['acceptance_min']:.3f})  "
                 f"max R-hat {s['rhat_max']:.4f}",
                 f"moves: {s['moves']}",
                 "proposal: importance start, effective sample size "
                 + (", ".join(f"{r['ess']:.0f}" for r in s.get("importance", [])) or "-")
                 + f" of {s['importance'][0]['draws'] if s.get('importance') else 0} draws per round; refitted "
                 "during sampling at steps "
                 f"{', '.join(str(a['step']) for a in s.get('adaptation', []) if a['refit']) or 'none'}",
                 f"wall time: {wall_time_text(t, self.pending)}",
                 f"log-density evaluations {c['evaluations']}: outside prior bounds {c['outside_prior']}, "
                 f"outside the physical support {c['outside_support']}"
                 + (f" ({self.attrs.get('support_condition')})" if c["outside_support"] else ""),
                 ""]
        table = self.summary() if summary is None else summary
        lines.append(f"intervals: {interval_name(table.attrs.get('ci_prob', CI_PROB))} (highest-density); "
                     "numbers to the precision their posterior sd allows (summary.csv has every digit)")
        with pd.option_context("display.width", 200, "display.max_columns", 20):
            lines.append(format_numbers(table).to_string())
        return "\n".join(lines)

    def save(self, path: str | os.PathLike) -> Path:
        """Write the fit as NetCDF, atomically (temporary file + rename), with the sha256 of each
        group and of the root attributes (:mod:`skinfit.io.integrity`), which :func:`load_fit`
        checks.  A pending fit is completed first.  Every group is written but those of
        :data:`DEFERRED` of a fit that records how to compute them again, of a model that ships
        with skinfit (:func:`skinfit.results.pointwise.recomputable`: nine tenths of the bytes,
        computed again on first use after :func:`load_fit`); a plug-in's or a user's model's fit,
        and one loaded from a file that holds them (saved by an earlier skinfit), keeps them.
        ``path`` is the file (a directory, a device such as /dev/null or a FIFO there is refused
        first)."""
        path = check_output_file(path, "Fit.save", "path", "fit")
        path.parent.mkdir(parents=True, exist_ok=True)
        if self.pending:
            self.complete()
        leave_out = recomputable(self._tree)
        if not leave_out:  # an earlier skinfit's fit, or a plug-in's model: the groups are saved with it
            self._read_stored()
        tree = self._tree
        schema = tree.attrs.get(integrity.SCHEMA_ATTR)
        if not isinstance(schema, (int, np.integer)) or schema < integrity.CHECKED_SCHEMA:  # an older file saved again
            tree.attrs[integrity.SCHEMA_ATTR] = integrity.CHECKED_SCHEMA  # (before its summary's key is computed)
        try:
            tree.attrs[SUMMARY_ATTR] = summary_to_attr(self.summary(), self._summary_key())
        except Exception as exc:  # the summary is only kept to save time: the fit is saved without it
            tree.attrs.pop(SUMMARY_ATTR, None)
            warnings.warn(f"{self.model_id} on {self.dataset_id}: saved without its summary table "
                          f"({type(exc).__name__}: {exc}); it is computed when read", UserWarning, stacklevel=2)
        written = tree
        if leave_out:
            written = xr.DataTree.from_dict({"/": tree.to_dataset(inherit=False)}
                                            | {n: tree[n].to_dataset(inherit=False) for n in tree.children
                                               if n not in DEFERRED})
        write_tree(written, path)
        tree.attrs[integrity.RECORD] = written.attrs[integrity.RECORD]  # the fit in memory as it is read back
        return path

    def _repr_html_(self) -> str:
        """Notebook view: model and data, the seed, the convergence verdict with its reasons,
        the guard-rail warnings and notes and the summary table."""
        s = self.attr("sampler")
        verdict = ("<b style='color:#1a7f37'>converged</b>" if s["converged"] else
                   "<b style='color:#cf222e'>NOT converged</b>: " + escape("; ".join(s["reasons"])))
        items = "".join(f"<li><b>{escape(w['status'])}</b> {escape(w['message'])}</li>"
                        for w in self.warnings + self.notes)
        seed = int(self.attrs.get("seed", -1))
        with pd.option_context("display.float_format", "{:.4g}".format):
            table = self.summary().to_html(float_format="{:.4g}".format, border=0)
        return (f"<div><p><b>{escape(self.model_id)}</b> on <b>{escape(self.dataset_id)}</b> "
                f"(data {escape(self.attrs['dataset_sha256'][:12])}; seed {seed if seed >= 0 else 'not recorded'})"
                f"<br>{verdict}; walkers {s['nwalkers']}, steps {s['n_steps']}, max R-hat {s['rhat_max']:.4f}</p>"
                + (f"<ul>{items}</ul>" if items else "") + table + "</div>")

    def __repr__(self):
        return f"Fit({self.model_id!r} on {self.dataset_id!r}, converged={self.converged})"


def load_fit(path: str | os.PathLike) -> Fit:
    """Load a fit saved by :meth:`Fit.save` (``path``: the file, or its run directory).

    The groups of :data:`DEFERRED` (pointwise log-likelihood and predictive draws) are made
    when first used (:attr:`Fit.idata`, :meth:`Fit.group`, :meth:`Fit.complete`): computed
    again from the draws, data and seed in the file, bit for bit those of the fit that was
    saved (:mod:`skinfit.results.pointwise`; InputError when this skinfit's model gives other
    numbers), or, for a file of an earlier skinfit that holds them, read from it (InputError if
    it has been replaced or changed meanwhile, rather than mix two results).  The file's
    checksums are checked as each part is read (:mod:`skinfit.io.integrity`)."""
    path = fit_file(path)
    tree, stored = read_tree(path, later=DEFERRED)
    if "model_id" not in tree.attrs:
        raise InputError(path, "not a skinfit result (no model_id attribute)")
    fit = Fit(tree, stored=stored, path=path)
    if stored is None and RECIPE in tree.attrs:  # computed again from the draws on first use
        fit._stored = Recomputed(path, lambda: fit.posterior)
    return fit


def as_fit(obj, where="fit", field=None) -> Fit:
    """A :class:`Fit` from a Fit, its DataTree or the path of a saved fit (:func:`load_fit`);
    InputTypeError naming ``where`` (the function) and ``field`` (the argument) for anything else."""
    if isinstance(obj, Fit):
        return obj
    if isinstance(obj, (str, os.PathLike)):
        return load_fit(obj)
    if isinstance(obj, xr.DataTree) and "model_id" in obj.attrs:
        return Fit(obj)
    raise InputTypeError(where, f"expected a skinfit Fit, its DataTree or the path of a fit.nc (got {shown(obj)})",
                         field=field)


def as_fits(fits, where, field="fits"):
    """A list of Fits from a sequence (or the values of a mapping) of what :func:`as_fit`
    accepts; InputTypeError naming the position of the first that is none of them."""
    if isinstance(fits, Mapping):
        fits = list(fits.values())
    if isinstance(fits, (str, bytes, os.PathLike, Fit)) or not isinstance(fits, Iterable):
        raise InputTypeError(where, f"expected a list of fits (Fit objects or paths of fit.nc) (got {shown(fits)})",
                             field=field)
    return [as_fit(f, where, f"{field}[{i}]") for i, f in enumerate(fits)]


def plain_json(value):
    """JSON ``default`` for a fit's attributes: numpy scalars and arrays as the Python values a
    fit in memory holds (a loaded fit's integer attributes are numpy integers), anything else as
    its text."""
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    return str(value)


def rebuild_posterior(tree):
    """The :class:`~skinfit.posterior.Posterior` of a saved fit, rebuilt from its own records
    (model card and prior file as saved, the data from its constant and observed groups),
    without the optimiser, the sampler or ArviZ's tree builder: a report's predictive check
    rebuilds it without fitting."""
    attrs = tree.attrs
    model = parse_model_text(attrs["model_card"], f"model card saved in fit ({attrs['model_id']})",
                             attrs["model_sha256"], saved=True)
    priors = PriorSet(id=attrs["priors_id"], model=attrs["model_id"],
                      priors=MappingProxyType(priors_from_attrs(attrs)), path="saved priors",
                      sha256=attrs["priors_sha256"], text=attrs["priors_text"])
    setup = json.loads(attrs["setup"])
    units = json.loads(attrs.get("data_units", attrs["units"]))  # the split levels' labels use them
    cd = tree["constant_data"].to_dataset()
    od = tree["observed_data"].to_dataset()
    frame = pd.DataFrame({c: cd[c].values for c in cd.data_vars} | {o: od[o].values for o in od.data_vars})
    columns = tuple(Column(c, c, units.get(c), "quantity" if c in units else "category") for c in frame.columns)
    ds = Dataset(id=attrs["dataset_id"], title="", frame=frame, columns=columns, groups=(),
                 provenance=MappingProxyType(json.loads(attrs["dataset_provenance"])), model=None,
                 path=attrs["dataset_path"], sha256=attrs["dataset_sha256"])
    return Posterior(model, priors, ds, split=setup["split"], noise=setup["noise"],
                     constants={k: v for k, v in setup["constants"].items() if k in model.constants})
