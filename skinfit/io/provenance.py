"""Which model card, prior file and data file a fit used, and whether another file was hidden.

Every fit records, in its root attribute ``inputs`` (JSON), the absolute path of the model card,
the prior file and the dataset's card and data file it read, where on the search path each was
found (:func:`skinfit.io.paths.where_from`: ``--path``, ``$SKINFIT_PATH``, ``user``, ``plug-in``,
``shipped``, or ``file`` when named by its path) and the files of the same id it hid (their path,
origin and sha256). The sha256 of the model card and prior file are the fit's ``model_sha256``
and ``priors_sha256``; the data file's own sha256 is recorded here (``dataset_sha256`` hashes
card and data together). A file on the search path that hides another of other content (a prior
file left in the user folder over the shipped one) is warned about (:class:`ShadowWarning`) when
the fit starts, and shown in :meth:`skinfit.Fit.report_text`.
"""

import hashlib
import json
import warnings
from pathlib import Path

from skinfit.io.paths import where_from

__all__ = ["ShadowWarning", "input_record", "inputs_of", "input_lines", "warn_shadows"]

_ORIGIN_TEXT = {"user": "user folder", "file": "named by its path", "shipped": "shipped", "plug-in": "plug-in",
                "--path": "--path", "$SKINFIT_PATH": "$SKINFIT_PATH"}
_NAMES = {"model": "model card", "priors": "prior file", "dataset": "dataset card"}


class ShadowWarning(UserWarning):
    """A model card, prior file or dataset found first on the search path hides another of the
    same id with other content (e.g. a file in the user folder hides the shipped one)."""


def _sha256(path):
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return None


def _file(kind, file):
    """``{"path", "origin", "shadows": [{"path", "origin", "sha256"}]}`` of the card ``file``
    (absolute; "" when the object was not read from a file)."""
    if not file:
        return {"path": None, "origin": "not a file", "shadows": []}
    origin, hidden = where_from(kind, file)
    return {"path": file, "origin": origin,
            "shadows": [{"path": str(card.resolve()), "origin": root.origin, "sha256": _sha256(card)}
                        for root, card in hidden]}


def input_record(model, priors, dataset):
    """The JSON-able record of what a fit of ``model`` (Model) with ``priors`` (PriorSet) on
    ``dataset`` (Dataset) reads: stored as the fit's ``inputs`` attribute."""
    card = _file("datasets", dataset.card_file)
    if dataset.card_file:
        card["sha256"] = _sha256(dataset.card_file)
    return {"model": _file("models", model.file), "priors": _file("priors", priors.file),
            "dataset": {**card, "file": dataset.data_file or None, "file_sha256": dataset.data_sha256 or None}}


def shadow_messages(record, sha256):
    """One sentence per file of ``record`` that hides a file of other content; ``sha256``: kind ->
    the sha256 of the file used (model and priors: of the file; dataset: of its card)."""
    out = []
    for kind in ("model", "priors", "dataset"):
        used = record.get(kind, {})
        other = [s for s in used.get("shadows", []) if s.get("sha256") != sha256.get(kind)]
        if other:
            hidden = "; ".join(f"{s['path']} ({_ORIGIN_TEXT.get(s['origin'], s['origin'])})" for s in other)
            out.append(f"the {_NAMES[kind]} used is {used['path']} ({_ORIGIN_TEXT.get(used['origin'], used['origin'])}"
                       f"), which hides a file of the same id with other content: {hidden}; remove or rename it "
                       f"to use the other")
    return out


def warn_shadows(record, model, priors):
    """Warn (:class:`ShadowWarning`, one line each) about every file of ``record`` that hides
    another of other content (pointing at the caller of :func:`skinfit.fit`, which reaches this
    through :func:`skinfit.inference.run.run`)."""
    sha = {"model": model.sha256, "priors": priors.sha256, "dataset": record["dataset"].get("sha256")}
    for message in shadow_messages(record, sha):
        warnings.warn(message, ShadowWarning, stacklevel=4)


def inputs_of(attrs):
    """What a fit (its root ``attrs``) read: ``{"model", "priors", "dataset"}``, each with its
    ``path``, ``sha256``, ``origin`` and the files it hid (``shadows``); the dataset's also its
    data ``file`` and ``file_sha256``. A fit saved before these were recorded gives the ids,
    the sha256 it recorded and no paths (``origin`` "not recorded")."""
    try:
        record = json.loads(attrs.get("inputs", "{}"))
    except (TypeError, ValueError):
        record = {}
    blank = {"path": None, "origin": "not recorded", "shadows": []}
    model = {**blank, **record.get("model", {}), "id": attrs.get("model_id"), "sha256": attrs.get("model_sha256")}
    priors = {**blank, **record.get("priors", {}), "id": attrs.get("priors_id"), "sha256": attrs.get("priors_sha256")}
    dataset = {**blank, "file": None, "file_sha256": None, **record.get("dataset", {}), "id": attrs.get("dataset_id"),
               "sha256_card_and_data": attrs.get("dataset_sha256")}
    dataset.setdefault("sha256", None)
    return {"model": model, "priors": priors, "dataset": dataset}


def input_lines(attrs):
    """The lines :meth:`skinfit.Fit.report_text` prints about the fit's inputs (full sha256)."""
    inputs = inputs_of(attrs)
    sha = {"model": inputs["model"]["sha256"], "priors": inputs["priors"]["sha256"],
           "dataset": inputs["dataset"]["sha256"]}

    def where(item):
        origin = _ORIGIN_TEXT.get(item["origin"], item["origin"])
        return f"{item['path'] or '(not a file)'} ({origin})"

    m, p, d = inputs["model"], inputs["priors"], inputs["dataset"]
    if m["origin"] == "not recorded":
        return [f"inputs: model card sha256 {m['sha256']}, prior file sha256 {p['sha256']} (paths not recorded: "
                "fitted by an older skinfit)"]
    data = (f"{d['file']} (sha256 {d['file_sha256']})" if d.get("file") else
            "(not read from a file: a DataFrame or simulated values)")
    lines = [f"model card: {where(m)}, sha256 {m['sha256']}",
             f"prior file: {where(p)}, sha256 {p['sha256']}",
             f"data file:  {data}" + (f", card {where(d)}" if d.get("path") else "")]
    lines += [f"WARNING: {message}" for message in shadow_messages(inputs, sha)]
    return lines
