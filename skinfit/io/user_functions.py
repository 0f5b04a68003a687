"""A model's forward model given as a plain Python function (:meth:`skinfit.Model.from_function`).

A user's function is called ``f(p, x)``: ``p`` maps each parameter to a (k, 1) array of k
parameter draws (SI), ``x`` each covariate to an (n,) SI array; it returns the (k, n) array of
the model's one observable, or a dict observable -> (k, n) array.  :func:`adapt` turns it into
a forward function of the card contract (:mod:`skinfit.io.forward_check`: ``(p, x, c) -> (y, ok)``),
with ``ok`` True everywhere: the function must be finite wherever the priors put mass, and a NaN
or inf it returns is a :class:`~skinfit.errors.ForwardError` (on the prior draws checked before a
fit, or while fitting).

A model card names such a function with ``function = "module:qualname"`` (instead of
``forward``) and may record ``function_sha256``, the sha256 of its source text
(:func:`source_sha256`; "" when Python has no source for it: a function typed at a plain
``python`` prompt or made by ``exec``).  A card file finds the function in the registry
(:mod:`skinfit.io.registry`, role ``function``: a plug-in's entry point, or
:meth:`~skinfit.Model.from_function` in this process); the card saved in a fit may also import it
by module and name (:func:`import_function`), with its source hash checked, for what evaluates the
model again (predictions, evidence, the report's predictive checks).
"""

import hashlib
import importlib
import inspect
import json
import sys
from collections.abc import Mapping

import numpy as np

from skinfit.errors import ForwardError, InputError, InputTypeError
from skinfit.io.arguments import shown
from skinfit.io.registry import lookup, register

__all__ = ["function_ref", "source_sha256", "adapt", "UserForward", "restore_forward", "import_function",
           "check_source_hash", "function_card"]


def function_ref(func):
    """``"module:qualname"`` of ``func`` (``"__main__:powerlaw_ea"`` for a notebook's function)."""
    return f"{getattr(func, '__module__', None) or '?'}:{getattr(func, '__qualname__', None) or '?'}"


def source_sha256(func):
    """sha256 of ``func``'s source text (:func:`inspect.getsource`), or "" when Python has none."""
    try:
        text = inspect.getsource(func)
    except (OSError, TypeError):  # no source file (a plain prompt, exec), or a builtin
        return ""
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def adapt(func, observables, ref, where):
    """The forward function ``(p, x, c) -> (y, ok)`` of the user function ``func(p, x)``, whose
    model has ``observables`` (names): a :class:`UserForward`, which pickles (a Model sent to
    worker processes) with ``func`` by module and name."""
    return UserForward(func, tuple(observables), ref, where)


#: Why a function reaches worker processes only by module and name (see UserForward).
_BY_NAME = ("a model's function reaches worker processes by module and name: define it at the top level of a "
            "module (a .py file) and import it from there")


class UserForward:
    """The forward function ``(p, x, c) -> (y, ok)`` of a user's ``func(p, x)`` (:func:`adapt`):
    one array is the first observable's, a dict is returned as it is (its keys checked by the
    caller, :func:`skinfit.io.forward_check.validated`).  An array that is not 2-D is a
    ForwardError naming ``where`` and ``ref``: parameters come as (k, 1) arrays, so a vectorised
    function returns (k, n).

    Pickled (a Model handed to worker processes) as ``ref`` and the sha256 of ``func``'s source:
    the worker imports the function by module and name (:func:`restore_forward`).  A function
    defined at a module's top level pickles anywhere; one defined in ``__main__`` reaches
    fork-started workers (they share this process's ``__main__``), and spawned ones only from a
    script (they run its top level again), not from a notebook or a prompt: those workers say so
    in one line; a lambda or a function defined inside another one cannot be pickled (an
    InputError in one line when pickled)."""

    def __init__(self, func, observables, ref, where):
        self.func, self.observables, self.ref, self.where = func, observables, ref, where
        self.__name__ = getattr(func, "__name__", "forward")
        self.__wrapped__ = func

    def __call__(self, p, x, c):
        y = self.func(p, x)
        y = dict(y) if isinstance(y, Mapping) else {self.observables[0]: y}
        for name, arr in y.items():
            if isinstance(arr, np.ndarray) and arr.ndim != 2:
                k = max((np.shape(v)[0] for v in p.values() if np.ndim(v)), default=1)
                n = max((len(v) for v in x.values()), default=1)
                raise ForwardError(self.where, f"{self.ref}: returned {name!r} of shape {arr.shape}; expected "
                                               f"({k}, {n}) = (parameter draws, data rows): parameters come as "
                                               "(k, 1) arrays, covariates as (n,)", field="function")
        return y, np.True_

    def __reduce__(self):
        if _found(self.ref) is not self.func:
            raise InputError(self.where, f"{self.ref} cannot be sent to worker processes (a lambda, or a function "
                                         f"defined inside another one): {_BY_NAME}", field="function")
        return restore_forward, (self.ref, source_sha256(self.func), self.observables, self.where)

    def __repr__(self):
        return f"UserForward({self.ref})"


