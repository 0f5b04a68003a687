"""Finger friction vs sliding velocity under longitudinal ultrasonic vibration (Torres et al.;
docs/models/ultrasonic.md).

The equilibrium friction coefficient of stress-aided depinning of polymer chains (eq. 3,
after the molecular friction theories of Schallamach and of Chernyak & Leonov, refs. [19], [14]
of Torres et al.), with a speed-dependent friction factor (eq. 4), averaged over one vibration
period of the relative velocity between finger and plate (eq. 5).

The period average is a fixed-phase quadrature over [0, pi] (by the symmetry
``cos(wt) = cos(-wt)``), split where the relative velocity's x component changes sign (for
motion along the vibration axis the speed |v_x| has a kink there), with Gauss-Legendre nodes on
each smooth piece. docs/models/ultrasonic.md suggests the midpoint rule; measured on the shipped design at the
paper's parameters, the midpoint rule over the half period changed by 6e-3 from 48 to 96 phases
and still by 2e-5 from 1000 to 2000 (O(h^2) at the kink), while ``PHASES`` = 48 Gauss-Legendre
nodes per piece change the average by < 1e-8 when doubled (32 would give 4e-7; the test asks
< 1e-6: tests/test_physics_ultrasonic.py). Off the shipped angles it is slowest near 0.01 rad,
where v_x has a sharp minimum of width ~ v_y (1.3e-6 on doubling; 2e-7 at 0.05 rad).

Eqs. 3-5 are each written once (:func:`_eq3`, :func:`_eq4`, :func:`_eq5`). The quadrature is a
linear functional of mu on the nodes' speeds, and mu is a smooth function of log(speed) whose
features (the depinning peak near V0, the fall of mu* over sqrt(k_V), the turn at V0/q) are
each about a decade wide whatever the parameters. So with parameters shared by all rows the
models evaluate mu at ``INTERP_PER_DECADE`` Chebyshev points per decade of the nodes' speeds
(192 on the shipped design, against its 6734 nodes) and take the period averages as one matrix
product with the nodes' weights times the barycentric interpolation basis
(:func:`_interpolation`, cached: it depends on the covariates alone). Against the node sum,
over 2000 prior draws on the shipped design: max abs difference 4.6e-3, 9.0e-6, 1.4e-11,
3.1e-13 at 7, 14, 28, 40 points per decade (posterior draws: 4e-15 at 40), while the node
sum's own error is about 1e-8; 8-25x less time per call at 16-256 posterior draws. With
parameters per row (split by a column) the models sum over the nodes of all rows flattened into
one axis, in blocks of at most ``BLOCK_CELLS`` (parameter vector, node) cells that stay in
cache. :func:`period_average` of :func:`mu_equilibrium`, on (k, rows, nodes) arrays, is the
reference both are tested against.
"""

from functools import lru_cache

import numpy as np

from skinfit.physics._cache import by_value

__all__ = ["PHASES", "mu_equilibrium", "mu_speed", "period_average", "ultrasonic", "ultrasonic_projected",
           "ultrasonic_constant_mu", "mu_inf_offset"]

#: Gauss-Legendre nodes per smooth piece of the half period (convergence shown by the tests).
PHASES = 48


#: exp(x) for x < -700 is below 1e-304, negligible beside every term it enters, and numpy's
#: exp takes a slow path (~5x) for arguments whose result underflows: they are clipped here
#: (broad ensembles, e.g. the MAP's prior draws, meet them at many quadrature nodes).
_EXP_FLOOR = -700.0


def _bracket(u, e):
    """``Vs*(1 - exp(-1/Vs)) - exp(-1/Vs)`` with ``u = 1/Vs``, ``e = exp(-u)``; cancellation-free
    for small u (series there)."""
    out = np.subtract(1.0, e, out=np.empty(np.broadcast_shapes(np.shape(u), np.shape(e))))
    with np.errstate(divide="ignore", invalid="ignore"):
        out /= u  # 1 - e loses < 1e-14 relative for u >= 1e-2
    out -= e
    small = u < 1e-2
    if small.any():
        out[small] = _bracket_series(u[small])
    return out


