"""The campaign file: a (models x datasets x groups) matrix of fits described in one TOML file,
read and checked into a frozen :class:`CampaignFile` (:mod:`skinfit.apps.campaign` runs it)::

    schema_version = 1
    seed = 20261122                  # the one campaign seed (integer)
    out = "runs/example"             # result folder, relative to the campaign file
    models = ["electroadhesion_coulomb", "electroadhesion_empirical"]   # ids or card paths
    datasets = ["electroadhesion_synthetic"]                            # ids or folder/card paths
    by = ["voltage"]                 # optional: fit each level of these columns separately
    scheduler = "local"              # optional: "local" (Dask LocalCluster) or "tcp://HOST:PORT"
    workers = 2                      # optional: local worker processes (default: CPU count)
    threads = 1                      # optional: BLAS/OpenMP threads per fit (default: see skinfit.apps.campaign)

    [fit]                            # optional options of every fit
    ess = 200                        # minimum effective sample size (default 400)
    max_steps = 5000                 # emcee step cap (default 20000)
    noise = "normal"                 # normal | student_t | lognormal (default: the card's)
    nwalkers = 32                    # emcee walkers (default: max(32, 4 d))

    [priors]                         # optional: prior file per model (default priors/<model>.toml)
    electroadhesion_coulomb = "priors/electroadhesion_coulomb.toml"

    [split]                          # optional: per model, parameters split by a column in a fit
    electroadhesion_empirical = { b = "voltage" }

Paths are relative to the campaign file (``campaigns/example.toml`` is a working example).
Every model, prior file and dataset is loaded and checked here, and mistakes raise
:class:`~skinfit.errors.InputError` naming the file and field.  Model and dataset ids must be
plain names (:data:`NAME`: letters, digits, ``.``, ``_``, ``-``; never a path) and unique
within the campaign, as they name result folders.  A dataset or model entry that names an
existing file is read from that file (as an absolute path), whatever its card's id.
"""

import re
from dataclasses import dataclass
from pathlib import Path

from skinfit.errors import InputError
from skinfit.io.arguments import check_count
from skinfit.io.data import Dataset, load_dataset
from skinfit.io.models import NOISE_MODELS, Model, load_model
from skinfit.io.priors import load_priors
from skinfit.io.toml import find_file, read_toml, require

__all__ = ["CampaignFile", "CampaignModel", "CampaignDataset", "read_campaign_file", "check_name", "NAME"]

#: What an id used as a folder name may look like: a name, never a path (no ``/``, ``..``, ``~``).
NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")

_TOP_KEYS = {"schema_version", "seed", "out", "models", "datasets", "by", "scheduler", "workers", "threads",
             "fit", "priors", "split"}
_FIT_KEYS = {"ess": (float, "ess_target"), "max_steps": (int, "max_steps"), "noise": (str, "noise"),
             "nwalkers": (int, "nwalkers")}


@dataclass(frozen=True)
class CampaignModel:
    """One entry of ``models``: the card (``card`` its absolute path), the prior file it is
    fitted with (``priors``: its absolute path, or the id as given) and its sha256, and the
    parameters split by a column (``split``: parameter -> column or columns, or None)."""

    entry: str
    model: Model
    card: str
    priors: str
    priors_sha256: str
    split: dict | None


@dataclass(frozen=True)
class CampaignDataset:
    """One entry of ``datasets``: the dataset and the absolute path of the card read."""

    dataset: Dataset
    card: str


@dataclass(frozen=True)
class CampaignFile:
    """A campaign file read and checked.  ``scheduler`` is as written (a string or None): the
    executor it names is checked by :func:`skinfit.apps.campaign.load_campaign`.  ``options``:
    the ``[fit]`` options as keyword arguments of :func:`skinfit.fit`."""

    path: str
    seed: int
    out: Path
    scheduler: str | None
    workers: int | None
    threads: int | None
    options: dict
    models: tuple
    datasets: tuple
    by: tuple


def check_name(value, what, where):
    """``value`` if it is a name fit for a folder (:data:`NAME`), else an InputError."""
    if not isinstance(value, str) or not NAME.match(value) or value in (".", ".."):
        raise InputError(where, f"{what} {value!r} cannot name a result folder: expected a name of letters, "
                         "digits, '.', '_' and '-' starting with a letter or digit (no '/', no '..')")
    return value


def _resolve(name, base):
    """A path relative to the campaign file when it names an existing file or folder, else an id."""
    p = base / name
    return str(p.resolve()) if p.exists() else name


def _card(kind, ref):
    """The absolute path of the card a reference loads (a path as given, or the shipped id's)."""
    card = find_file(kind, ref)
    return str(Path(card).resolve())


def _unique_id(seen, obj_id, entry, kind, where, card):
    """Two entries with one id would share result folders: refuse it, naming both."""
    if obj_id in seen:
        first, first_card = seen[obj_id]
        raise InputError(where, f"{kind} id {obj_id!r} ({card}) is also the id of {first} ({first_card}); "
                         "two entries with one id would share result folders: give one card another id",
                         field=entry)
    seen[obj_id] = (entry, card)


def _str_list(doc, key, where, required=True):
    value = doc.get(key)
    if value is None and not required:
        return []
    if isinstance(value, str) and key == "by":
        value = [value]
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        raise InputError(where, f"expected a non-empty list of strings (got {value!r})", field=key)
    return value