def _found(ref):
    """The object ``ref`` (``module:qualname``) names among the modules imported, or None."""
    module, _, qualname = ref.partition(":")
    obj = sys.modules.get(module)
    for part in qualname.split("."):
        obj = getattr(obj, part, None)
    return obj


def restore_forward(ref, recorded, observables, where):
    """The :class:`UserForward` of the function ``ref`` (``module:qualname``) in a worker
    process (unpickling one), its source checked against the ``recorded`` sha256, and the
    function registered (role ``function``) as :meth:`~skinfit.Model.from_function` does; one
    line when the worker cannot import it (a notebook's function in a spawned worker)."""
    module = ref.partition(":")[0]
    func = _found(ref) if module == "__main__" else None
    if func is None and module == "__main__":
        raise InputError(where, f"{ref} is not defined in this worker process: a function defined in a notebook "
                                f"or at a prompt (__main__) reaches fork-started workers only; {_BY_NAME}",
                         field="function")
    if func is None:
        func = import_function(ref, recorded, where)
    check_source_hash(func, ref, recorded, where)
    if lookup("function", ref) in (None, "register()"):
        register("function", ref, func, replace=True)
    return UserForward(func, tuple(observables), ref, where)


_REFIT = "predictions would not be those of the model fitted; restore the function, or refit"
_REWRITE = "write the card again (Model.to_card), or delete its function_sha256 to check nothing"


def check_source_hash(func, ref, recorded, where, saved=True):
    """InputError naming ``where`` when ``func``'s source differs from the ``recorded`` sha256
    (nothing to check when either is unknown); the remedy for a fit's card (``saved``) or a card file."""
    now = source_sha256(func)
    if recorded and now and now != recorded:
        raise InputError(where, f"the source of {ref} has changed since it was recorded (sha256 {recorded[:12]}... "
                                f"recorded, {now[:12]}... now): {_REFIT if saved else _REWRITE}",
                         field="function_sha256")
    return func


def import_function(ref, recorded, where):
    """The function ``ref`` (``module:qualname``) imported, its source checked against the
    ``recorded`` sha256; InputError in one line when it cannot be imported or has changed."""
    module, _, qualname = ref.partition(":")
    need = "needed only to evaluate the model again (predictions, evidence); the saved draws need no function"
    try:
        obj = importlib.import_module(module)
        for part in qualname.split("."):
            obj = getattr(obj, part)
    except Exception as exc:  # ImportError, AttributeError, or whatever the module raises on import
        raise InputError(where, f"cannot import the model's function {ref} ({type(exc).__name__}: "
                                f"{str(exc)[:100]}): {need}", field="function") from None
    if not callable(obj):
        raise InputError(where, f"{ref} is a {type(obj).__name__}, not a function: {need}", field="function")
    return check_source_hash(obj, ref, recorded, where)


def _toml_string(text):
    return json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")