def _bracket_series(s):
    """The bracket for small ``s = 1/Vs``: sum_j (-1)^(j+1) j s^j/(j+1)!, to j = 6."""
    return s * (1 / 2 - s * (1 / 3 - s * (1 / 8 - s * (1 / 30 - s * (1 / 144 - s / 840)))))


def mu_equilibrium(v, mu_star, q, v0):
    """Equilibrium friction coefficient mu_E at speed ``v`` >= 0 [m/s] (eq. 3 of Torres et al.).

    ``mu_E = 2*mu_star*(q+1)*(Vs*(1-exp(-1/Vs)) - exp(-1/Vs)) / (1 + q - exp(-1/Vs))``,
    ``Vs = v/v0``; tends to 0 as ``v -> 0`` (the bracket behaves like Vs).  ``v`` may lack the
    leading parameter axes of the others (speeds shared by an ensemble): what depends on ``v``
    alone is computed once.
    """
    v = np.asarray(v, dtype=float)
    moving = v > 0.0
    inv_v = 1.0 / np.where(moving, v, 1.0)  # no parameter axes yet
    value = _eq3(inv_v, mu_star, q, v0)
    return value if moving.all() else np.where(moving, value, 0.0)


def mu_speed(v, mu_inf, mu_0, k_v):
    """Speed-dependent friction factor mu*(V) (eq. 4 of Torres et al., sign as printed)."""
    return _eq4(np.asarray(v, dtype=float) ** 2, mu_inf, mu_0, k_v)


def _eq3(inv_v, mu_star, q, v0):
    """mu_E of eq. 3 from ``1/v``, computed in place on one array of the arguments' broadcast
    shape (the flat quadrature calls it on thousands of nodes per parameter vector)."""
    shape = np.broadcast_shapes(*(np.shape(a) for a in (inv_v, mu_star, q, v0)))
    u = np.multiply(v0, inv_v, out=np.empty(shape))
    e = np.negative(u, out=np.empty_like(u))
    np.maximum(e, _EXP_FLOOR, out=e)
    np.exp(e, out=e)
    value = _bracket(u, e)
    value *= mu_star
    q1 = 1.0 + np.asarray(q)
    value *= 2.0 * q1
    np.subtract(q1, e, out=e)
    value /= e
    return value


def _eq4(v2, mu_inf, mu_0, k_v):
    """mu* of eq. 4 from ``v^2``, in place on one array of the arguments' broadcast shape."""
    out = np.divide(v2, k_v, out=np.empty(np.broadcast_shapes(*(np.shape(a) for a in (v2, mu_inf, mu_0, k_v)))))
    np.negative(out, out=out)
    np.maximum(out, _EXP_FLOOR, out=out)
    np.exp(out, out=out)
    out *= mu_inf - mu_0
    out += mu_inf
    return out


@lru_cache(maxsize=8)
def _gauss_legendre(m):
    """``m`` Gauss-Legendre nodes and weights on [0, 1] (weights summing to 1)."""
    t, w = np.polynomial.legendre.leggauss(m)
    return (t + 1) / 2, w / 2


