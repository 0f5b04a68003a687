"""The code a card may name: role -> registered name -> function with the role's signature.

A model card names functions in five roles: its ``forward`` model (or, for a model written as
a plain function ``f(p, x)``, its ``function``: :mod:`skinfit.io.user_functions`),
``[sampling.shear]`` offsets, ``[sampling.shift]`` constants and a ``[derived]`` function.  Only functions
registered for that role can be named, as ``module:function`` or by their short name, and
the registry checks the role's call signature when a card is loaded: a card naming a cache
helper, an integer constant or another role's function is refused then, not at fit time.

Shipped physics is registered in :data:`BUILTIN` (as import strings: the physics modules
import nothing from skinfit, and are imported only when a card names them).  Installed
packages add functions through the ``skinfit.models`` entry-point group (read on first
need): the entry point loads either a forward function (registered under the entry
point's name) or a mapping ``{"forward": {name: f}, "function": {...}, "shear": {...},
"shift": {...}, "derived": {...}, "folder": path}`` whose ``folder`` holds ``models/`` and ``priors/``
cards that :mod:`skinfit.io.toml` then finds by id.
"""

import importlib
import inspect
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path

from skinfit.errors import InputError

__all__ = ["ROLES", "BUILTIN", "ENTRY_POINT_GROUP", "resolve", "lookup", "registered", "register", "unregister",
           "plugin_folders", "plugin_problems"]

ENTRY_POINT_GROUP = "skinfit.models"

#: role -> the positional arguments its functions are called with (see skinfit.physics).
ROLES = {
    "forward": ("p", "x", "c"),   # -> (y: dict of (k, n) arrays, ok: bool (k, n))
    "shear": ("p", "c"),          # -> log-offset, broadcastable to (k,)
    "shift": ("c",),              # -> float > 0, same unit as the parameter
    "derived": ("p", "x", "c"),   # -> dict name -> (k, n) array
    "function": ("p", "x"),       # a user's forward model: -> (k, n) array, or dict name -> (k, n) array
}
_CARD_KEY = {"forward": "forward", "shear": "sampling.shear", "shift": "sampling.shift",
             "derived": "derived.function", "function": "function"}

_PHYS = "skinfit.physics."
#: role -> "module:function" of every shipped function a card may name.
BUILTIN = {
    "forward": tuple(_PHYS + r for r in (
        "electroadhesion:electroadhesion", "electroadhesion:electroadhesion_coulomb",
        "electroadhesion:electroadhesion_empirical",
        "contact_area:contact_area", "contact_area:contact_area_hertz",
        "contact_area:contact_area_no_levitation",
        "textured:textured_surface", "textured:textured_no_transition", "textured:textured_no_hysteresis",
        "ultrasonic:ultrasonic", "ultrasonic:ultrasonic_projected", "ultrasonic:ultrasonic_constant_mu",
        "wavy:wavy_surface", "wavy:wavy_two_point_coulomb", "wavy:wavy_ball_bearing")),
    "shear": (_PHYS + "electroadhesion:phi_offset", _PHYS + "ultrasonic:mu_inf_offset"),
    "shift": (_PHYS + "electroadhesion:air_gap_shift",),
    "derived": tuple(_PHYS + r for r in (
        "contact_area:derived", "contact_area:derived_hertz", "contact_area:derived_no_levitation")),
    "function": (),
}


@dataclass(frozen=True)
class _Entry:
    ref: str        # "module:function"
    origin: str     # "skinfit" or "entry point <name> (<distribution>)"
    function: object = None  # set for plug-ins (already loaded), None for builtins (imported on use)


_TABLE = None      # role -> {key: _Entry}, keys being both "module:function" and the short name
_PLUGINS = None    # (role -> {key: _Entry}, folders)
_RESOLVED = {}


def _builtin_table():
    global _TABLE
    if _TABLE is None:
        table = {role: {} for role in ROLES}
        for role, refs in BUILTIN.items():
            for ref in refs:
                entry = _Entry(ref, "skinfit")
                table[role][ref] = entry
                table[role].setdefault(ref.partition(":")[2], entry)
        _TABLE = table
    return _TABLE


def _load_plugins():
    """Read the ``skinfit.models`` entry points once: (role -> {key: entry}, card folders,
    problems).  An entry point that fails to import, loads something else than a function or a
    mapping of roles, or registers a name already taken is left out and its problem recorded
    (:func:`plugin_problems`): one broken plug-in does not take the others or the shipped models down."""
    global _PLUGINS
    if _PLUGINS is not None:
        return _PLUGINS
    table, folders, problems = {role: {} for role in ROLES}, [], []
    builtin = _builtin_table()
    for ep in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
        dist = getattr(ep.dist, "name", "?")
        origin = f"entry point {ep.name!r} of {dist}"
        try:
            obj = ep.load()
        except Exception as exc:  # a broken plug-in must not take the shipped models down with it
            problems.append(f"installed package {dist}: its {ENTRY_POINT_GROUP} entry point {ep.name!r} "
                            f"({ep.value}) fails to import: {type(exc).__name__}: {str(exc)[:120]}")
            continue
        spec = {"forward": {ep.name: obj}} if callable(obj) else obj
        if not isinstance(spec, dict) or set(spec) - set(ROLES) - {"folder"}:
            problems.append(f"installed package {dist}: {origin} must load a forward function or a mapping with "
                            f"keys {', '.join(ROLES)}, folder")
            continue
        entries = {}
        try:
            for role in ROLES:
                for name, func in dict(spec.get(role, {})).items():
                    ref = f"{getattr(func, '__module__', '?')}:{getattr(func, '__name__', '?')}"
                    entry = _Entry(ref, origin, func)
                    for key in (name, ref):
                        if key in builtin[role] or key in table[role] or (role, key) in entries:
                            raise InputError(f"installed package {dist}", f"{origin} registers {role} "
                                             f"{key!r}, which is already registered")
                        entries[role, key] = entry
                    _check_signature(role, func, f"installed package {dist}", f"{ENTRY_POINT_GROUP}.{ep.name}")
        except InputError as exc:
            problems.append(str(exc))
            continue
        for (role, key), entry in entries.items():
            table[role][key] = entry
        if spec.get("folder") is not None:
            folders.append(Path(spec["folder"]))
    _PLUGINS = (table, tuple(folders), tuple(problems))
    return _PLUGINS