def _quantities(value, what, where, *, observable=False):
    """[(name, unit, description or noise)] of ``observable`` / ``covariates`` / ``parameters`` as
    :meth:`~skinfit.Model.from_function` takes them; InputTypeError naming ``what`` otherwise."""
    if observable and isinstance(value, tuple) and value and all(isinstance(v, str) for v in value):
        value = [value]  # one ("name", "unit"[, noise])
    items = list(value.items()) if isinstance(value, Mapping) else value
    expected = ("a (name, unit) pair, a sequence of them, or a mapping name -> unit" if observable
                else "a mapping name -> unit (or name -> (unit, description))")
    if isinstance(items, (str, bytes)) or not isinstance(items, (list, tuple)):
        raise InputTypeError(where, f"expected {expected} (got {shown(value)})", field=what)
    out = []
    for item in items:
        if isinstance(item, tuple) and len(item) == 2 and isinstance(item[1], tuple):
            item = (item[0], *item[1])  # name -> (unit, description)
        if not (isinstance(item, (tuple, list)) and 2 <= len(item) <= 3 and all(isinstance(v, str) for v in item)):
            raise InputTypeError(where, f"expected {expected} (got {shown(item)})", field=what)
        out.append((item[0], item[1], item[2] if len(item) == 3 else ""))
    if observable and not out:
        raise InputError(where, "expected at least one observable", field=what)
    return out


def function_card(func, observable, covariates, parameters, id=None, title=None, source=None):
    """``(ref, card text)`` of a model whose forward model is ``func(p, x)``
    (:meth:`skinfit.Model.from_function`, which documents the arguments): checked here for what
    the card cannot say (a lambda without ``id``, a name used twice across observables,
    covariates, parameters and noise parameters); the card's own checks follow on parsing."""
    name = getattr(func, "__name__", type(func).__name__)
    where = f"Model.from_function({name})"
    if not callable(func):
        raise InputTypeError(where, f"expected a function f(p, x) (got {shown(func)})", field="func")
    try:
        inspect.signature(func).bind("p", "x")
    except TypeError:
        raise InputError(where, f"{name}{inspect.signature(func)} must take (p, x): p the parameters "
                                "{name: (k, 1) array}, x the covariates {name: (n,) array}", field="func") from None
    except ValueError:
        raise InputError(where, f"{func!r} has no inspectable signature", field="func") from None
    if id is None and not name.isidentifier():
        raise InputError(where, f"a function named {name!r} (a lambda) gives the model no id: pass id='...'",
                         field="id")
    ref = function_ref(func)
    obs = _quantities(observable, "observable", where, observable=True)
    covs = _quantities(covariates, "covariates", where)
    pars = _quantities(parameters, "parameters", where)
    seen = {}
    noise = {"sigma", "nu"} | {f"{n}_{o[0]}" for o in obs for n in ("sigma", "nu")}
    for kind, group in (("observable", obs), ("covariate", covs), ("parameter", pars)):
        for q in group:
            if q[0] in seen:
                raise InputError(where, f"{kind} {q[0]!r} shadows the {seen[q[0]]} of that name: give them "
                                        "different names", field=kind if kind == "observable" else kind + "s")
            if kind == "parameter" and q[0] in noise:
                raise InputError(where, f"parameter {q[0]!r} shadows the noise parameter of that name: rename it",
                                 field="parameters")
            seen[q[0]] = kind
    lines = ["schema_version = 1", f"id = {_toml_string(id if id is not None else name)}",
             f"title = {_toml_string(title if title is not None else f'{name} (a Python function)')}",
             f"source = {_toml_string(source if source is not None else f'Python function {ref}')}",
             f"function = {_toml_string(ref)}", f"function_sha256 = {_toml_string(source_sha256(func))}"]
    for table, group in (("observables", obs), ("covariates", covs), ("parameters", pars)):
        for qname, unit, extra in group:
            lines += ["", f"[[{table}]]", f"name = {_toml_string(qname)}", f"unit = {_toml_string(unit)}"]
            if extra:
                lines.append(f"{'noise' if table == 'observables' else 'description'} = {_toml_string(extra)}")
    return ref, "\n".join(lines) + "\n"