def _phase_nodes(vf_x, vy, amp_v, m):
    """Phases (..., 2m) on [0, pi] and weights for the average over a period.

    Where ``v_x`` changes sign the speed has a kink (motion along the vibration axis) or a sharp
    minimum of width ~ v_y/(omega*A/2): [0, pi] is split there, and each piece gets ``m``
    Gauss-Legendre nodes (rows where v_x keeps its sign: one piece, the other of zero width).
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(amp_v > 0, vf_x / np.where(amp_v > 0, amp_v, 1.0), -2.0)
    split = np.arccos(np.clip(ratio, -1.0, 1.0))[..., None]  # pi when there is no kink
    t, w = _gauss_legendre(m)
    phases = np.concatenate([split * t, split + (np.pi - split) * t], axis=-1)
    weights = np.concatenate([split * w, (np.pi - split) * w], axis=-1) / np.pi
    return phases, weights


def _eq5(velocity, angle, amplitude_pp, frequency, m):
    """The relative velocity of eq. 5 at the quadrature nodes: ``(still, vf_x, vy, vx, weights)``.

    ``still`` marks the rows without vibration (their speed is the finger's own, one node);
    ``vx`` and ``weights`` (rows where the plate vibrates, 2m) sample x velocity over a period
    at the nodes of :func:`_phase_nodes`; ``vy`` is constant over the period.
    """
    vf_x, vy = velocity * np.cos(angle), velocity * np.sin(angle)
    amp_v = np.pi * frequency * amplitude_pp  # omega * A/2
    still = amp_v == 0
    phases, weights = _phase_nodes(vf_x[~still], vy[~still], amp_v[~still], m)
    return still, vf_x, vy, vf_x[~still][:, None] - amp_v[~still][:, None] * np.cos(phases), weights


def period_average(f, velocity, angle, amplitude_pp, frequency, m=PHASES):
    """Average over one vibration period of ``f(speed, v_x, v_y)`` (eq. 5 of Torres et al.).

    The plate vibrates along x with peak-to-peak ``amplitude_pp`` [m] at ``frequency`` [Hz];
    the finger moves at ``velocity`` [m/s] at ``angle`` [rad] to the vibration axis. ``f`` is
    evaluated on arrays with a trailing phase axis and may prepend axes (parameter ensembles).
    Rows without vibration need no average and get a single node.
    """
    velocity, angle, amplitude_pp, frequency = np.broadcast_arrays(velocity, angle, amplitude_pp, frequency)
    still, vf_x, vy, vx_moving, w_moving = _eq5(velocity, angle, amplitude_pp, frequency, m)
    parts = []
    for rows, vx, weights in ((still, vf_x[still][:, None], np.ones((int(still.sum()), 1))),
                              (~still, vx_moving, w_moving)):
        if not rows.any():
            continue
        vyy = np.broadcast_to(vy[rows][:, None], vx.shape)
        values = f(np.hypot(vx, vyy), vx, vyy, rows)
        parts.append((rows, np.einsum("...rn,rn->...r", values, np.broadcast_to(weights, values.shape[-2:]))))
    lead = np.broadcast_shapes(*(v.shape[:-1] for _, v in parts))
    out = np.empty(lead + velocity.shape)
    for rows, values in parts:
        out[..., rows] = values
    return out


def _rows(x):
    return x["velocity"], x["direction_angle"], x["amplitude_pp"], x["frequency"]


#: (parameter vector, node) cells per block of :func:`_average`: its arrays (1 MB each) stay in
#: cache.  Measured on the shipped rows (84 distinct, 6734 nodes), 256 posterior draws: 9.6 ms
#: per block-wise call against 20.4 ms in one piece; 16 draws (an emcee half-ensemble) are one
#: block.
BLOCK_CELLS = 131072


@by_value
def _nodes(velocity, angle, amplitude_pp, frequency, m, projected):
    """The period average's nodes, flattened over rows: (1/speed, speed^2, weight, start, counts).

    Row r owns nodes ``start[r]:start[r] + counts[r]`` (one for a row without vibration, ``2m``
    otherwise, :func:`_phase_nodes`).  Nodes at rest get weight 0 (mu_E(0) = 0) and
    placeholder speeds; with ``projected`` the weights carry ``(v_r . u_f)/|v_r|``.  They
    depend on the covariates alone and are cached by their values.
    """
    velocity, angle, amplitude_pp, frequency = (a.ravel() for a in (velocity, angle, amplitude_pp, frequency))
    still, vf_x, vy, vx_moving, w_moving = _eq5(velocity, angle, amplitude_pp, frequency, m)
    counts = np.where(still, 1, 2 * m)
    start = (np.cumsum(counts) - counts).astype(np.intp)  # empty without rows
    vx, vyy, weight = (np.empty(int(counts.sum())) for _ in range(3))
    vx[start[still]], vyy[start[still]], weight[start[still]] = vf_x[still], vy[still], 1.0
    at = start[~still][:, None] + np.arange(2 * m)
    vx[at], vyy[at], weight[at] = vx_moving, vy[~still][:, None], w_moving
    speed = np.hypot(vx, vyy)
    moving = speed > 0.0
    safe = np.where(moving, speed, 1.0)
    if projected:
        along = (vx * np.repeat(np.cos(angle), counts) + vyy * np.repeat(np.sin(angle), counts)) / safe
        weight = weight * along
    return 1.0 / safe, np.where(moving, speed * speed, 0.0), np.where(moving, weight, 0.0), start, counts


#: Chebyshev points per decade of the nodes' speeds (at least ``INTERP_MIN``) on which
#: :func:`_interpolation` evaluates mu: at 40 the interpolated averages equal the node sums to
#: round-off (3e-13 over prior draws on the shipped design, 4.8 decades; 3e-12 with rows at
#: 1e-9 and 10 m/s added, 6.2 decades; at 28 per decade 1e-11 and 2.5e-9).
INTERP_PER_DECADE = 40
INTERP_MIN = 32


@by_value
def _interpolation(velocity, angle, amplitude_pp, frequency, m, projected):
    """The period averages of all rows as ``(1/c, c^2, matrix)``: mu at the speeds ``c``
    (Chebyshev points of the second kind in log speed spanning the moving nodes, ``N`` =
    :data:`INTERP_PER_DECADE` per decade) times ``matrix.T`` (N, rows) is, for every row, the
    weighted sum over its nodes of the barycentric interpolant of mu at the node speeds."""
    inv_v, _, weight, start, counts = _nodes(velocity, angle, amplitude_pp, frequency, scalars=(m, projected))
    used = weight != 0.0  # nodes at rest (weight 0, mu_E(0) = 0) stay out of the span
    if not used.any():
        return np.ones(1), np.ones(1), np.zeros((len(start), 1))
    log_v = -np.log(inv_v)
    lo, hi = log_v[used].min(), log_v[used].max()
    n_pts = 1 if hi - lo < 1e-12 else max(INTERP_MIN, int(np.ceil(INTERP_PER_DECADE * (hi - lo) / np.log(10.0))))
    j = np.arange(n_pts)
    pts = lo + (hi - lo) * (1.0 - np.cos(np.pi * j / max(n_pts - 1, 1))) / 2.0
    bary = np.where(j % 2 == 0, 1.0, -1.0)  # barycentric weights of Chebyshev points (2nd kind)
    bary[[0, -1]] *= 0.5
    matrix = np.empty((len(start), n_pts))
    ends = start + counts
    per = max(1, BLOCK_CELLS // n_pts)  # nodes per block of the basis
    r = 0
    while r < len(start):
        r_end = max(r + 1, int(np.searchsorted(ends, start[r] + per, side="right")))
        a, b = start[r], ends[r_end - 1]
        diff = log_v[a:b, None] - pts
        hit = diff == 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            basis = bary / diff
            basis /= basis.sum(axis=1, keepdims=True)
        rows_hit = hit.any(axis=1)
        basis[rows_hit] = hit[rows_hit]  # a node on an interpolation point takes its value
        basis *= weight[a:b, None]  # 0 at the nodes left out
        matrix[r:r_end] = np.add.reduceat(basis, start[r:r_end] - a, axis=0)
        r = r_end
    speeds = np.exp(pts)
    return 1.0 / speeds, speeds * speeds, matrix


def _average(p, x, *, projected=False, constant_mu=False, m=PHASES):
    """Period average of mu_E for parameters (k, 1), (k, n) or (1, 1) against rows (n,).

    Parameters shared by all rows: mu at the interpolation points of :func:`_interpolation`
    and one matrix product (shipped design, 16 posterior draws: 0.08 ms against 0.66 ms on the
    nodes). Parameters per row: on the flat nodes of :func:`_nodes`, in blocks of
    :data:`BLOCK_CELLS` cells, reduced per row. The same equations (:func:`_eq3`,
    :func:`_eq4`) as :func:`period_average` of :func:`mu_equilibrium`
    (tests/test_physics_ultrasonic.py), which evaluates (k, rows, nodes) arrays and took
    1.4-1.6x as long as the flat nodes at 16-32 posterior draws."""
    names = ("mu_plus", "q", "V0") if constant_mu else ("mu_inf", "mu_0", "k_V", "q", "V0")
    params = {name: np.atleast_2d(np.asarray(p[name], dtype=float)) for name in names}
    if all(v.shape[1] == 1 for v in params.values()):  # shared by all rows: interpolated
        inv_c, c2, matrix = _interpolation(*_rows(x), scalars=(m, projected))
        star = params["mu_plus"] if constant_mu else _eq4(c2, params["mu_inf"], params["mu_0"], params["k_V"])
        return _eq3(inv_c, star, params["q"], params["V0"]) @ matrix.T
    inv_v, v2, weight, start, counts = _nodes(*_rows(x), scalars=(m, projected))
    n = len(start)
    for name, v in params.items():
        if v.shape[1] > 1:
            params[name] = np.repeat(v, counts, axis=1)  # per-row values to nodes
    k = max(v.shape[0] for v in params.values())
    out = np.empty((k, n))
    if n == 0:
        return out
    step = max(1, BLOCK_CELLS // len(inv_v))
    for i in range(0, k, step):
        block = {name: v[i:i + step] if v.shape[0] > 1 else v for name, v in params.items()}
        star = block["mu_plus"] if constant_mu else _eq4(v2, block["mu_inf"], block["mu_0"], block["k_V"])
        values = _eq3(inv_v, star, block["q"], block["V0"])
        values *= weight
        out[i:i + step] = np.add.reduceat(values, start, axis=1)
    return out


def mu_inf_offset(p, c):
    """Sampling shear for ``mu_inf`` (declared in the card's ``[sampling.shear]``): sample
    ``log(mu_inf) - log(1 + q)``.

    For small q, eq. 3 gives ``log mu_E ~ log mu* + log(2 B / (1 - E)) - q / (exp(V0/V) - 1)``
    (``B`` the bracket, ``E = exp(-V0/V)``), and ``1 / (exp(V0/V) - 1) ~ V/V0 - 1/2`` is about
    1 at V ~ 1.5 V0: data at the tactile speeds around V0 pin ``log(mu_inf) - q``, a ridge
    curved in (log q, log mu_inf) (log mu_inf linear in q, which spans decades) and nearly
    flat in (log q, log(mu_inf / (1 + q))).  Measured on the shipped data, 10 seeds: median
    steps 350 -> 175 (refits at 50, 100 and 200 in most fits -> none in 8 of 10), sampling
    0.28 -> 0.12 s.  The offset depends on q alone, so the map's Jacobian is that of the log.
    (Sampling q linearly instead straightens the same ridge but made SBC fits slower: q spans
    decades over its prior.)
    """
    return np.log1p(p["q"])


def _support(p):
    """mu*(V) of eq. 4 lies between mu_inf and 2*mu_inf - mu_0: positive iff mu_0 < 2*mu_inf."""
    return 2.0 * p["mu_inf"] - p["mu_0"] > 0.0


def ultrasonic(p, x, c):
    """Friction coefficient: period average of mu_E(|v_r|) with mu* = mu*(|v_r|) (eqs. 3-5).

    Parameters ``mu_inf``, ``mu_0`` [-], ``k_V`` [m^2/s^2], ``q`` [-], ``V0`` [m/s]; covariates
    ``velocity`` [m/s], ``direction_angle`` [rad], ``amplitude_pp`` [m], ``frequency`` [Hz].
    """
    return {"friction_coefficient": _average(p, x)}, _support(p)


def ultrasonic_projected(p, x, c):
    """As :func:`ultrasonic`, averaging only the friction component along the finger's own
    direction, ``mu_E(|v_r|) * (v_r . u_f)/|v_r|`` (the competitor of Torres et al.'s Section IV)."""
    return {"friction_coefficient": _average(p, x, projected=True)}, _support(p)


def ultrasonic_constant_mu(p, x, c):
    """Eq. 1 of Torres et al., period-averaged: eq. 3 with the constant ``mu_plus`` in place of mu*(V).

    Read literally: ``mu_plus`` is the prefactor of eq. 1 (the printed brace holds the whole
    fraction), not the peak of mu_E as the paper's prose calls it; at q = 0.0177 the curve
    peaks at 0.905*mu_plus at V = 3.26*V0. At zero amplitude it equals :func:`ultrasonic` at
    any single speed V where ``mu_plus = mu*(V)`` (eq. 4).
    """
    return {"friction_coefficient": _average(p, x, constant_mu=True)}, np.True_
