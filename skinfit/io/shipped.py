"""Whether a model card is a shipped one, unchanged, whose functions are all skinfit's own.

Then what is computed from a fit of it (a population kept by content) follows from the fit's
content and skinfit's source (:func:`skinfit.io.paths.source_hash`) alone; a user's card or
forward function may change without the fit changing.
"""

from pathlib import Path

from skinfit.io.models import load_model
from skinfit.io.paths import locate, shipped_root
from skinfit.io.registry import resolve

__all__ = ["shipped_physics"]


def shipped_physics(model_id, model_sha256):
    """True when the card ``model_id`` found now is the shipped one (not a user's card that
    shadows it), with sha256 ``model_sha256`` (a fit's ``model_sha256``), and every function it
    names (forward, shear, shift, derived) is in :mod:`skinfit.physics`."""
    try:
        model = load_model(model_id)
        shipped = shipped_root()
        if shipped is None or model.sha256 != model_sha256:
            return False
        if Path(locate("models", model_id)).resolve().parent != (Path(shipped) / "models").resolve():
            return False  # a card of the user's that shadows a shipped one
        refs = [("forward", model.forward_ref), *(("shear", r) for r in model.shear.values()),
                *(("shift", r) for r in model.shift.values())]
        if model.derived.get("function"):
            refs.append(("derived", model.derived["function"]))
        return all(resolve(role, ref, model.path).__module__.startswith("skinfit.physics.") for role, ref in refs)
    except Exception:  # a model that cannot be checked is simply not shipped physics
        return False