def plugin_problems():
    """One line for each ``skinfit.models`` entry point left out because it is broken."""
    return _load_plugins()[2]


def plugin_folders():
    """Folders of ``models/`` and ``priors/`` cards provided by installed plug-ins."""
    return _load_plugins()[1]


def registered(role):
    """Sorted short names registered for ``role`` (shipped, then plug-ins)."""
    names = {k for k in _builtin_table()[role] if ":" not in k}
    names |= {k for k in _load_plugins()[0][role] if ":" not in k}
    return sorted(names)


def _lookup(role, ref):
    entry = _builtin_table()[role].get(ref)
    if entry is None:
        entry = _load_plugins()[0][role].get(ref)
    return entry


def lookup(role, ref):
    """Whether ``ref`` is registered for ``role``: where it comes from (``"skinfit"``, an entry
    point, ``"register()"``), or None."""
    entry = _lookup(role, ref)
    return None if entry is None else entry.origin


def _check_signature(role, func, where, field):
    if not callable(func):
        raise InputError(where, f"names {type(func).__name__} {func!r}, not a function", field=field)
    try:
        inspect.signature(func).bind(*ROLES[role])
    except TypeError:
        raise InputError(where, f"{getattr(func, '__name__', func)}{inspect.signature(func)} cannot be a "
                         f"{role} function: it must take ({', '.join(ROLES[role])})", field=field) from None
    except ValueError:  # builtins without a signature
        raise InputError(where, f"{func!r} has no inspectable signature", field=field) from None


def resolve(role, ref, where, field=None):
    """The function ``ref`` (``module:function`` or a registered short name) names for ``role``.

    Raises InputError naming ``where`` and the card key when ``ref`` is not registered for
    this role (saying which role it is registered for, if any) or has the wrong signature.
    """
    field = field or _CARD_KEY[role]
    if not isinstance(ref, str) or not ref:
        raise InputError(where, f"expected the name of a registered {role} function (got {ref!r})", field=field)
    key = (role, ref)
    if key in _RESOLVED:
        return _RESOLVED[key]
    entry = _lookup(role, ref)
    if entry is None:
        other = [r for r in ROLES if r != role and _lookup(r, ref) is not None]
        if other:
            raise InputError(where, f"{ref!r} is registered as a {other[0]} function, not a {role} function "
                             f"(registered {role} functions: {', '.join(registered(role))})", field=field)
        broken = f"; left out: {'; '.join(plugin_problems())}" if plugin_problems() else ""
        what = "model function f(p, x)" if role == "function" else f"{role} function"
        known = ", ".join(registered(role)) or "none"
        here = " or skinfit.Model.from_function in this process" if role == "function" else ""
        raise InputError(where, f"{ref!r} is not a registered {what} (registered: {known}; a package adds its own "
                         f"through the {ENTRY_POINT_GROUP!r} entry point{here}{broken})", field=field)
    func = entry.function
    if func is None:
        module, _, name = entry.ref.partition(":")
        func = getattr(importlib.import_module(module), name)
    _check_signature(role, func, where, field)
    _RESOLVED[key] = func
    return func


def register(role, name, func, *, replace=False):
    """Register ``func`` for ``role`` under ``name`` (a short name or ``module:function``) in
    this process: for interactive work and tests; an installed package uses the entry point.
    ``replace``: a function registered here before under ``name`` is replaced (a notebook cell
    run again), never a shipped or plug-in one."""
    if role not in ROLES:
        raise InputError("register", f"unknown role {role!r} (expected one of {', '.join(ROLES)})")
    _check_signature(role, func, "register", name)
    found = _lookup(role, name)
    if found is not None and not (replace and found.origin == "register()"):
        raise InputError("register", f"{role} {name!r} is already registered ({found.origin})")
    _load_plugins()[0][role][name] = _Entry(name, "register()", func)
    _RESOLVED.pop((role, name), None)


def unregister(role, name):
    """Remove a function added by :func:`register`."""
    _load_plugins()[0][role].pop(name, None)
    _RESOLVED.pop((role, name), None)


def _reset():
    """Forget the entry points read so far (tests that install or fake a plug-in)."""
    global _PLUGINS
    _PLUGINS = None
    _RESOLVED.clear()
