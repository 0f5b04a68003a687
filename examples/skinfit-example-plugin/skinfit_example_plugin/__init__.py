"""An example skinfit plug-in: one physics function, its model card and its prior file.

skinfit finds it through the ``skinfit.models`` entry point (see pyproject.toml), which loads
:data:`SKINFIT`: the forward functions it registers and the folder of its cards.
"""

from pathlib import Path

import numpy as np

__all__ = ["two_term_friction", "SKINFIT"]


def two_term_friction(p, x, c):
    """Derjaguin's two-term friction law, F_t = mu * F_n + F_0 (B. V. Derjaguin, "Molekulartheorie
    der äusseren Reibung", Zeitschrift für Physik 88, 1934): a load-proportional term and an
    adhesive term independent of the load.

    ``p``: ``mu`` [1] and ``F0`` [N], floats or arrays broadcastable to (k, n); ``x``:
    ``normal_force`` [N], shape (n,); returns ``({"tangential_force": (k, n) array [N]}, ok)``
    with ``ok`` all True (any mu, F0 >= 0 gives a finite force).
    """
    ft = p["mu"] * x["normal_force"] + p["F0"]
    ft = np.broadcast_to(ft, np.broadcast_shapes(np.shape(ft), (1, len(x["normal_force"]))))
    return {"tangential_force": ft}, np.ones(ft.shape, dtype=bool)


SKINFIT = {
    "forward": {"two_term_friction": two_term_friction},
    "folder": Path(__file__).parent / "cards",
}
