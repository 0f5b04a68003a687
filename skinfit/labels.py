"""Units and long names of every variable of a fit's result tree (CF-style ``units`` and
``long_name`` attrs): parameters and data in the SI units they are stored in."""

from .posterior import noise_suffix
from .units import si_unit

__all__ = ["variable_attrs", "annotate"]


def variable_attrs(post):
    """name -> {"units": SI unit, "long_name": text} for the parameters, noise parameters,
    observables, covariates and other data columns of Posterior ``post``."""
    model, out = post.model, {}
    for q in (*model.parameters, *model.observables, *model.covariates):
        out[q.name] = {"units": q.unit, "long_name": q.name.replace("_", " ")
                       + (f": {q.description}" if q.description else "")}
    for o in post.observables:
        unit = next(q.unit for q in model.observables if q.name == o)
        suffix = noise_suffix(post.observables, o)
        lognormal = post.noise[o] == "lognormal"
        out[f"sigma{suffix}"] = {"units": "1" if lognormal else unit,
                                 "long_name": f"noise scale of {o}" + (" (of its log)" if lognormal else "")}
        out[f"nu{suffix}"] = {"units": "1", "long_name": f"Student-t degrees of freedom of the noise of {o}"}
    for c in post.dataset.columns:
        if c.name not in out:
            out[c.name] = {"units": si_unit(c.unit) if c.unit else "", "long_name": c.name.replace("_", " ")}
    if model.derived:
        for name, unit in model.derived["quantities"].items():
            out[name] = {"units": unit, "long_name": f"{name.replace('_', ' ')} (derived)"}
    return out


def annotate(tree, post):
    """Set ``units`` and ``long_name`` on every variable of ``tree`` (a DataTree) that
    :func:`variable_attrs` knows; the log-likelihood's values are in nats."""
    attrs = variable_attrs(post)
    for group in tree.children:
        node = tree[group]
        for var in node.data_vars:
            if group == "log_likelihood":
                node[var].attrs.update({"units": "1", "long_name": f"pointwise log-likelihood of {var} (nats)"})
            elif var in attrs:
                node[var].attrs.update(attrs[var])
    return tree