def read_campaign_file(path):
    """Read and check a campaign file; every model, prior file and dataset is loaded once here."""
    path = Path(path)
    doc, _ = read_toml(path)
    where = str(path)
    base = path.resolve().parent
    unknown = set(doc) - _TOP_KEYS
    if unknown:
        raise InputError(where, f"unknown keys {sorted(unknown)} (expected {', '.join(sorted(_TOP_KEYS))})")
    seed = require(doc, "seed", int, where)
    if seed < 0:
        raise InputError(where, f"expected an integer >= 0 (got {seed})", field="seed")
    out = base / require(doc, "out", str, where)
    scheduler = require(doc, "scheduler", str, where, default=None)
    workers = check_count(require(doc, "workers", int, where, default=None), where, "workers", optional=True)
    threads = check_count(require(doc, "threads", int, where, default=None), where, "threads", optional=True)
    options = {}
    fit_doc = require(doc, "fit", dict, where, default={})
    for key, value in fit_doc.items():
        if key not in _FIT_KEYS:
            raise InputError(where, f"unknown fit option (expected {', '.join(_FIT_KEYS)})", field=f"fit.{key}")
        kind, name = _FIT_KEYS[key]
        value = require(fit_doc, key, kind, where, field_prefix="fit.")
        if kind is str and value not in NOISE_MODELS:
            raise InputError(where, f"expected one of {', '.join(NOISE_MODELS)} (got {value!r})", field=f"fit.{key}")
        if kind is not str and value <= 0:
            raise InputError(where, f"expected a number > 0 (got {value})", field=f"fit.{key}")
        options[name] = value

    models, model_cards, seen = {}, {}, {}
    for i, name in enumerate(_str_list(doc, "models", where)):
        try:
            model_cards[name] = _card("models", _resolve(name, base))
            models[name] = load_model(model_cards[name])
        except InputError as exc:
            raise InputError(where, str(exc), field=f"models[{i}]") from None
        check_name(models[name].id, "model id", f"{where}: models[{i}]")
        _unique_id(seen, models[name].id, f"models[{i}]", "model", where, model_cards[name])
    priors_doc = require(doc, "priors", dict, where, default={})
    split_doc = require(doc, "split", dict, where, default={})
    for table, key in ((priors_doc, "priors"), (split_doc, "split")):
        for name in table:
            if name not in models:
                raise InputError(where, f"not one of the campaign's models ({', '.join(models)})",
                                 field=f"{key}.{name}")
    entries = []
    for name, model in models.items():
        ref = require(priors_doc, name, str, where, field_prefix="priors.", default=model.id)
        try:
            prior_set = load_priors(_resolve(ref, base))
        except InputError as exc:
            raise InputError(where, str(exc), field=f"priors.{name}") from None
        missing = [p for p in model.parameter_names if p not in prior_set]
        if missing:
            raise InputError(where, f"prior file {prior_set.path} has no prior for {', '.join(missing)}",
                             field=f"priors.{name}")
        split = require(split_doc, name, dict, where, field_prefix="split.", default={})
        for param, cols in split.items():
            if param not in model.parameter_names:
                raise InputError(where, f"model {model.id!r} has no parameter {param!r} (parameters: "
                                 f"{', '.join(model.parameter_names)})", field=f"split.{name}.{param}")
            if not (isinstance(cols, str)
                    or (isinstance(cols, list) and cols and all(isinstance(c, str) for c in cols))):
                raise InputError(where, f"expected a column name or a list of them (got {cols!r})",
                                 field=f"split.{name}.{param}")
        entries.append(CampaignModel(
            entry=name, model=model, card=model_cards[name],
            priors=str(Path(prior_set.path).resolve()) if Path(prior_set.path).exists() else ref,
            priors_sha256=prior_set.sha256, split=split or None))

    by = _str_list(doc, "by", where, required=False)
    datasets, seen = [], {}
    for i, name in enumerate(_str_list(doc, "datasets", where)):
        try:
            # the card actually read, as an absolute path: a path entry whose card id equals a
            # shipped dataset's is fitted from that path, never from the shipped folder
            ref = _card("datasets", _resolve(name, base))
            dataset = load_dataset(ref)
        except InputError as exc:
            raise InputError(where, str(exc), field=f"datasets[{i}]") from None
        check_name(dataset.id, "dataset id", f"{where}: datasets[{i}]")
        _unique_id(seen, dataset.id, f"datasets[{i}]", "dataset", where, ref)
        for c in by:
            if c not in dataset.frame.columns:
                raise InputError(where, f"dataset {dataset.id!r} has no column {c!r} (columns: "
                                 f"{', '.join(dataset.frame.columns)})", field="by")
        for m in entries:
            for split_cols in (m.split or {}).values():
                for c in [split_cols] if isinstance(split_cols, str) else split_cols:
                    if c not in dataset.frame.columns:
                        raise InputError(where, f"dataset {dataset.id!r} has no column {c!r}",
                                         field=f"split.{m.entry}")
        datasets.append(CampaignDataset(dataset, ref))
    return CampaignFile(path=where, seed=seed, out=out, scheduler=scheduler, workers=workers, threads=threads,
                        options=options, models=tuple(entries), datasets=tuple(datasets), by=tuple(by))
